"""The figures behind the ETDRK4 exponential step (docs/latency.md, "Each amplitude's own rate too").

    python scripts/etd_check.py rates [--params centered_fc2] [--max-fanout 12] [--cycles 6]
    python scripts/etd_check.py chain [--params centered_fc2]
    python scripts/etd_check.py bench [--params centered_fc2] [--cycles 30] [--rounds 3]
    python scripts/etd_check.py steps [--params centered_fc2] [--cycles 8] [--steps 20 24 32 40] [--fanouts 4 12]

rates: the processor's envelope operator at rest, split into each amplitude's own rate (its diagonal) and the
coupling (the rest), per DOF kind; then the remainder the RK4 part of the ETD step sees (the linearised
envelope equations less the own rates and the insulators' linear oscillators) at rest, after power-up and after
--cycles cycles.  chain: the 3-gate chain's settled amplitudes at the end against step 1, exponential step
with and without ETDRK4 (forced at every step), steps 2-32.  bench: one fcb sample's cycles without and with ETDRK4, alternated in one
process: CPU seconds and microseconds per gate-block step.  steps: the nominal processor at explicit steps
(beyond the ETD bound too: the bound is lifted for this scan) and whether each runs --cycles cycles.
Prints JSON.
"""
import argparse
import json
import time

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from mech2spice import data
from mech2spice.backends import envelope
from mech2spice.backends._envelope_latency import own_rates
from mech2spice.cpu.physical import PhysicalCPU
from mech2spice.cpu.run import load_program, make_memory
from mech2spice.physics import stability
from mech2spice.physics.envelope import Envelope
from mech2spice.physics.params import load_params


def processor(params: str, max_fanout: int | None, power_up: bool = True, **kw) -> PhysicalCPU:
    return PhysicalCPU(make_memory(load_program(str(data.program("sieve.asm")))), "envelope", load_params(params),
                       power_up=power_up, max_fanout=max_fanout, **kw)


def _radius(op) -> float:
    return float(np.abs(spla.eigs(op, k=3, which="LM", return_eigenvectors=False, tol=1e-3, maxiter=20000)).max())


def remainder_rate(env: Envelope, own0, binv, A, s) -> float:
    """Spectral radius (per period) of the linearised envelope equations at (A, s) less what the ETD step
    treats exactly: each amplitude's own rate at these insulator positions, each insulator's linear oscillator."""
    E, J = stability.linearise(env, A, s)
    lu = spla.splu(E.tocsc())
    nf, ns = env.fast.size, env.slow.size
    lam = own0 - binv * (env.G @ s)
    f, j = np.arange(nf), np.arange(ns)
    k, c, m = env.Ks.diagonal(), env.Cs.diagonal(), env.ms
    rows = np.concatenate([f, f, nf + f, nf + f, 2 * nf + j, 2 * nf + ns + j, 2 * nf + ns + j])
    cols = np.concatenate([f, nf + f, f, nf + f, 2 * nf + ns + j, 2 * nf + j, 2 * nf + ns + j])
    vals = np.concatenate([lam.real, -lam.imag, lam.imag, lam.real, np.ones(ns), -k / m, -c / m])
    D = sp.csr_matrix((vals, (rows, cols)), shape=J.shape)
    op = spla.LinearOperator(J.shape, matvec=lambda x: lu.solve(J @ x) - D @ x, dtype=float)
    return _radius(op) * env.model.period


def rates(a) -> dict:
    cpu = processor(a.params, a.max_fanout)
    model = cpu.model
    env, T = Envelope.of(model), model.period
    own0, binv = own_rates(env, env.block_inverse())
    M = -sp.csr_matrix(env.block_inverse()) @ sp.csc_matrix(env.Z0)
    coupling = M - sp.diags(M.diagonal())
    kinds = {}
    for name, o in zip((model.names[i] for i in env.fast), np.abs(own0) * T):
        kinds.setdefault(name.split(".")[-1], []).append(float(o))
    out = {"params": a.params, "max_fanout": a.max_fanout, "period_units": "per drive period",
           "operator_at_rest": _radius(spla.aslinearoperator(M)) * T,
           "own_rate_by_kind": {k: [min(v), max(v)] for k, v in kinds.items()},
           "coupling_at_rest": _radius(spla.aslinearoperator(coupling)) * T,
           "bound_periods": {"rk4_insulators_exact": envelope.max_step_periods(model, True, False),
                             "etd": envelope.max_step_periods(model, True, True)}}
    A, s = cpu.state[0][:, 0], cpu.state[1][:, 0]
    out["remainder"] = {"rest": remainder_rate(env, own0, binv, np.zeros_like(A), np.zeros_like(s)),
                        "after_power_up": remainder_rate(env, own0, binv, A, s)}
    for _ in range(a.cycles):
        cpu.step()
    out["remainder"][f"after_{a.cycles}_cycles"] = remainder_rate(env, own0, binv, cpu.state[0][:, 0],
                                                                 cpu.state[1][:, 0])
    return out


