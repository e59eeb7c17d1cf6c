"""The mechanical model as an oscillator-level ngspice circuit (mobility analogy) and its netlist.

Two nodes per DOF (velocity v, displacement x), trapezoidal prewarping for an exact phasor response at
the drive frequency, and hierarchical emission through the `.subckt` library (m2s_osc, m2s_nor2, ...).
The analogy, the prewarp and its measured errors: docs/spice.md, section "The carrier-level netlist".
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

from ..errors import Mech2SpiceError
from ..physics.model import MechModel
from ..physics.params import DEFAULT, GateParams
from ..physics.stimulus import Stimulus
from . import readout
from ._common import NgspiceSettings, Namer, comment_text, drive_schedule, num, prewarp_scale

@dataclass(frozen=True)
class SpiceOptions(NgspiceSettings):
    """ngspice settings for the carrier-level netlist (defaults measured in reports/speed_accuracy.md)."""
    max_step_periods: float = 1 / 40  # max (and, in steady state, actual) step, in drive periods
    # tolerances measured at T/40 (reports/speed_accuracy.md): reltol 1e-5 costs no time against 1e-3
    # (the step is pinned; only Newton iterations change) and cuts the NOR gate's trajectory error
    # 0.023 -> 0.0065 u_R; vntol 1e-6 (ngspice's default) let the settled gate drift 0.0033 u_R, 0.84 deg
    reltol: float = 1e-5
    vntol: float = 1e-9               # displacements are ~1e-2 (u_R = 0.0182)
    prewarp: bool = True              # trap only: exact phasor response at omega (see module doc)
    trtol: float | None = None        # None: 1e4 when prewarped (pins the step, below), else ngspice's 7
    noise_temperature: float = 0.0    # k_B T (model units): a trnoise source per dashpot (physics/noise.py)
    noise_seed: int = 0               # ngspice's seed is derived from it and the batch member
    MAX_STEP_LIMIT = 0.25             # a quarter period: coarser steps cannot resolve the carrier

    def validate(self) -> None:
        """Refuse settings ngspice would reject or misread."""
        super().validate()
        if self.trtol is not None and not (math.isfinite(self.trtol) and self.trtol > 0):
            raise Mech2SpiceError("SpiceOptions.trtol must be positive")
        from ..physics.noise import check_temperature
        check_temperature(self.noise_temperature)
        if self.noise_seed < 0:
            raise Mech2SpiceError(f"SpiceOptions.noise_seed {self.noise_seed}: must be an integer >= 0")

    @property
    def fixed_step(self) -> bool:
        """Prewarped trap needs every step at max_step: the warp is exact for that h only."""
        return self.prewarp and self.method == "trap"

    def trtol_value(self) -> float:
        """The trtol given to ngspice: the set one, else 1e4 when fixed_step (pins the step), else 7."""
        # ngspice's truncation-error control shrank steps below max_step at reltol 1e-6 (all steps;
        # 2 % phasor error on a linear chain); trtol 1e4 keeps them at max_step (error 7e-12)
        return self.trtol if self.trtol is not None else (1e4 if self.fixed_step else 7.0)

    def warp(self, omega: float) -> float:
        """Capacitor scale making trapezoidal steps of max_step exact at omega (1 without prewarp)."""
        return prewarp_scale(self)


OSC = """\
* m2s_osc: one mechanical oscillator, mobility analogy.
*   V(v) = velocity, V(x) = displacement; forces are currents injected into v.
*   m u'' = -k u - c u' + forces;  k, c are LOCAL values (may be negative).
*   w scales both capacitors (trapezoidal prewarp, see mech2spice.spice.oscillator_netlist); w = 1 for slow DOFs.
.subckt m2s_osc x v params: m=1 k=1 c=0 w={warp}
Cm v 0 {m*w}
Gc v 0 v 0 {c}
Gk v 0 x 0 {k}
Cx x 0 {w}
Gx 0 x v 0 1
.ends m2s_osc
"""

NOR2 = """\
* m2s_nor2: one NOR gate block (paper Fig. 3c).
*   Channel C (driven by the source), insulator I (slow), and per logical input n = 1, 2 a
*   spring-coupled gate ns and a dashpot-coupled gate nd.
* Ports: xc vc        channel displacement, velocity (the output)
*        asrc         source amplitude (a voltage): force V(asrc)*sin(omega*time+psrc) on the channel
*        x1s v1s v1d  input 1: spring gate displacement, velocity; dashpot gate velocity
*        x2s v2s v2d  input 2
* Params: m*, k*, c* per oscillator, k and c LOCAL (total minus attached couplings); defaults are an
*   unconnected gate's totals.  g* are the signed gammas of V = g u_f^2 u_i (gci = -gamma_ic).
.subckt m2s_nor2 xc vc asrc x1s v1s v1d x2s v2s v2d
+ params: mc={m_c} kc={k_c} cc={c_c} mi={m_i} ki={k_i} ci={c_i}
+ m1s={m_g} k1s={k_g} c1s={c_g} m1d={m_g} k1d={k_g} c1d={c_g}
+ m2s={m_g} k2s={k_g} c2s={c_g} m2d={m_g} k2d={k_g} c2d={c_g}
+ gci={-gamma_ic} g1s={gamma_ig} g1d={gamma_ig} g2s={gamma_ig} g2d={gamma_ig} psrc=0
Xc xc vc m2s_osc m={mc} k={kc} c={cc}
Xi xi vi m2s_osc m={mi} k={ki} c={ci} w=1
X1s x1s v1s m2s_osc m={m1s} k={k1s} c={c1s}
X1d x1d v1d m2s_osc m={m1d} k={k1d} c={c1d}
X2s x2s v2s m2s_osc m={m2s} k={k2s} c={c2s}
X2d x2d v2d m2s_osc m={m2d} k={k2d} c={c2d}
* quadratic couplings: force -2 g u_f u_i on each fast DOF, -sum g u_f^2 on the insulator
Bc vc 0 I = 2*gci*V(xc)*V(xi)
B1s v1s 0 I = 2*g1s*V(x1s)*V(xi)
B1d v1d 0 I = 2*g1d*V(x1d)*V(xi)
B2s v2s 0 I = 2*g2s*V(x2s)*V(xi)
B2d v2d 0 I = 2*g2d*V(x2d)*V(xi)
Bi vi 0 I = gci*V(xc)*V(xc) + g1s*V(x1s)*V(x1s) + g1d*V(x1d)*V(x1d) + g2s*V(x2s)*V(x2s) + g2d*V(x2d)*V(x2d)
Bsrc 0 vc I = V(asrc)*sin(omega*time+psrc)
.ends m2s_nor2
"""

COUPLE = """\
* m2s_couple: an upstream channel (xc, vc) driving a gate pair: spring k to the spring gate (xs, vs),
*   dashpot c to the dashpot gate (vd).  One VCCS per link injects into both ends (action = reaction).
.subckt m2s_couple xc vc xs vs vd params: k={k_couple} c={c_couple}
Gk vc vs xc xs {k}
Gc vc vd vc vd {c}
.ends m2s_couple
"""

DRIVE = """\
* m2s_drive: force V(amp)*sin(omega*time+ph) into the velocity node v.
.subckt m2s_drive v amp params: ph=0
B1 0 v I = V(amp)*sin(omega*time+ph)
.ends m2s_drive
"""

PAIRDRIVE = """\
* m2s_pairdrive: an external (or constant-level) input on a gate pair: the spring gate gets
*   V(amps)*sin(omega*time+ps), the dashpot gate V(ampd)*sin(omega*time+pd), pd = ps + pi/2, as an
*   upstream channel would drive them.  Amplitudes are voltages (DC for a constant level, PWL for a
*   schedule).
.subckt m2s_pairdrive vs vd amps ampd params: ps=0 pd=1.5707963267948966
Bs 0 vs I = V(amps)*sin(omega*time+ps)
Bd 0 vd I = V(ampd)*sin(omega*time+pd)
.ends m2s_pairdrive
"""

SUBCKTS = {"m2s_osc.subckt": OSC, "m2s_nor2.subckt": NOR2, "m2s_couple.subckt": COUPLE,
           "m2s_drive.subckt": DRIVE, "m2s_pairdrive.subckt": PAIRDRIVE}
PARAMS_FILE = "m2s_params.inc"


def param_values(p: GateParams, omega: float | None = None, warp: float = 1.0) -> dict[str, float]:
    """The global .param set the library reads (c_* derived from Q, couplings from F_R/u_R)."""
    return {"omega": p.omega if omega is None else omega, "warp": warp,
            "m_g": p.m_g, "k_g": p.k_g, "c_g": p.c_g, "m_i": p.m_i, "k_i": p.k_i, "c_i": p.c_i,
            "m_c": p.m_c, "k_c": p.k_c, "c_c": p.c_c, "gamma_ig": p.gamma_ig, "gamma_ic": p.gamma_ic,
            "f_c": p.f_c, "f_r": p.f_r, "u_r": p.u_r, "k_couple": p.k_couple, "c_couple": p.c_couple}


def params_text(values: dict[str, float], header: str) -> str:
    """`.param` lines for `values` under a `* header` comment line."""
    lines = [f"* {header}"]
    lines += [f".param {k}={num(v)}" for k, v in values.items()]
    return "\n".join(lines) + "\n"


def subckt_library(p: GateParams = DEFAULT) -> dict[str, str]:
    """filename -> text: the .param set of `p` and the five generic subcircuits."""
    head = f"mech2spice gate parameters '{comment_text(p.name)}' (c = m sqrt(k/m)/Q; warp=1: no prewarp)"
    return {PARAMS_FILE: params_text(param_values(p), head), **SUBCKTS}


LIBRARY_HEADS = (b"* m2s_", b"* mech2spice gate parameters")     # how each library file begins


def check_library_files(directory, p: GateParams = DEFAULT, inputs=(), force: bool = False) -> list[Path]:
    """The library's paths under `directory`, each one a file we may replace: never an input (`inputs`, e.g.
    the parameter file) nor a link; a file this library did not write only with `force`."""
    from ..inputs import check_output_file, head
    ours = ("a file of this library", lambda f: head(f, 64).startswith(LIBRARY_HEADS))
    paths = [Path(directory) / name for name in sorted(subckt_library(p))]
    for path in paths:
        if path.is_symlink():
            raise Mech2SpiceError(f"subckt file {path} is a link: refusing to replace it (remove it first)")
        check_output_file(path, inputs, "subckt file", kind=ours, force=force, parents=True)
    return paths


def write_subckt_library(directory, p: GateParams = DEFAULT, inputs=(), force: bool = False) -> list[Path]:
    """Write the library files into `directory` (created), every one checked before any is written
    (`check_library_files`), each replaced whole; returns their paths, sorted."""
    from ..inputs import write_bytes
    paths = check_library_files(directory, p, inputs, force)
    Path(directory).mkdir(parents=True, exist_ok=True)
    texts = subckt_library(p)
    for path in paths:
        write_bytes(path, texts[path.name].encode("ascii"))
    return paths


# --- netlist emission ------------------------------------------------------------
class Incidence:
    """Per-DOF lists of the elements touching it, so planning is linear in the model's size."""

    def __init__(self, model: MechModel):
        self.quads = self._index(model.n, [(f, s) for f, s, _ in model.quads])
        self.springs = self._index(model.n, [(i, j) for i, j, _ in model.springs])
        self.dashpots = self._index(model.n, [(i, j) for i, j, _ in model.dashpots])
        self.drives = self._index(model.n, [(d.dof,) for d in model.drives])

    @staticmethod
    def _index(n: int, ends) -> list[list[int]]:
        out = [[] for _ in range(n)]
        for k, dofs in enumerate(ends):
            for i in set(dofs):
                out[i].append(k)
        return out


