"""Monte-Carlo of whole designs under element spread: the spread spec, sampled models, per-sample results.

A sample is the design's mechanical model with every element (physics/spread.py: each DOF's local k,
m, c, each coupling spring and dashpot, each gamma, each drive) multiplied by its own factor

    factor = 1 + sigma_local[kind] * z_element + sigma_wafer[kind] * w_kind

z_element independent standard normals (local mismatch); w_kind one standard normal per kind and sample
shared by every element of that kind (a wafer-level shift), correlated across kinds with coefficient
`wafer_rho`.  Sample i draws from numpy's Generator seeded with (seed, i), so a sample is the same
whatever task, worker or resumed run computes it.

It passes when, for every input vector, every output bit decodes to the logic oracle's value.  Each
gate channel is checked against its own logic value too: a *root* gate failure is a gate out of its
expected band while every gate feeding it is in its band (the failure starts there); the per-gate
failure rate is root failures / (samples x gates), which is what a gate count extrapolates.

Engines that batch (envelope, rk4) run many samples as one model: the block-diagonal union of the
sampled copies (experiments/tolerance.union), with the stimulus batch holding the input vectors.

Thermal noise (`noise` T > 0, physics/noise.py): every sample also gets its own Langevin forces, seeded
by (seed, i); such samples run one per engine run (the batch holds the input vectors) so that a sample's
noise does not depend on which others share its run.  The outputs are read at the last period of the
run, so a failure is a bit read wrong (or outside both bands) at that moment: the bit-error rate.
"""
from __future__ import annotations

import hashlib
import itertools
import json
import math
from dataclasses import asdict, dataclass, field
from pathlib import Path

import numpy as np

from .. import simulation
from ..backends import engine_class, logic, make_engine
from ..errors import DivergenceError
from ..errors import Mech2SpiceError
from ..physics import context, network, spread
from ..physics.noise import check_temperature
from ..physics.params import GateParams
from ..physics.stimulus import Stimulus
from ..synthesis.ports import output_bits, port_range
from ..synthesis.synth import Netlist
from . import clocking
from .tolerance import QUANTILES, wilson

KINDS = ("k", "m", "c", "spring", "dashpot", "gamma", "drive")
TRIM_DEFAULTS = {"trim": "none", "trim_residual": 0.0, "drift": 0.0}   # the spec's fields that mean "not trimmed"
MAX_ALL_VECTORS = 256          # a design with at most this many input combinations is checked on all of them


@dataclass(frozen=True)
class SpreadSpec:
    """Relative Gaussian spread per element kind: local mismatch plus a wafer-level shift per kind."""
    local: dict = field(default_factory=dict)     # kind -> sigma (independent per element)
    wafer: dict = field(default_factory=dict)     # kind -> sigma (one shift per kind and sample)
    wafer_rho: float = 0.0                        # correlation of the wafer shifts across kinds
    trim: str = "none"                            # after the spread: none, f (k/m), fc (k/m and c/m)
    trim_residual: float = 0.0                    # relative sigma of the trimmed quantity
    drift: float = 0.0                            # in service: every stiffness times (1 + drift)

    def __post_init__(self):
        spread.check_trim(self.trim, self.trim_residual)
        spread.check_drift(self.drift)

    @property
    def zero(self) -> bool:
        """True when every sample is the nominal design (nothing spread, no residual, no drift)."""
        return (not any(self.local.values()) and not any(self.wafer.values()) and not self.drift
                and not (self.trim != "none" and self.trim_residual))

    def sample(self, nominal, elems: list, seed: int, index: int):
        """Sample `index` of `nominal`: spread, trimmed, drifted; and the factor of every element."""
        f = self.factors(elems, seed, index)
        model = spread.scaled(nominal, elems, f)
        model = spread.trimmed(model, nominal, elems, self.trim, self.trim_residual, spread.trim_rng(seed, index),
                               balance_point=context.balance_point(nominal.params) if self.trim == "fcb" else None)
        return spread.drifted(model, self.drift), f

    def factors(self, elems: list, seed: int, index: int) -> np.ndarray:
        """The factor of every element of sample `index`."""
        rng = np.random.default_rng([seed, index])
        z = rng.standard_normal(len(elems))
        common, own = rng.standard_normal(), rng.standard_normal(len(KINDS))
        w = math.sqrt(self.wafer_rho) * common + math.sqrt(1 - self.wafer_rho) * own
        kind = np.array([KINDS.index(e.kind) for e in elems], int)
        loc = np.array([self.local.get(k, 0.0) for k in KINDS])[kind]
        waf = np.array([self.wafer.get(k, 0.0) for k in KINDS])[kind]
        return 1.0 + loc * z + waf * w[kind]

    def describe(self) -> dict:
        """The spec as JSON fields; trim and drift only when set, so untrimmed results files keep their keys."""
        out = asdict(self)
        for key, off in TRIM_DEFAULTS.items():
            if out[key] == off:
                del out[key]
        return out


