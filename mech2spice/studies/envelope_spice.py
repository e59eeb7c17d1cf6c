"""ngspice on the envelope equations (mech2spice/spice/envelope.py): speed vs accuracy, failure points, scaling.

Not a report of its own: the envelope-spice sections of `mech2spice report speed_accuracy`, which is the one
writer of speed_accuracy.md and puts `block()` at its end.  Sections (written to envelope_spice.json and the
chart speed_accuracy_envelope_spice.png beside the report):
  accuracy  the NOR gate (4 nominal input pairs, 2500 periods from rest), chain(3) (8 members, inputs
            00 -> 10 -> 00 and band-edge levels, 4500 periods) and the 2-bit adder (4 of its 16 input pairs,
            2900 periods at 0 then (a, b), 5800 periods): ngspice-envelope at max steps 8..0.5 periods x
            {trap, gear} x reltol {1e-3, 1e-4, 1e-5}, and the Python envelope integrator (envelope.integrate,
            RK4) at its steps; errors against envelope.integrate at 1/8 period (converged), and against RK4
            at 160 steps/period for the gate.  Scenes and error measures: experiments/scenes.py,
            experiments/validate.py.
  failures  what breaks: very large max steps (ngspice's own truncation-error control takes over), and the
            stall ngspice fell into right after a PWL breakpoint (the drive form spice/envelope.py avoids).
  scaling   arrays of independent NOR gates up to 4200 oscillators: ngspice-envelope and the Python envelope
            for 50 and 2500 periods; ngspice carrier-level from reports/speed_accuracy.json ('scaling', 50
            periods; its 2500-period cost extrapolated linearly, as its step is pinned).

usage: mech2spice report speed_accuracy --only envelope_spice [--quick]       # all three sections
       mech2spice report speed_accuracy --only envelope_spice.scaling       # one, merged into the JSON
"""
from __future__ import annotations

import platform
import re
import subprocess
import tempfile
import time
from dataclasses import asdict
from pathlib import Path

import numpy as np

from ..errors import Mech2SpiceError
from ..experiments import validate as V
from ..experiments import scenes as S
from ..physics import nor
from ..backends import envelope
from ..physics.params import DEFAULT, NOMINAL0
from ..physics.stimulus import Stimulus
from ..spice import envelope_netlist as se
from ._common import SANDBOX, conditions, load_average, log, read_json, write_json

MACHINE = f"{SANDBOX}, shared"
SECTIONS = ("accuracy", "failures", "scaling")
P = DEFAULT
REF_STEP = 0.125                 # periods: the Python envelope reference
CHECK_STEP = 0.25                # the reference's own error: against this step
MAX_STEPS = [8, 4, 2, 1, 0.5]
METHODS = ["trap", "gear"]
RELTOLS = [1e-4, 1e-5, 1e-3]     # the default first
PY_STEPS = [0.25, 0.5, 1, 2, 4, 8]
ADDER_MEMBERS = [5, 11, 14, 15]  # (a, b) = (1, 1), (2, 3), (3, 2), (3, 3): every output bit changes somewhere
LARGE_STEPS = [64, 1000]         # failures: max steps where ngspice's truncation-error control decides alone
SCALING_GATES = [1, 10, 50, 170, 350, 700]
SCALING_PERIODS = [50, 2500]
ACCT_MIN_GATES = 170             # sizes whose 2500-period run is repeated under .options acct
WORKERS = 2
STALL_TIMEOUT = 20.0             # s per ngspice process in the PWL-stall experiment (normal runs: < 4 s)


# --- scenes ------------------------------------------------------------------------------------------
def subset(sc: S.Scene, members: list[int]) -> S.Scene:
    """The scene restricted to the batch members at indices `members`."""
    st = Stimulus(sc.stimulus.times, sc.stimulus.amps[:, :, members])
    return S.Scene(sc.name, sc.model, st, sc.periods, sc.probes, [sc.members[k] for k in members], sc.events,
                   sc.windows, sc.description + f" (members {', '.join(sc.members[k] for k in members)})")


def scenes(quick: bool) -> dict[str, S.Scene]:
    """The accuracy scenes: the gate's 4 nominal pairs, chain(3), 4 adder members (fewer when `quick`)."""
    out = {"nor_gate": S.gate_scene(P, "nominal"), "chain3": S.chain_scene(P),
           "adder": subset(S.adder_scene(P), ADDER_MEMBERS)}
    if quick:
        out["chain3"] = subset(out["chain3"], [0, 1])
        out["adder"] = subset(out["adder"], [2])
    return out