@dataclass
class _Plan:
    """Which model elements the hierarchical instances already cover."""
    gates: list                     # GateBlocks emitted as m2s_nor2
    internal: dict[int, str]        # DOF -> hierarchical x node for probes (inside an m2s_nor2)
    in_gate: set[int]               # DOFs emitted inside an m2s_nor2
    quads: set[int]                 # indices of model.quads covered
    drives: set[int]                # indices of model.drives covered
    springs: set[int]
    dashpots: set[int]


def nor_quads(model: MechModel, inc: Incidence, g) -> dict[int, int] | None:
    """DOF -> quad index for the five quads an m2s_nor2 holds, or None if the block is not one."""
    if len(g.inputs) != 2:
        return None
    fast = [g.channel, *[d for pair in g.inputs for d in pair]]
    found = {}
    for qi in inc.quads[g.insulator]:
        f, s, _ = model.quads[qi]
        if s == g.insulator and f in fast and f not in found:
            found[f] = qi
    return found if len(found) == 5 else None


def gate_is_closed(model: MechModel, inc: Incidence, g, own_quads: set[int]) -> bool:
    """True if nothing outside the block touches its hidden nodes (insulator x/v, dashpot-gate x)."""
    hidden_x = (g.insulator, g.inputs[0][1], g.inputs[1][1])
    if any(set(inc.quads[i]) - own_quads or inc.springs[i] for i in hidden_x):
        return False
    return not (inc.dashpots[g.insulator] or inc.drives[g.insulator])