def _sigmas(value, where: str) -> dict:
    """A sigma (every kind) or {kind or "*": sigma} -> {kind: sigma}."""
    if isinstance(value, (int, float)) and not isinstance(value, bool):
        value = {"*": value}
    if not isinstance(value, dict):
        raise Mech2SpiceError(f"spread spec '{where}': expected a sigma or {{kind: sigma}}, got {value!r}")
    out = dict.fromkeys(KINDS, 0.0)
    for key, s in sorted(value.items(), key=lambda kv: kv[0] != "*"):
        if key != "*" and key not in KINDS:
            raise Mech2SpiceError(f"spread spec '{where}': unknown kind '{key}' (kinds: *, {', '.join(KINDS)})")
        if isinstance(s, bool) or not isinstance(s, (int, float)) or not (math.isfinite(s) and 0 <= s < 1):
            raise Mech2SpiceError(f"spread spec '{where}.{key}': sigma must be a number in [0, 1), got {s!r}")
        out.update(dict.fromkeys(KINDS, float(s)) if key == "*" else {key: float(s)})
    return out


def parse_spread(text: str) -> SpreadSpec:
    """`--spread`: a sigma (local, every kind), a JSON object, or a JSON file of one:
    {"local": SIGMA | {KIND: SIGMA}, "wafer": SIGMA | {KIND: SIGMA}, "wafer_rho": RHO}."""
    text = str(text).strip()
    try:
        return spec_of(float(text))
    except ValueError:
        pass
    if spread_file(text) is None:
        try:
            obj = json.loads(text)
        except json.JSONDecodeError as e:
            raise Mech2SpiceError(f"--spread: invalid JSON ({e.msg} at character {e.pos})") from None
    else:
        from ..inputs import read_json
        obj = read_json(text, "spread spec")
    return spec_of(obj)


def spread_file(text: str) -> str | None:
    """The file a --spread value names, or None for a sigma or an inline JSON object."""
    text = str(text).strip()
    try:
        float(text)
        return None
    except ValueError:
        return None if text.startswith("{") else text


def spec_of(obj) -> SpreadSpec:
    """A SpreadSpec from a sigma or the JSON object `parse_spread` describes."""
    if not isinstance(obj, dict):
        return SpreadSpec(_sigmas(obj, "local"), _sigmas(0.0, "wafer"))
    unknown = set(obj) - {"local", "wafer", "wafer_rho", *TRIM_DEFAULTS}
    if unknown:
        raise Mech2SpiceError(f"spread spec: unknown field(s) {', '.join(sorted(unknown))} (local, wafer, wafer_rho, "
                              f"{', '.join(TRIM_DEFAULTS)})")
    rho = obj.get("wafer_rho", 0.0)
    if isinstance(rho, bool) or not isinstance(rho, (int, float)) or not 0 <= rho <= 1:
        raise Mech2SpiceError(f"spread spec 'wafer_rho': must be a number in [0, 1], got {rho!r}")
    trim = {key: obj.get(key, off) for key, off in TRIM_DEFAULTS.items()}
    if not isinstance(trim["trim"], str):
        raise Mech2SpiceError(f"spread spec 'trim': must be one of {', '.join(spread.TRIMS)}, got {trim['trim']!r}")
    return SpreadSpec(_sigmas(obj.get("local", 0.0), "local"), _sigmas(obj.get("wafer", 0.0), "wafer"), float(rho),
                      **trim)