def chain(a) -> dict:
    from mech2spice.experiments import scenes
    sc = scenes.chain_scene(load_params(a.params))
    u, out = sc.model.amplitude_unit, {"params": a.params, "reference": "step 1, same integrator"}
    chosen = envelope.needs_etd
    for etd in (False, True):
        envelope.needs_etd = lambda *args, **kw: etd      # ETDRK4 at every step (or never), not only where needed
        run = lambda st: np.abs(envelope.integrate(sc.model, sc.periods, step_periods=st, stimulus=sc.stimulus,
                                                   exponential=True, etd=etd).amp)
        try:
            ref, rows = run(1), {}
            for st in (2, 4, 8, 16, 32):
                try:
                    x = run(st)
                    rows[st] = float(np.abs(x[-1] - ref[-1]).max() / u)
                except Exception as e:          # a step beyond the bound or a divergence: what it said
                    rows[st] = str(e).splitlines()[0]
        finally:
            envelope.needs_etd = chosen
        out["etd" if etd else "insulators_only"] = rows
    return out


def bench(a) -> dict:
    from mech2spice.experiments import montecarlo as mc
    from mech2spice.experiments.blas import set_blas_threads
    from mech2spice.experiments.mc_clocked import CpuMC
    set_blas_threads(1)
    spec = mc.spec_of({"local": 0.01, "trim": "fcb", "trim_residual": 1e-4})
    ways = {etd: CpuMC(str(data.program("sieve.asm")), a.cycles, load_params(a.params), "envelope", spec, 7, etd=etd)
            for etd in (False, True)}
    for w in ways.values():
        w._machine(0).step()                       # compiled kernels loaded
    res = {False: [], True: []}
    for r in range(a.rounds):
        for etd in ((False, True) if r % 2 == 0 else (True, False)):
            cpu = ways[etd]._machine(1)
            t = time.process_time()
            for _ in ways[etd].want:
                cpu.step()
            dt = time.process_time() - t
            res[etd].append({"cpu_s": dt, "block_steps": cpu.block_steps, "us_per_block_step": dt / cpu.block_steps * 1e6,
                             "step": cpu.step_periods})
    return {"params": a.params, "cycles": a.cycles, "sample": 1, "insulators_only": res[False], "etd": res[True]}


def steps(a) -> dict:
    out = {}
    bound = envelope.ETD_ROTATION
    envelope.ETD_ROTATION = 1e9                   # the scan looks beyond the bound
    try:
        for fo in a.fanouts:
            for st in a.steps:
                cpu = processor(a.params, fo, power_up=False, step=st)
                try:
                    cpu.amps = cpu._reset()
                    for _ in range(a.cycles):
                        cpu.step()
                    out[f"fanout {fo}, step {st}"] = "ran"
                except Exception as e:
                    out[f"fanout {fo}, step {st}"] = str(e).splitlines()[0]
    finally:
        envelope.ETD_ROTATION = bound
    return {"params": a.params, "cycles": a.cycles, "runs": out}


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("what", choices=["rates", "chain", "bench", "steps"])
    ap.add_argument("--params", default="centered_fc2")
    ap.add_argument("--max-fanout", type=int, default=None)
    ap.add_argument("--cycles", type=int, default=None)
    ap.add_argument("--rounds", type=int, default=3)
    ap.add_argument("--steps", type=float, nargs="+", default=[20, 24, 32, 40])
    ap.add_argument("--fanouts", type=int, nargs="+", default=[4, 12])
    a = ap.parse_args()
    a.cycles = a.cycles if a.cycles is not None else {"rates": 6, "bench": 30, "steps": 8}.get(a.what, 0)
    print(json.dumps({"rates": rates, "chain": chain, "bench": bench, "steps": steps}[a.what](a), indent=1))


if __name__ == "__main__":
    main()