def gate_plan(model: MechModel, inc: Incidence) -> _Plan:
    """Which gates are closed NOR blocks a library instance can carry, and the DOFs and elements they take."""
    plan = _Plan([], {}, set(), set(), set(), set(), set())
    for g in model.design.gates:
        if getattr(g, "structure", "classic") != "classic":
            continue                                       # another block structure: DOF by DOF
        q = nor_quads(model, inc, g)
        dofs = {g.channel, g.insulator, *[d for pair in g.inputs for d in pair]}
        if q is None or len(dofs) != 6 or dofs & plan.in_gate or not gate_is_closed(model, inc, g, set(q.values())):
            continue                                       # emitted DOF by DOF instead
        plan.gates.append(g)
        plan.quads |= set(q.values())
        plan.in_gate |= dofs
    return plan


def gate_overrides(m: MechModel, p: GateParams, inc: Incidence, g, src, channel_gamma: str) -> list[tuple[str, str]]:
    """A closed gate's instance parameters that differ from the library defaults (its locals, sampled values).

    `channel_gamma` names the channel-insulator coupling's parameter in the target library."""
    (s1, d1), (s2, d2) = g.inputs
    roles = {"c": (g.channel, p.m_c, p.k_c, p.c_c), "i": (g.insulator, p.m_i, p.k_i, p.c_i),
             "1s": (s1, p.m_g, p.k_g, p.c_g), "1d": (d1, p.m_g, p.k_g, p.c_g),
             "2s": (s2, p.m_g, p.k_g, p.c_g), "2d": (d2, p.m_g, p.k_g, p.c_g)}
    out = []
    for r, (i, m0, k0, c0) in roles.items():
        for key, val, ref in (("m", m.mass[i], m0), ("k", m.k_local[i], k0), ("c", m.c_local[i], c0)):
            if not math.isclose(val, ref, rel_tol=1e-13, abs_tol=0.0):
                out.append((f"{key}{r}", num(val)))
    gam = {m.quads[q][0]: m.quads[q][2] for q in inc.quads[g.insulator] if m.quads[q][1] == g.insulator}
    for key, dof, ref in ((channel_gamma, g.channel, -p.gamma_ic), ("g1s", s1, p.gamma_ig), ("g1d", d1, p.gamma_ig),
                          ("g2s", s2, p.gamma_ig), ("g2d", d2, p.gamma_ig)):
        if gam[dof] != ref:
            out.append((key, num(gam[dof])))
    if src and m.drives[src[0]].phase != 0.0:
        out.append(("psrc", num(m.drives[src[0]].phase)))
    return out