def all_vectors(netlist: Netlist) -> list[dict[str, int]]:
    """Every input combination (port integers), for designs with at most MAX_ALL_VECTORS of them."""
    ports = list(netlist.inputs.items())
    n = sum(w for _, w in ports)
    if 2 ** n > MAX_ALL_VECTORS:
        raise Mech2SpiceError(f"{netlist.top} has {2 ** n} input combinations: give the inputs with --set P=V")
    spans = [port_range(netlist, p) for p, _ in ports]
    return [dict(zip([p for p, _ in ports], combo)) for combo in itertools.product(*spans)]


class DesignMC:
    """A combinational design's nominal model, stimulus and logic expectations; evaluates samples."""

    def __init__(self, netlist: Netlist, p: GateParams, vectors: list[dict[str, int]], backend: str,
                 spec: SpreadSpec, seed: int, periods: int | None = None, options=None, union: int | None = None,
                 noise: float = 0.0):
        if netlist.clocked:
            raise Mech2SpiceError(f"{netlist.top} is clocked: montecarlo runs combinational designs")
        self.netlist, self.p, self.vectors, self.spec, self.seed = netlist, p, vectors, spec, seed
        self.backend, self.options, self.noise = backend, options, check_temperature(noise)
        self.engine = make_engine(backend, options)
        if not self.engine.capabilities.physical:
            raise Mech2SpiceError(f"montecarlo needs a physical backend, not '{backend}'")
        self.model = network.build(netlist, p)
        self.stim = network.stimulus(self.model, netlist, p, [(0, vectors)])
        self.elems = spread.elements(self.model)
        self.budget = periods or clocking.period_budget(netlist)
        self.fixed = periods is not None
        self.outs = [b for b in output_bits(netlist) if b in self.model.probes]
        self.gates = list(self.model.design.blocks)
        self.channels = [self.model.design.blocks[g].channel for g in self.gates]
        gi = {g: k for k, g in enumerate(self.gates)}
        self.feeders = [[gi[s] for s in netlist.graph.predecessors(g) if s in gi] for g in self.gates]
        bits = [logic.evaluate_bits(netlist, v) for v in vectors]
        self.want_out = np.array([[b[o] for b in bits] for o in self.outs], int)        # (outs, B)
        self.want_gate = np.array([[b[g] for b in bits] for g in self.gates], int)      # (gates, B)
        self.union = 1 if self.noise else union or (1 if engine_class(backend).capabilities.simulator else 8)

    def engine_for(self, i: int):
        """The engine sample i runs on: with noise, the backend with sample i's own noise seed."""
        if not self.noise:
            return self.engine
        from ..backends import noisy_engine
        return noisy_engine(self.backend, self.options, self.noise, noise_seed(self.seed, i))

    def sample(self, i: int):
        """Sample i's model and stimulus (the nominal ones when the spec spreads nothing)."""
        if self.spec.zero:
            return self.model, self.stim
        model, f = self.spec.sample(self.model, self.elems, self.seed, i)
        fd = np.ones(len(self.model.drives))
        for e, x in zip(self.elems, f):
            if e.kind == "drive":
                fd[e.index] = x
        return model, Stimulus(self.stim.times, self.stim.amps * fd[None, :, None])

    def evaluate(self, indices: list[int]) -> list[dict]:
        """One record per sample index, `self.union` samples per engine run."""
        out = []
        for k in range(0, len(indices), self.union):
            out += self._run_group(list(indices[k:k + self.union]))
        return out

    def amplitudes(self, idx: list[int]) -> tuple[np.ndarray, int]:
        """Final amplitudes (u_R) of samples idx run as one model: (samples, outputs + gates, vectors), periods.
        The positions in idx of samples found unstable (verdict.py) are left in `self.unstable`."""
        model, stim, probes = self._joined([self.sample(i) for i in idx])
        amps, used, judged = self._integrate(model, stim, probes, self.engine_for(idx[0]))
        self.unstable = _unstable_samples(judged, len(idx))
        return amps.reshape(len(idx), len(self.outs) + len(self.gates), -1), used

    def _run_group(self, idx: list[int]) -> list[dict]:
        try:
            amps, used = self.amplitudes(idx)
        except (DivergenceError, Mech2SpiceError) as e:
            if len(idx) > 1:                 # find the sample that failed: run them one by one
                return [r for i in idx for r in self._run_group([i])]
            return [{"i": idx[0], "pass": False, "margin": -math.inf, "reason": str(e).splitlines()[0]}]
        return [self._record(i, amps[s], len(self.outs), used, s not in self.unstable) for s, i in enumerate(idx)]

    def _joined(self, pairs):
        """One model (the union of the samples) and stimulus, and the probes: outputs then gate channels."""
        if len(pairs) == 1:
            model, stim = pairs[0]
            model = _with_probes(model, self.channels, self.gates, "")
            return model, stim, self.outs + [f"gate:{g}" for g in self.gates]
        from .tolerance import union
        big = union([m for m, _ in pairs], [f"s{k}/" for k in range(len(pairs))])
        big.params, n, probes = self.p, self.model.n, []
        for k in range(len(pairs)):
            for o in self.outs:
                big.add_probe(f"s{k}/{o}", k * n + self.model.probes[o])
            for g, ch in zip(self.gates, self.channels):
                big.add_probe(f"s{k}/gate:{g}", k * n + ch)
            probes += [f"s{k}/{o}" for o in self.outs] + [f"s{k}/gate:{g}" for g in self.gates]
        amps = np.concatenate([s.amps for _, s in pairs], axis=1)
        return big, Stimulus(self.stim.times, amps), probes

    def _integrate(self, model, stim, probes, engine):
        """Amplitudes of every probe at the end and the stability verdicts (None without a state); engines
        with a state stop once the outputs have settled (simulation's settle rule on the output probes only,
        so a nominal sample matches `simulate`)."""
        if not engine.capabilities.state:
            run = engine.run(model, self.budget, stim, probes=probes)
            return run.final_amplitudes(probes, model.amplitude_unit), self.budget, None
        n_o, n_g = len(self.outs), len(self.gates)
        rows = [k for k in range(len(probes)) if k % (n_o + n_g) < n_o]
        return simulation._run_until_settled(engine, model, stim, probes, self.budget, False, self.fixed, watch=rows)

    def _record(self, i: int, a: np.ndarray, n_o: int, used: int, stable: bool = True) -> dict:
        """Pass/fail, margins, wrong output bits and root gate failures of one sample from its amplitudes; a
        sample whose network has a self-oscillating mode (`stable` False) fails whatever its bits read."""
        ao, ag = a[:n_o], a[n_o:]
        band_of, margin = self.p.levels.band_of, self.p.levels.margin
        got_o = np.vectorize(lambda x: -1 if band_of(x) is None else band_of(x))(ao) if ao.size else ao
        m_o = np.vectorize(margin)(ao, self.want_out) if ao.size else np.zeros((0, 1))
        bad_g = np.vectorize(lambda x, w: band_of(x) != w)(ag, self.want_gate) if ag.size else np.zeros((0, 1), bool)
        m_g = np.vectorize(margin)(ag, self.want_gate) if ag.size else np.zeros((0, 1))
        roots = set()
        for g in range(len(self.gates)):
            up_ok = np.all(~bad_g[self.feeders[g]], axis=0) if self.feeders[g] else np.ones(bad_g.shape[1], bool)
            if np.any(bad_g[g] & up_ok):
                roots.add(self.gates[g])
        wrong = {o: int(np.sum(got_o[k] != self.want_out[k])) for k, o in enumerate(self.outs)}
        return {"i": i, "pass": stable and not any(wrong.values()), "stable": stable,
                "margin": float(m_o.min()) if m_o.size else None,
                "gate_margin": float(m_g.min()) if m_g.size else None,
                "failing_bits": {o: c for o, c in wrong.items() if c}, "failing_gates": sorted(roots),
                "worst_gate": self.gates[int(np.argmin(m_g.min(axis=1)))] if m_g.size else None,
                "periods": int(used)}