# --- runners -----------------------------------------------------------------------------------------
def run_spice(sc: S.Scene, opts: se.EnvelopeSpiceOptions, timeout: float | None = None) -> dict:
    """ngspice-envelope on every member (WORKERS processes at a time); amplitudes in u_R at each period's
    end, like validate.run_envelope's samples.  wall_s: the sum of the processes' own times (one-core
    cost); elapsed_s: the wall clock with WORKERS processes."""
    t0 = time.perf_counter()
    try:
        run = se.run_envelope_spice(sc.model, sc.periods, sc.stimulus, opts, workers=WORKERS, timeout=timeout)
    except Mech2SpiceError as e:
        return {"failed": str(e)[:300], "elapsed_s": time.perf_counter() - t0}
    rows = [run.probe_names.index(n) for n in sc.probes]
    amp = np.abs(run.amp[:, rows, :]) / P.u_r
    return {"amp": np.concatenate([np.zeros((1,) + amp.shape[1:]), amp]), "t": np.arange(sc.periods + 1.0),
            "wall_s": float(np.sum(run.extra["wall_s"])), "elapsed_s": time.perf_counter() - t0,
            "points": float(np.mean(run.extra["points"])),
            "max_step_used": float(np.max(run.extra["max_step_used_periods"]))}


def scored(sc: S.Scene, ref: dict, r: dict) -> dict:
    """`r` against the reference `ref` (validate.compare): errors in u_R, crossings; or its failure."""
    if "failed" in r:
        return {"failed": r["failed"]}
    c = V.compare(sc, ref, r)
    return {"amp_err_ur": c["amp_err"], "traj_err_ur": c["traj_err"], "time_err": c["time_err"],
            "crossings": c["n_crossings"], "crossing_mismatch": c["crossing_count_mismatch"]}


def accuracy(quick: bool) -> dict:
    """The accuracy section: each scene on ngspice-envelope and the Python envelope, against the reference."""
    out = {}
    for name, sc in scenes(quick).items():
        log(f"[accuracy] {name}: {sc.model.n} oscillators, {sc.stimulus.batch} members, {sc.periods} periods")
        ref = V.run_envelope(sc, REF_STEP)
        chk = V.run_envelope(sc, CHECK_STEP)
        d = {"description": sc.description, "oscillators": sc.model.n, "members": sc.members,
             "periods": sc.periods, "stability_bound_periods": envelope.max_step_periods(sc.model),
             "reference": {"step": REF_STEP, "wall_s": ref["wall_s"],
                           "vs_step": CHECK_STEP, **scored(sc, ref, chk)},
             "spice": [], "python": []}
        rk = None
        if name == "nor_gate":
            rk = V.run_rk4(sc, 160)
            d["rk4_160"] = {"wall_s": rk["wall_s"], "vs_reference": scored(sc, rk, ref)}
        for step in PY_STEPS:
            if step > d["stability_bound_periods"]:
                d["python"].append({"step": step, "refused": f"beyond the stability bound "
                                                             f"{d['stability_bound_periods']:.1f} periods"})
                continue
            r = V.run_envelope(sc, step)
            row = {"step": step, "wall_s": r["wall_s"], **scored(sc, ref, r)}
            if rk is not None:
                row["vs_rk4_160"] = scored(sc, rk, r)
            d["python"].append(row)
        reltols = RELTOLS[:1] if quick else RELTOLS
        steps = MAX_STEPS[1:3] if quick else MAX_STEPS
        for rt in reltols:
            for method in METHODS:
                for ms in steps:
                    opts = se.EnvelopeSpiceOptions(method=method, max_step_periods=ms, reltol=rt)
                    r = run_spice(sc, opts, timeout=120)
                    row = {"method": method, "max_step": ms, "reltol": rt,
                           **{k: r[k] for k in ("wall_s", "elapsed_s", "points", "max_step_used") if k in r},
                           **scored(sc, ref, r)}
                    if rk is not None and "failed" not in r:
                        row["vs_rk4_160"] = scored(sc, rk, r)
                    d["spice"].append(row)
                    log(f"  {method} reltol {rt:g} max step {ms:g}: " + (
                        f"FAILED {row['failed']}" if "failed" in row else
                        f"{row['wall_s']:.2f} s, traj {row['traj_err_ur']:.4f}, settled {row['amp_err_ur']:.5f} u_R"))
        out[name] = d
    return out


# --- failures -----------------------------------------------------------------------------------------
_TANH = re.compile(r"^B(a_\S+) (\S+) 0 V = (.*)$", re.M)
_TERM = re.compile(r"([-0-9.e+]+)\*\(1 \+ tanh\(\(time - ([-0-9.e+]+)\)/[-0-9.e+]+\)\)")