def coupling_links(m: MechModel, inc: Incidence, plan):
    """(spring, dashpot, upstream DOF, spring gate, dashpot gate) for every channel -> gate-pair link of the
    planned gates that one coupling device can carry; the links taken are added to `plan`."""
    for s, d in (pair for g in plan.gates for pair in g.inputs):
        ks = [(n, sum(m.springs[n][:2]) - s) for n in inc.springs[s] if n not in plan.springs]
        cs = [(n, sum(m.dashpots[n][:2]) - d) for n in inc.dashpots[d] if n not in plan.dashpots]
        match = [(a, b) for a in ks for b in cs if a[1] == b[1]]
        if not match:
            continue
        (nk, up), (nc, _) = match[0]
        plan.springs.add(nk)
        plan.dashpots.add(nc)
        yield nk, nc, up, s, d


def drive_split(m: MechModel, inc: Incidence, plan) -> tuple[list[tuple[int, int, int, int]], list[int]]:
    """The drives a pair-drive device can carry, as (spring gate, dashpot gate, its drive, theirs), and the rest,
    leaving out the drives the planned gates already take."""
    used, pairs = set(plan.drives), []
    for g in plan.gates:
        for s, d in g.inputs:
            ds = [k for k in inc.drives[s] if k not in used]
            dd = [k for k in inc.drives[d] if k not in used]
            if len(ds) == 1 and len(dd) == 1:
                pairs.append((s, d, ds[0], dd[0]))
                used |= {ds[0], dd[0]}
    return pairs, [k for k in range(len(m.drives)) if k not in used]