def _unstable_samples(judged, n: int) -> set[int]:
    """Positions of the samples (DOF prefix "s{k}/" in a union of n samples) that carry a growing mode in any
    input vector's verdict; a lone sample is position 0."""
    bad = set()
    for v, _ in judged or []:
        if v.stable:
            continue
        if n == 1 or not v.converged:
            return set(range(n)) if not v.converged else {0}
        bad |= {int(d.split("/")[0][1:]) for m in v.modes if m.growth > 0 for d in m.dofs if "/" in d}
    return bad


def noise_seed(seed: int, i: int) -> int:
    """Sample i's noise seed: a function of (seed, i) only, apart from its spread draws."""
    return int(np.random.default_rng([seed, i, 0x6e6f]).integers(2 ** 31))


def _with_probes(model, channels, gates, prefix):
    """A shallow copy of `model` whose probes add every gate channel (as "gate:NAME")."""
    from dataclasses import replace
    probes = dict(model.probes)
    probes.update({f"{prefix}gate:{g}": ch for g, ch in zip(gates, channels)})
    return replace(model, probes=probes)


def job_key(job: dict) -> str:
    """A short hash naming what a results file holds (design, params, vectors, spec, seed, backend...).

    Parameters named by a file or a shipped block ('robust' changes when `mech2spice design` installs a
    better one) enter by their values, so a results file never resumes under other values; the built-in
    presets enter by name, which keeps the keys of results files written before blocks were data."""
    from ..physics.params import BUILTIN, DEFAULT_LEVELS, load_params
    keyed = dict(job)
    if job.get("params") not in BUILTIN:
        values = load_params(job["params"]).to_dict()
        if values["levels"] == DEFAULT_LEVELS.to_dict():
            del values["levels"]          # keys of results files written before levels were block data
        keyed["params_values"] = values
    return hashlib.sha256(json.dumps(keyed, sort_keys=True, default=str).encode()).hexdigest()[:16]