def pwl_variant(text: str, T: float, ramp_periods: float = 1e-3) -> str:
    """The netlist with its smooth drive steps written as PWL voltage sources (ramp centred on each
    change, as spice/carrier.py writes the carrier-level drives): the form spice/envelope.py does not use."""
    def sub(m):
        name, node, expr = m.groups()
        a = float(expr.split(" + ", 1)[0])
        pts, ramp = [f"0 {a!r}"], ramp_periods * T
        for half, t1 in _TERM.findall(expr):
            t1, a1 = float(t1), a + 2 * float(half)
            pts += [f"{t1 - ramp / 2!r} {a!r}", f"{t1 + ramp / 2!r} {a1!r}"]
            a = a1
        return f"V{name} {node} 0 PWL({' '.join(pts)})"
    return _TANH.sub(sub, text)


def run_text(text: str, timeout: float) -> dict:
    """Run one netlist text in ngspice; on a timeout, how far it got and its step sizes into the stall."""
    with tempfile.TemporaryDirectory(prefix="m2s_es_") as d:
        cir, raw = Path(d) / "c.cir", Path(d) / "c.raw"
        cir.write_text(text)
        t0 = time.perf_counter()
        try:
            p = subprocess.run(["ngspice", "-b", "-n", "-r", str(raw), str(cir)], capture_output=True, text=True,
                               timeout=timeout, stdin=subprocess.DEVNULL)
        except subprocess.TimeoutExpired:
            from ..spice.runner import read_raw
            out = {"stalled": True, "wall_s": time.perf_counter() - t0}
            if raw.exists() and raw.stat().st_size:
                _, data = read_raw(raw)
                t = data[:, 0]
                if t.size > 2:
                    dt = np.diff(t) / P.period
                    k = int(np.argmax(dt <= dt[-1] * 1.01))          # first step at the final (minimum) size
                    out.update(reached_period=float(t[-1] / P.period), last_step_periods=float(dt[-1]),
                               steps_into_stall_periods=dt[max(k - 12, 0):k + 1].tolist(),
                               stall_from_period=float(t[k] / P.period))
            return out
        return {"stalled": False, "wall_s": time.perf_counter() - t0, "rc": p.returncode}


def failures(quick: bool) -> dict:
    """The failures section: the PWL-drive stall on adder members, and very large max steps per scene."""
    sc = S.adder_scene(P)
    out = {"pwl_stall": [], "large_steps": {}}
    members = [1, 15] if not quick else [1]
    log(f"[failures] PWL vs smooth drive steps, adder members {members}")
    for ms, rt in ((2, 1e-5), (0.5, 1e-5), (2, 1e-4)):
        opts = se.EnvelopeSpiceOptions(max_step_periods=ms, reltol=rt)
        for b in members:
            text = se.emit_envelope_with_probes(sc.model, sc.stimulus, sc.periods, opts, batch_index=b)[0]
            for form, t in (("tanh (used)", text), ("PWL, ramp 1e-3 T", pwl_variant(text, P.period))):
                r = run_text(t, STALL_TIMEOUT)
                out["pwl_stall"].append({"member": sc.members[b], "max_step": ms, "reltol": rt, "form": form, **r})
                log(f"  {form} max step {ms} reltol {rt:g} {sc.members[b]}: "
                    + ("STALLED" if r["stalled"] else f"{r['wall_s']:.2f} s"))
    log("[failures] very large max steps")
    for name, s in scenes(quick).items():
        ref = V.run_envelope(s, REF_STEP)
        rows = []
        for ms in LARGE_STEPS:
            for rt in RELTOLS:
                r = run_spice(s, se.EnvelopeSpiceOptions(max_step_periods=ms, reltol=rt), timeout=120)
                rows.append({"max_step": ms, "reltol": rt,
                             **{k: r[k] for k in ("wall_s", "points", "max_step_used") if k in r}, **scored(s, ref, r)})
        out["large_steps"][name] = rows
    return out


# --- scaling --------------------------------------------------------------------------------------------
def gate_array(n: int):
    """A model of `n` independent NOR gates, both inputs of each driven at the nominal 0 (0.5 F_R)."""
    return nor.gate_array(P, n, NOMINAL0, declare=False)


def acct(model, periods: int, opts, drop_b: bool = False) -> dict:
    """ngspice's own accounting (.options acct) of one run: where its time goes.  drop_b: the same netlist
    without its B sources (a linear circuit, physically meaningless: a cost probe only)."""
    from ..spice.runner import run_netlist
    text = se.emit_envelope_with_probes(model, None, periods, opts)[0].replace(".options ", ".options acct ", 1)
    if drop_b:
        text = "\n".join(ln for ln in text.splitlines() if not ln.startswith("B")) + "\n"
    t0 = time.perf_counter()
    _, _, log_text = run_netlist(text)
    wall = time.perf_counter() - t0
    keys = {"Transient analysis time": "analysis_s", "Transient load time": "load_s",
            "Transient factor time": "factor_s", "Transient solve time": "solve_s",
            "Transient iterations": "iterations", "Transient timepoints": "timepoints"}
    out = {}
    for line in log_text.splitlines():
        key, _, val = line.partition("=")
        name = keys.get(key.strip())
        if name:
            out[name] = float(val.split()[0])
    out["b_sources"] = text.count("\nB")
    out["wall_s"] = wall
    return out