def coupling_overrides(m: MechModel, p: GateParams, nk: int, nc: int) -> list[tuple[str, str]]:
    """A coupling device's k and c where they differ from the library's F_R/u_R and its dashpot."""
    k, c = m.springs[nk][2], m.dashpots[nc][2]
    return [(n, num(v)) for n, v, ref in (("k", k, p.k_couple), ("c", c, p.c_couple))
            if not math.isclose(v, ref, rel_tol=1e-13)]


NOISE_NT_PERIODS = 1 / 10     # trnoise's sample interval: sinc^4(f0 NT) = 0.968 at the drive frequency, corrected
def noisy_options(options: SpiceOptions, T: float, seed: int) -> SpiceOptions:
    """`options` with thermal noise at T (model units): unwarped, at most NOISE_MAX_STEP periods a step."""
    from dataclasses import replace
    return replace(options, noise_temperature=T, noise_seed=seed, prewarp=False,
                   max_step_periods=min(options.max_step_periods, NOISE_MAX_STEP))


NOISE_MAX_STEP = 1 / 400      # periods: a noisy netlist runs unwarped; trap's detuning (w h)^2 / 12 = 2e-5 is 1 % of a
                              # Q = 200 linewidth (the default T/40 would detune by 0.8 linewidths)


class _Emitter:
    def __init__(self, model: MechModel, periods: int, stimulus: Stimulus | None, batch_index: int,
                 options: SpiceOptions):
        self.m, self.periods, self.opt = model, int(periods), options
        self.p: GateParams = model.params or DEFAULT
        self.T = model.period
        self.h = options.max_step_periods * self.T
        # trnoise sets a breakpoint every NT, after which ngspice shortens the step: the prewarp, exact only
        # for steps of max_step, would mistune every oscillator, so a noisy netlist runs unwarped
        self.warp = 1.0 if options.noise_temperature else options.warp(model.omega)
        # one namer per prefix: stems are unique within a prefix, prefixes keep kinds apart
        self.namer = {k: Namer() for k in ("dof", "gate", "couple", "drive", "amp")}
        self.stem = [self.namer["dof"](n) for n in model.names]
        self.inc = Incidence(model)
        # with noise every DOF is emitted on its own: a gate block's insulator nodes are internal to its
        # .subckt, where a top-level noise source cannot reach them
        self.plan = _Plan([], {}, set(), set(), set(), set(), set()) if options.noise_temperature \
            else gate_plan(model, self.inc)
        self.lines: list[str] = []
        self.amp_nodes: dict[tuple, str] = {}
        self.amp_lines: list[str] = []
        self.stimulus, self.b = stimulus, batch_index

    def x(self, i: int) -> str:
        """The displacement node of DOF i."""
        return f"x_{self.stem[i]}"

    def v(self, i: int) -> str:
        """The velocity node of DOF i."""
        return f"v_{self.stem[i]}"

    def probe_node(self, i: int) -> str:
        """The node holding DOF i's displacement (hierarchical inside an m2s_nor2 instance)."""
        return self.plan.internal.get(i, self.x(i))

    # -- drive amplitudes: one voltage source per distinct schedule
    def schedule(self, d: int) -> tuple[tuple[float, float], ...]:
        """The (time, amplitude) points of drive d for this batch member over the run."""
        return drive_schedule(self.m, self.stimulus, self.b, d, self.periods * self.T)

    def amp_node(self, d: int, share: int | None = None) -> str:
        """The amplitude node of drive d (an editable source per drive; a pair's twin drive `share`
        reuses the node when its schedule is the same)."""
        sched = self.schedule(d)
        key = (d if share is None else share, sched)
        if key not in self.amp_nodes:
            node = f"a_{self.namer['amp'](self.m.drives[d].name or 'drive')}"
            self.amp_nodes[key] = node
            self.amp_lines.append(f"V{node} {node} 0 {self._source(sched)}")
        return self.amp_nodes[key]

    def _source(self, sched) -> str:
        if len(sched) == 1:
            return f"DC {num(sched[0][1])}"
        ramp = 1e-3 * self.T        # a step change centred on t1 (ngspice steps onto both corners)
        pts = [f"0 {num(sched[0][1])}"]
        for (t0, a0), (t1, a1) in zip(sched, sched[1:]):
            pts += [f"{num(t1 - ramp / 2)} {num(a0)}", f"{num(t1 + ramp / 2)} {num(a1)}"]
        return "PWL(" + " ".join(pts) + ")"

    # -- blocks
    def gate(self, g) -> None:
        """Emit gate block g as one m2s_nor2 instance (with its source drive and non-default params)."""
        inst = f"xg_{self.namer['gate'](g.name)}"
        (s1, d1), (s2, d2) = g.inputs
        src = self.inc.drives[g.channel][:1]
        self.plan.drives |= set(src)
        asrc = self.amp_node(src[0]) if src else "0"
        ports = [self.x(g.channel), self.v(g.channel), asrc, self.x(s1), self.v(s1), self.v(d1),
                 self.x(s2), self.v(s2), self.v(d2)]
        self.plan.internal.update({g.insulator: f"{inst}.xi", d1: f"{inst}.x1d", d2: f"{inst}.x2d"})
        over = gate_overrides(self.m, self.p, self.inc, g, src, channel_gamma="gci")
        self.lines.append(f"{inst} {' '.join(ports)} m2s_nor2" + "".join(f" {k}={v}" for k, v in over))

    def couplings(self) -> None:
        """Channel -> gate-pair spring+dashpot links as m2s_couple; the rest as single elements."""
        m = self.m
        for nk, nc, up, s, d in coupling_links(m, self.inc, self.plan):
            over = "".join(f" {n}={v}" for n, v in coupling_overrides(m, self.p, nk, nc))
            self.lines.append(f"Xc_{self.namer['couple'](m.names[s])} {self.x(up)} {self.v(up)} {self.x(s)} "
                              f"{self.v(s)} {self.v(d)} m2s_couple{over}")
        for n, (i, j, k) in enumerate(m.springs):
            if n not in self.plan.springs:
                self.lines.append(f"Gk_{n} {self.v(i)} {self.v(j)} {self.x(i)} {self.x(j)} {num(k)}")
        for n, (i, j, c) in enumerate(m.dashpots):
            if n not in self.plan.dashpots:
                self.lines.append(f"Gc_{n} {self.v(i)} {self.v(j)} {self.v(i)} {self.v(j)} {num(c)}")

    def oscillators(self) -> None:
        """Emit every DOF outside a gate block as m2s_osc, every uncovered quad as two B sources."""
        m = self.m
        for i in range(m.n):
            if i in self.plan.in_gate:
                continue
            w = " w=1" if m.slow[i] else ""
            self.lines.append(f"Xo_{self.stem[i]} {self.x(i)} {self.v(i)} m2s_osc m={num(m.mass[i])} "
                              f"k={num(m.k_local[i])} c={num(m.c_local[i])}{w}")
        for n, (f, s, g) in enumerate(m.quads):
            if n not in self.plan.quads:
                self.lines.append(f"Bqf_{n} {self.v(f)} 0 I = {num(2 * g)}*V({self.x(f)})*V({self.x(s)})")
                self.lines.append(f"Bqs_{n} {self.v(s)} 0 I = {num(g)}*V({self.x(f)})*V({self.x(f)})")

    def drives(self) -> None:
        """External pair drives as m2s_pairdrive, every other drive as m2s_drive."""
        m = self.m
        pairs, single = drive_split(m, self.inc, self.plan)
        for s, d, a, b in pairs:
            self.lines.append(
                f"Xd_{self.namer['drive'](m.drives[a].name)} {self.v(s)} {self.v(d)} {self.amp_node(a)} "
                f"{self.amp_node(b, share=a)} m2s_pairdrive ps={num(m.drives[a].phase)} pd={num(m.drives[b].phase)}")
        for k in single:
            d = m.drives[k]
            self.lines.append(f"Xd_{self.namer['drive'](d.name)} {self.v(d.dof)} {self.amp_node(k)} "
                              f"m2s_drive ph={num(d.phase)}")

    def noise(self) -> None:
        """One trnoise current source per fluctuating dashpot (physics/noise.py), when noise is on.

        trnoise(NA NT) draws a Gaussian of rms NA every NT and interpolates linearly: one-sided density
        2 NA^2 NT at low frequency, shaped by sinc^4(f NT).  NA = sqrt(2 T c / NT) / sinc^2(f0 NT) gives
        the fluctuation-dissipation density 4 T c exactly at the drive frequency f0."""
        T = self.opt.noise_temperature
        if not T:
            return
        from ..physics.noise import noisy_elements
        nt = NOISE_NT_PERIODS * self.T
        x = nt * self.m.omega / (2 * math.pi)
        sinc2 = (math.sin(math.pi * x) / (math.pi * x)) ** 2
        for e, (i, j, c) in enumerate(noisy_elements(self.m)):
            na = math.sqrt(2 * T * c / nt) / sinc2
            self.lines.append(f"Inz_{e} {self.v(j) if j >= 0 else 0} {self.v(i)} DC 0 trnoise({num(na)} {num(nt)} 0 0)")

    def noise_seed(self) -> int:
        """ngspice's seed for this batch member (each member its own noise)."""
        return (self.opt.noise_seed * 100003 + self.b) % (2 ** 31 - 2) + 1

    def analysis(self) -> list[str]:
        """The .options, .tran, .four and .save lines."""
        o = self.opt
        opts = f".options method={o.method} reltol={num(o.reltol)} abstol={num(o.abstol)} " \
               f"chgtol={num(o.chgtol)} vntol={num(o.vntol)} trtol={num(o.trtol_value())}"
        if o.method == "gear":
            opts += f" maxord={o.maxord}"
        if o.noise_temperature:
            opts += f" seed={self.noise_seed()}"
        # a quarter period past the end keeps ngspice's final short steps out of the last period
        tstop = (self.periods + 0.25) * self.T
        out = [opts, f".tran {num(self.h)} {num(tstop)} 0 {num(self.h)} uic"]
        nodes = [f"v({self.probe_node(i)})" for i in self.m.probes.values()]
        for k in range(0, len(nodes), 8):
            out.append(".save " + " ".join(nodes[k:k + 8]))
        return out

    READING = "|A| / u_R, A the phasor at omega of the probed displacement over the last drive period"

    def readout(self) -> list[str]:
        """The .control block a standalone `ngspice -b` run prints its decoded result with (not with -r:
        batch mode would run the circuit twice, once for the raw file)."""
        t0, t1 = readout.period_window(self.periods, self.T)
        nodes = [self.probe_node(i) for i in self.m.probes.values()]
        # noise breakpoints shorten steps (see __init__): then the grid is not uniform
        uniform = self.opt.fixed_step and not self.opt.noise_temperature
        return readout.control_block(self.m, lambda k, i: readout.carrier_amplitude(
            k, nodes[i], self.m.omega, t0, t1, self.m.amplitude_unit, uniform), self.READING,
            readout.period_mask(t0, t1))

    def reading_head(self, about: str) -> list[str]:
        """The header's explanation of the result: probed node -> port bit, u_R, bands, how to run it."""
        t0, t1 = readout.period_window(self.periods, self.T)
        nodes = [f"v({self.probe_node(i)})" for i in self.m.probes.values()]
        what = f"{self.READING}, t = {num(t0)}..{num(t1)}"
        return [f"* {s}" for s in readout.header(self.m, nodes, what, about, True, "ngspice -b THIS_FILE")]

    def netlist(self, title: str, reading: bool = False, about: str = "") -> str:
        """Emit every element and return the whole netlist text (`reading`: with the header and .control
        block that print the decoded result)."""
        m, o = self.m, self.opt
        for g in self.plan.gates:
            self.gate(g)
        self.couplings()
        self.oscillators()
        self.drives()
        self.noise()
        head = [f"* {comment_text(title or 'mech2spice netlist')}",
                f"* mech2spice: {m.n} DOFs, {len(self.plan.gates)} NOR blocks, {self.periods} periods of "
                f"T = {num(self.T)}; method={o.method}, max step {num(o.max_step_periods)} T, prewarp w = "
                f"{num(self.warp)}",
                "* DOF -> displacement node:"]
        head += [f"*   {comment_text(n)} -> {self.probe_node(i)}" for i, n in enumerate(m.names)]
        if reading:
            head = head[:2] + self.reading_head(about) + head[2:]
        body = [params_text(param_values(self.p, m.omega, self.warp), "parameters").rstrip("\n")]
        body += [t.rstrip("\n") for t in SUBCKTS.values()]
        body += ["* --- circuit", *self.lines, "* --- drive amplitudes", *self.amp_lines, *self.analysis()]
        body += [*(self.readout() if reading else []), ".end"]
        return "\n".join(head + body) + "\n"


def emit(model: MechModel, periods: int, stimulus: Stimulus | None = None, batch_index: int = 0,
         options: SpiceOptions = SpiceOptions(), title: str = "", about: str = "") -> str:
    """A self-contained netlist that reads its own result: `ngspice -b file.cir` runs it and prints each
    output bit's amplitude and value and each port's integer (readout.py); `about` names design and inputs."""
    return emit_with_probes(model, periods, stimulus, batch_index, options, title, reading=True, about=about)[0]


def emit_with_probes(model: MechModel, periods: int, stimulus: Stimulus | None = None, batch_index: int = 0,
                     options: SpiceOptions = SpiceOptions(), title: str = "", reading: bool = False,
                     about: str = "") -> tuple[str, list[str]]:
    """The netlist and the raw-file vector name of each probe (model.probes order); without `reading`
    it is the form `ngspice -b -r out.raw` runs (no .control block)."""
    model.check()
    options.validate()
    if periods < 1:
        raise Mech2SpiceError("periods must be at least 1")
    e = _Emitter(model, periods, stimulus, batch_index, options)
    text = e.netlist(title, reading, about)
    return text, [f"v({e.probe_node(i)})".lower() for i in model.probes.values()]