def netlist_sha256(netlist) -> str:
    """What a synthesized design computes, as a digest: top, ports, nodes with their kinds, wires. A results
    file keyed by it never resumes after its design was edited (the path alone named the edited file too)."""
    g = netlist.graph
    nodes = [(n, {k: v for k, v in a.items() if k != "cell"}) for n, a in g.nodes(data=True)]   # not src lines
    data = [netlist.top, netlist.inputs, netlist.outputs, netlist.clock, sorted(netlist.signed), nodes,
            *([list(netlist.sampled)] if netlist.sampled else []),      # the same hash as before where none
            [(u, v, a) for u, v, a in g.edges(data=True)]]
    return hashlib.sha256(json.dumps(data, sort_keys=True, default=str).encode()).hexdigest()


def summary(records: list[dict], n_gates: int) -> dict:
    """samples, failures, yield with its Wilson interval, margin quantiles, failing bits, per-gate rate."""
    n = len(records)
    passed = sum(bool(r["pass"]) for r in records)
    margins = np.array([r["margin"] if r.get("margin") is not None else np.nan for r in records], float)
    finite = margins[np.isfinite(margins)]       # a diverged sample's -inf has no place in a quantile
    bits, gates = {}, {}
    for r in records:
        for b, c in r.get("failing_bits", {}).items():
            bits[b] = bits.get(b, 0) + 1
        for g in r.get("failing_gates", []):
            gates[g] = gates.get(g, 0) + 1
    roots = sum(gates.values())
    judged = sum("failing_gates" in r for r in records)   # a sample refused before its run judged no gate
    rate = roots / (judged * n_gates) if judged and n_gates else None
    lo, hi = wilson(roots, judged * n_gates) if judged and n_gates else (0.0, 1.0)
    return {"samples": n, "failures": n - passed, "yield": passed / n if n else None,
            "yield_ci95": list(wilson(passed, n)),
            "margin_quantiles": {f"{q}%": float(np.percentile(finite, q)) for q in QUANTILES} if finite.size else {},
            "margin_samples": int(finite.size),   # the samples the quantiles are over (0: none has a margin)
            "failing_bits": dict(sorted(bits.items(), key=lambda kv: -kv[1])),
            "gate_failure_rate": rate,   # None: no gate judged (clocked runs; every sample refused before its run)
            "gate_failure_rate_ci95": [lo, hi], "gates": n_gates, "gate_samples": judged if n_gates else 0,
            "failing_gates": dict(sorted(gates.items(), key=lambda kv: -kv[1])[:20]),
            "reasons": _reasons(records)}


def _reasons(records: list[dict]) -> dict:
    out = {}
    for r in records:
        if r.get("reason"):
            out[r["reason"][:80]] = out.get(r["reason"][:80], 0) + 1
    return out


def design_path(path) -> Path:
    """The Verilog file of a design argument.  Only the path given: a shipped design of the same name is
    never used in its place (that ran a different design than the one asked for)."""
    p = Path(path)
    if not p.exists():
        raise Mech2SpiceError(f"no such file: {path} (the design to sample)")
    return p