def scaling(quick: bool, directory: Path) -> dict:
    """Independent NOR gates on ngspice-envelope and the Python envelope; the carrier-level times come
    from DIRECTORY/speed_accuracy.json."""
    carrier = {}
    try:
        sa = read_json(Path(directory) / "speed_accuracy.json")["scaling"]
        carrier = {"periods": sa["periods"], "options": sa["ngspice_options"],
                   "rows": {r["oscillators"]: r["ngspice_s"] for r in sa["rows"]}}
    except (OSError, KeyError, TypeError, ValueError):
        pass
    rows = []
    opts = se.EnvelopeSpiceOptions()
    for n in SCALING_GATES[:3] if quick else SCALING_GATES:
        m = gate_array(n)
        t0 = time.perf_counter()
        envelope.Envelope.of(m)          # the operator both backends read (cached on the model)
        step = envelope.default_step(m)
        row = {"gates": n, "oscillators": m.n, "python_step": step, "operator_s": time.perf_counter() - t0}
        envelope.integrate(m, 1, step_periods=1.0)     # the compiled loop's per-model set-up, outside timing
        for per in SCALING_PERIODS:
            t0 = time.perf_counter()
            r = se.run_envelope_spice(m, per, None, opts, workers=1)
            row[f"spice_{per}_s"] = time.perf_counter() - t0
            row[f"spice_{per}_points"] = int(r.extra["points"][0])
            t0 = time.perf_counter()
            e = envelope.integrate(m, per, step_periods=step)
            row[f"python_{per}_s"] = time.perf_counter() - t0
            row[f"diff_{per}_ur"] = float(np.abs(np.abs(r.amp[-1]) - np.abs(e.amp[-1])).max() / P.u_r)
        if n >= ACCT_MIN_GATES:
            row["acct"] = acct(m, SCALING_PERIODS[-1], opts)
            row["acct_without_b"] = acct(m, SCALING_PERIODS[-1], opts, drop_b=True)
        if m.n in carrier.get("rows", {}):
            c = carrier["rows"][m.n]
            row["carrier_50_s"] = c * 50 / carrier["periods"]
            row["carrier_2500_s_extrapolated"] = c * 2500 / carrier["periods"]
        rows.append(row)
        log(f"[scaling] {m.n:5d} oscillators: " + ", ".join(f"{k} {v:.2f}" for k, v in row.items() if k.endswith("_s")))
    return {"periods": SCALING_PERIODS, "spice_options": asdict(opts), "carrier": carrier, "rows": rows}


# --- output ----------------------------------------------------------------------------------------------


def measure(directory: Path, only=None, quick: bool = False) -> dict:
    """Run the sections in `only` (None: all three, from scratch; else merged into envelope_spice.json as a
    rerun); returns the results (reports/envelope_spice.py draws the chart)."""
    jpath = Path(directory) / "envelope_spice.json"
    res = read_json(jpath, {}) if only else {}
    # compile the Python envelope loop and start ngspice once, outside every timing
    g = S.gate_scene(P, "nominal", periods=20)
    V.run_envelope(g, 1.0)
    se.run_envelope_spice(g.model, 20, g.stimulus, workers=1)
    t0 = time.perf_counter()
    pre = "rerun_" if only else ""
    res.update(machine=MACHINE, python=platform.python_version(), default_options=asdict(se.EnvelopeSpiceOptions()),
               settings=settings(), conditions=conditions())
    res[pre + "load_before"] = " / ".join(f"{x:.1f}" for x in load_average())
    for name, fn in (("accuracy", accuracy), ("failures", failures),
                     ("scaling", lambda q: scaling(q, directory))):
        if not only or name in only:
            res[name] = fn(quick)
    res[pre + "load_after"] = " / ".join(f"{x:.1f}" for x in load_average())
    res["total_wall_s" if not only else "partial_rerun_s"] = time.perf_counter() - t0
    res["rerun_sections"] = sorted(set(res.get("rerun_sections", [])) | set(only)) if only else []
    res.setdefault("total_wall_s", res.get("partial_rerun_s", 0.0))
    write_json(jpath, res)
    return res


def settings() -> dict:
    """The measurement's settings the report states (it reads them from the JSON, not from this module)."""
    return {"methods": METHODS, "reltols": RELTOLS, "ref_step": REF_STEP, "check_step": CHECK_STEP,
            "stall_timeout": STALL_TIMEOUT, "large_steps": LARGE_STEPS, "max_steps": MAX_STEPS,
            "scaling_periods": SCALING_PERIODS}


