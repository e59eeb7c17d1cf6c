"""The mechanical model as a VACASK netlist of compiled Verilog-A devices (spice/veriloga.py), and its runner.

Two forms from one emitter, as for ngspice (docs/vacask.md):

* carrier level: the mobility analogy, every element an OSDI device (m2s_nor2, m2s_couple, m2s_pairdrive,
  m2s_osc, ...); transient with trapezoidal steps pinned at max_step and the prewarp of spice/oscillator_netlist.py;
  per-period phasors by runner.demodulate.  The same netlist takes VACASK's harmonic-balance analysis
  (`emit_hb`, `run_hb`): the periodic steady state directly, phasors at omega and its harmonics.
* envelope level: physics/envelope.py's equations as m2s_env_* devices (two amplitude nodes per oscillating
  DOF); steps of whole periods; amplitudes at each period's end.

Which gate blocks become m2s_nor2 instances is decided as for ngspice (spice.oscillator_netlist's plan), plus: a
gate whose insulator is probed is emitted DOF by DOF (the insulator is internal to the block device).
Drive amplitudes are voltage nodes, one per distinct schedule (spice._common.drive_schedule): a DC source,
or a chain of series pulse sources, one ramp per change (VACASK has no PWL source).
"""
from __future__ import annotations

import functools
import math
import re
import tempfile
import time
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np

from ..errors import DivergenceError, Mech2SpiceError, ToolMissingError
from ..inputs import check_fields
from ..physics.model import MechModel
from ..physics.params import DEFAULT, GateParams
from ..physics.stimulus import Stimulus
from ..run_result import Run
from ._common import (check_samples, check_transient, comment_text, DEFAULT_TIMEOUT_S, drive_schedule,
                      map_batch, Namer, num, prewarp_scale, probe_dof_names)
from . import readout
from .oscillator_netlist import (Incidence, coupling_links, coupling_overrides, drive_split, gate_overrides,
                      gate_plan)

METHODS = ("trap", "gear")
RELREFS = ("pointlocal", "local", "pointglobal", "global")   # Newton's relative reference (VACASK relrefsol/res)
CARRIER, ENVELOPE = "carrier", "envelope"     # the two forms (veriloga.CARRIER, veriloga.ENVELOPE)
OSDI = {CARRIER: "m2s_carrier.osdi", ENVELOPE: "m2s_envelope.osdi"}   # veriloga.FILES, compiled
TRAN, HB = "tran1", "hb1"


# --- options ---------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class VacaskOptions:
    """VACASK transient settings for the carrier-level netlist (defaults measured: docs/vacask.md)."""
    method: str = "trap"              # tran_method: trap | gear (BDF)
    max_step_periods: float = 1 / 40  # max (and, pinned, actual) step in drive periods
    reltol: float = 1e-5
    abstol: float = 1e-12             # residual (force) tolerance
    vntol: float = 1e-9               # node (displacement, velocity) tolerance
    chgtol: float = 1e-14
    lteratio: float = 1e4             # tran_lteratio: a loose LTE bound keeps every step at max_step
    prewarp: bool = True              # trap only: exact phasor response at omega (spice/oscillator_netlist.py)
    # Newton's relative tolerance against each unknown's value at this point, as SPICE does; VACASK's default
    # ('local': its largest value so far) stopped early on oscillating nodes: the gate's '10' output settled
    # 4.6e-4 u_R off (1.6e-3 at T/80); 'pointlocal' matches HB and ngspice to 1e-10 at the same cost
    relref: str = "pointlocal"
    timeout_s: float | None = None    # one VACASK process; None: DEFAULT_TIMEOUT_S
    MAX_STEP_LIMIT = 0.25
    RAMP_PERIODS = 1e-3               # a drive-amplitude change ramps over this many periods

    def __post_init__(self):
        self.validate()              # a bad value fails where it is set, not later inside a run

    def validate(self) -> None:
        """Refuse settings VACASK would reject or misread."""
        check_fields(self)
        check_transient(self, "VACASK")
        if self.relref not in RELREFS:
            raise Mech2SpiceError(f"VACASK relref '{self.relref}' unknown (use {', '.join(RELREFS)})")
        if not (math.isfinite(self.lteratio) and self.lteratio > 1):
            raise Mech2SpiceError(f"{type(self).__name__}.lteratio must be > 1")

    @property
    def time_limit(self) -> float:
        """Seconds one VACASK process may run."""
        return self.timeout_s or DEFAULT_TIMEOUT_S

    @property
    def fixed_step(self) -> bool:
        """Prewarped trap needs every step at max_step."""
        return self.prewarp and self.method == "trap"

    def warp(self, omega: float) -> float:
        """Capacitor scale making trapezoidal steps of max_step exact at omega (1 without prewarp)."""
        return prewarp_scale(self)


@dataclass(frozen=True)
class VacaskEnvelopeOptions(VacaskOptions):
    """VACASK transient settings for the envelope netlist (amplitude nodes in u_R)."""
    max_step_periods: float = 2.0
    reltol: float = 1e-4
    vntol: float = 1e-7
    lteratio: float = 3.5             # VACASK's default: the truncation-error control sets the step
    prewarp: bool = False             # nothing oscillates in the envelope circuit
    MAX_STEP_LIMIT = 1000.0
    RAMP_PERIODS = 0.5


# --- the netlist -------------------------------------------------------------------------------------------
@dataclass
class Netlist:
    """An emitted netlist: its text, the raw-file vectors of the probes, and the OSDI it loads."""
    text: str
    vectors: list[str]
    form: str


class _Emitter:
    """Builds one VACASK netlist; `form` is veriloga.CARRIER or veriloga.ENVELOPE."""

    def __init__(self, model: MechModel, periods: int, stimulus: Stimulus | None, batch_index: int,
                 options: VacaskOptions, form: str):
        model.check()
        options.validate()
        if periods < 1:
            raise Mech2SpiceError("periods must be at least 1")
        self.m, self.periods, self.opt, self.form = model, int(periods), options, form
        self.stimulus, self.b = stimulus, batch_index
        self.env = form == ENVELOPE
        if self.env:
            from ..physics.envelope import Envelope
            Envelope.of(model)          # refuses what has no envelope form (slow-fast links, driven slow DOFs)
        self.p: GateParams = DEFAULT      # instance parameters are written where they differ from the library's
        self.T = 2 * math.pi / model.omega
        self.namer = {k: Namer() for k in ("dof", "amp")}
        self.stem = [self.namer["dof"](n) for n in model.names]
        self.inc = Incidence(model)
        self.plan = gate_plan(model, self.inc)
        probed = set(model.probes.values())
        self.plan.gates = [g for g in self.plan.gates if g.insulator not in probed]
        self._replan()
        self.lines: list[str] = []
        self.amp_nodes: dict[tuple, str] = {}
        self.amp_lines: list[str] = []

    def _replan(self) -> None:
        """Recompute what the kept gate blocks cover (after dropping some)."""
        from .oscillator_netlist import nor_quads
        self.plan.quads, self.plan.in_gate = set(), set()
        for g in self.plan.gates:
            self.plan.quads |= set(nor_quads(self.m, self.inc, g).values())
            self.plan.in_gate |= {g.channel, g.insulator, *[d for pair in g.inputs for d in pair]}

    # -- nodes: (displacement, velocity) or (Re A, Im A) per DOF; slow DOFs (sx, sv) in the envelope form
    def nodes(self, i: int) -> tuple[str, str]:
        """The two nodes of DOF i: (x, v) at carrier level, (Re A, Im A) or (s, s') in the envelope form."""
        s = self.stem[i]
        if not self.env:
            return f"x_{s}", f"v_{s}"
        return (f"sx_{s}", f"sv_{s}") if self.m.slow[i] else (f"ar_{s}", f"ai_{s}")

    def probe_vectors(self) -> list[str]:
        """The raw-file vectors holding each probe, in the model's probe order."""
        out = []
        for name, dof in self.m.probes.items():
            if self.env and self.m.slow[dof]:
                raise Mech2SpiceError(f"probe '{name}' is on a slow DOF; the envelope netlist probes oscillating DOFs")
            p, q = self.nodes(dof)
            out += [p, q] if self.env else [p]
        return out

    # -- drive amplitudes
    def schedule(self, d: int):
        """Drive d's (time, amplitude) changes for this batch member."""
        return drive_schedule(self.m, self.stimulus, self.b, d, self.periods * self.T)

    def amp_node(self, d: int, share: int | None = None) -> str:
        """The node carrying drive d's amplitude schedule (one per distinct schedule)."""
        sched = self.schedule(d)
        key = (d if share is None else share, sched)
        if key not in self.amp_nodes:
            stem = self.namer["amp"](self.m.drives[d].name or "drive")
            self.amp_nodes[key] = f"a_{stem}"
            self.amp_lines += self._source(stem, sched)
        return self.amp_nodes[key]

    def _source(self, stem: str, sched) -> list[str]:
        """DC, or a DC source and one pulse source in series per change (a ramp of RAMP_PERIODS centred on it).
        The chain's inner nodes and sources have prefixes of their own (ap<k>_, vp<k>_): no stem can reach them."""
        if len(sched) == 1:
            return [f"va_{stem} (a_{stem} 0) vsource dc={num(sched[0][1])}"]
        ramp = self.opt.RAMP_PERIODS * self.T
        out, lo = [f"vp0_{stem} (ap0_{stem} 0) vsource dc={num(sched[0][1])}"], f"ap0_{stem}"
        for k, ((_, a0), (t1, a1)) in enumerate(zip(sched, sched[1:]), 1):
            hi = f"a_{stem}" if k == len(sched) - 1 else f"ap{k}_{stem}"
            out.append(f"vp{k}_{stem} ({hi} {lo}) vsource type=\"pulse\" val0=0 val1={num(a1 - a0)} "
                       f"delay={num(max(t1 - ramp / 2, 0.0))} rise={num(ramp)}")
            lo = hi
        return out

    # -- instances
    def inst(self, kind: str, name: str, nodes: list[str], model: str, params) -> None:
        """Add one device instance line."""
        par = "".join(f" {k}={v}" for k, v in params)
        namer = self.namer.setdefault(kind, Namer())      # names are unique per kind; kinds keep prefixes apart
        self.lines.append(f"{kind}_{namer(name)} ({' '.join(nodes)}) {model}{par}")

    def gate(self, g) -> None:
        """A closed NOR block as one nor2 device."""
        (s1, d1), (s2, d2) = g.inputs
        src = self.inc.drives[g.channel][:1]
        self.plan.drives |= set(src)
        asrc = self.amp_node(src[0]) if src else "0"
        nodes = [*self.nodes(g.channel), asrc] + [n for dof in (s1, d1, s2, d2) for n in self.nodes(dof)]
        self.inst("xg", g.name, nodes, "nor2", gate_overrides(self.m, self.p, self.inc, g, src, channel_gamma="gc"))

    def couplings(self) -> None:
        """Channel -> gate-pair spring+dashpot links as one couple device; the rest as single elements."""
        m = self.m
        for nk, nc, up, s, d in coupling_links(m, self.inc, self.plan):
            self.inst("xc", m.names[s], [*self.nodes(up), *self.nodes(s), *self.nodes(d)], "couple",
                      coupling_overrides(m, self.p, nk, nc))
        for n, (i, j, k) in enumerate(m.springs):
            if n not in self.plan.springs:
                self.inst("xk", str(n), [*self.nodes(i), *self.nodes(j)], "spring", [("k", num(k))])
        for n, (i, j, c) in enumerate(m.dashpots):
            if n not in self.plan.dashpots:
                self.inst("xb", str(n), [*self.nodes(i), *self.nodes(j)], "dashpot", [("c", num(c))])

    def oscillators(self) -> None:
        """Every DOF no gate device carries, as its own oscillator device."""
        m = self.m
        for i in range(m.n):
            if i not in self.plan.in_gate:
                model = ("slow" if self.env else "osc_slow") if m.slow[i] else "osc"
                self.inst("xo", self.stem[i], list(self.nodes(i)), model,
                          [("mass", num(m.mass[i])), ("k", num(m.k_local[i])), ("c", num(m.c_local[i]))])
        for n, (f, s, g) in enumerate(m.quads):
            if n not in self.plan.quads:
                self.inst("xq", str(n), [*self.nodes(f), *self.nodes(s)], "quad", [("g", num(g))])

    def drives(self) -> None:
        """External pair drives as pairdrive devices, every other drive as a drive device."""
        m = self.m
        pairs, single = drive_split(m, self.inc, self.plan)
        for s, d, a, b in pairs:
            self.inst("xd", m.drives[a].name, [*self.nodes(s), *self.nodes(d), self.amp_node(a),
                                               self.amp_node(b, share=a)], "pairdrive",
                      [("ps", num(m.drives[a].phase)), ("pd", num(m.drives[b].phase))])
        for k in single:
            dr = m.drives[k]
            self.inst("xd", dr.name, [*self.nodes(dr.dof), self.amp_node(k)], "drive", [("ph", num(dr.phase))])

    # -- the whole file
    def models(self, osdi: str) -> list[str]:
        """load + model cards: omega and the prewarp (carrier) or u_R (envelope) are model parameters."""
        om = num(self.m.omega)
        if self.env:
            u = num(self.m.amplitude_unit)
            common = f"omega={om} u={u}"
            cards = [("osc", "m2s_env_osc", common), ("slow", "m2s_env_slow", ""), ("nor2", "m2s_env_nor2", common),
                     ("couple", "m2s_env_couple", common), ("spring", "m2s_env_spring", f"u={u}"),
                     ("dashpot", "m2s_env_dashpot", common), ("quad", "m2s_env_quad", f"u={u}"),
                     ("drive", "m2s_env_drive", ""), ("pairdrive", "m2s_env_pairdrive", "")]
        else:
            w = num(self.opt.warp(self.m.omega))
            cards = [("osc", "m2s_osc", f"w={w}"), ("osc_slow", "m2s_osc", "w=1.0"),
                     ("nor2", "m2s_nor2", f"omega={om} w={w}"), ("couple", "m2s_couple", ""),
                     ("spring", "m2s_spring", ""), ("dashpot", "m2s_dashpot", ""), ("quad", "m2s_quad", ""),
                     ("drive", "m2s_drive", f"omega={om}"), ("pairdrive", "m2s_pairdrive", f"omega={om}")]
        return [f'load "{osdi}"', "model vsource vsource"] + [f"model {a} {b} {c}".rstrip() for a, b, c in cards]

    def options_line(self) -> str:
        """The simulator options line from the settings."""
        o = self.opt
        return (f'options tran_method="{o.method}" reltol={num(o.reltol)} abstol={num(o.abstol)} '
                f"vntol={num(o.vntol)} chgtol={num(o.chgtol)} tran_lteratio={num(o.lteratio)} "
                f'relrefsol="{o.relref}" relrefres="{o.relref}" '
                # strictoutput=0: a run that fails keeps the rows it wrote (they name the DOF that diverged)
                "strictoutput=0")

    def tran(self) -> list[str]:
        """The transient analysis line: max step from the settings, starting from rest (uic)."""
        h = self.opt.max_step_periods * self.T
        # carrier: a quarter period past the end keeps the final short steps out of the last period
        tstop = (self.periods + (0 if self.env else 0.25)) * self.T
        return [f"analysis {TRAN} tran stop={num(tstop)} step={num(h)} maxstep={num(h)} icmode=\"uic\""]

    def circuit(self) -> None:
        """Emit gates, couplings and the remaining oscillators."""
        for g in self.plan.gates:
            self.gate(g)
        self.couplings()
        self.oscillators()
        self.drives()

    def reading(self) -> str:
        """How an output bit's amplitude is read from this netlist's raw file (the header says it)."""
        if self.env:
            return (f"|A| / u_R = sqrt(v(ar)^2 + v(ai)^2) at t = {num(self.periods * self.T)}, the run's end "
                    "(the nodes hold A in u_R)")
        t0, t1 = readout.period_window(self.periods, self.T)
        return (f"|A| / u_R, A the phasor at omega of the probed displacement over the last drive period, "
                f"t = {num(t0)}..{num(t1)}")

    def reading_head(self, about: str) -> list[str]:
        """The header's explanation of the result: probed node -> port bit, u_R, bands, and what VACASK
        cannot do (its control block has no command that evaluates results; `postprocess` runs Python)."""
        pairs = [self.nodes(d) for d in self.m.probes.values()]
        nodes = [f"v({a}) v({b})" if self.env else f"v({a})" for a, b in pairs]
        run = f"vacask THIS_FILE (in its folder); it writes {TRAN}.raw with the probed nodes"
        lines = readout.header(self.m, nodes, self.reading(), about, False, run)
        lines += ["VACASK cannot decode by itself: its control block evaluates no results (only `postprocess`,",
                  "which runs Python).  Read the amplitudes from the raw file as above, or emit for ngspice,",
                  "whose netlist prints them (--format ngspice or ngspice-envelope)."]
        return [f"// {s}" for s in lines]      # names in them are comment_text already

    def text(self, title: str, osdi: str, analysis: list[str], extra_head: list[str] = (), about: str = "") -> str:
        """The whole netlist: header (with how to read the result), models, circuit, analysis and save lines."""
        m, o = self.m, self.opt
        vecs = self.probe_vectors()
        head = [comment_text(title or "mech2spice VACASK netlist"),
                f"// mech2spice ({self.form} level): {m.n} DOFs, {len(self.plan.gates)} NOR blocks, "
                f"{self.periods} periods of T = {num(self.T)}; method {o.method}, max step {num(o.max_step_periods)} T",
                *self.reading_head(about), "// DOF -> nodes:"]
        head += [f"//   {comment_text(n)} -> {' '.join(self.nodes(i))}" for i, n in enumerate(m.names)]
        body = ["", "ground 0", *self.models(osdi), "", "// --- circuit", *self.lines, "// --- drive amplitudes",
                *self.amp_lines, "", "control", f"  {self.options_line()}", *[f"  {s}" for s in extra_head]]
        body += [f"  save {' '.join(f'v({v})' for v in vecs[k:k + 8])}" for k in range(0, len(vecs), 8)]
        body += [f"  {s}" for s in analysis] + ["endc"]
        return "\n".join(head + body) + "\n"


def _osdi_ref(form: str, standalone: bool) -> str:
    """What the netlist loads: the compiled library, placed beside it at run time (`run_netlist(forms=...)`),
    or, standalone, the .va embedded in the file (VACASK compiles it on load)."""
    return OSDI[form].replace(".osdi", ".va") if standalone else OSDI[form]


def emit(model: MechModel, periods: int, stimulus: Stimulus | None = None, batch_index: int = 0,
         options: VacaskOptions | None = None, form: str = CARRIER, title: str = "",
         standalone: bool = False, about: str = "") -> Netlist:
    """A VACASK transient netlist of `model` (standalone: loads the .va from its own directory, embedded);
    `about` (design, inputs) goes into the header that says how to read the result."""
    options = options or (VacaskEnvelopeOptions() if form == ENVELOPE else VacaskOptions())
    e = _Emitter(model, periods, stimulus, batch_index, options, form)
    e.circuit()
    ref = _osdi_ref(form, standalone)
    text = e.text(title, ref, e.tran(), about=about)
    if standalone:
        text += _embed(form)
    return Netlist(text, e.probe_vectors(), form)


_INSTANCE = re.compile(r"^(\w+) \(([^()]*)\) (\w+)")
_MODULE = re.compile(r"module\s+(\w+)\s*\(([^)]*)\);(.*?)endmodule", re.S)


@functools.lru_cache(maxsize=8)
def _internal_nodes(library: str) -> dict[str, tuple[str, ...]]:
    """Verilog-A module -> its internal nodes (declared electrical, not ports), from a library's text."""
    out = {}
    for m in _MODULE.finditer(library):
        ports = {p.strip() for p in m.group(2).split(",")}
        nodes = {n.strip() for decl in re.findall(r"electrical\s+([^;]+);", m.group(3)) for n in decl.split(",")}
        out[m.group(1)] = tuple(sorted(nodes - ports))
    return out


def netlist_unknowns(text: str, libraries: tuple[str, ...]) -> set[str]:
    """The node unknowns VACASK reports for a netlist this module emitted (lower case, as its raw files name
    them): every node an instance connects but ground, and `instance:node` for each internal node of the
    Verilog-A module behind it (`libraries`: the .va texts it loads).  A saved state's names are checked
    against this set before they go into the netlist's ic list."""
    internal = {k: v for lib in libraries for k, v in _internal_nodes(lib).items()}
    cards, out = {}, set()
    for line in text.split("\ncontrol\n", 1)[0].splitlines():       # the circuit: before the control block
        if line.startswith("model "):
            _, card, module = line.split()[:3]
            cards[card] = module
        elif m := _INSTANCE.match(line):
            inst, nodes, card = m.groups()
            out |= set(nodes.split()) - {"0"}
            out |= {f"{inst}:{n}" for n in internal.get(cards.get(card, ""), ())}
    return {n.lower() for n in out}


def _embed(form: str) -> str:
    """The Verilog-A library as an embedded file: the netlist alone is enough (VACASK compiles it on load)."""
    from . import veriloga as va
    name = va.FILES[form]
    return f'\nembed "{name}" <<<FILE\n{va.library(DEFAULT)[name]}>>>FILE\n'


# --- running -----------------------------------------------------------------------------------------------
_ABORTED = re.compile(r"^Analysis '\w+' aborted|^\s*error", re.I | re.M)
_ERR = re.compile(r"error|failed|not found|abort|cannot|singular|too small|unknown|syntax", re.I)


def _message(log: str) -> str | None:
    """The first line of VACASK's output that reports a failure (with the location line after a parse error)."""
    lines = [s.strip() for s in log.splitlines() if s.strip()]
    banner = next((k for k, s in enumerate(lines) if s.startswith("OpenBLAS CPUs")), -1)
    lines = lines[banner + 1:]                 # the banner says 'vacask unknown' (its version), no error
    for n, line in enumerate(lines):
        if _ERR.search(line):
            return " ".join(lines[n:n + 3])[:400]
    return None


def run_netlist(text: str, analysis: str = TRAN, timeout: float | None = None, workdir=None,
                forms: tuple[str, ...] = (), extra_files: dict | None = None) -> tuple[list[str], np.ndarray, str]:
    """Run a netlist under `vacask` in a temporary directory, the compiled libraries of `forms` (and
    `extra_files`: name -> path) beside it; returns (vector names, data, log) of the raw file
    `<analysis>.raw` (complex data as complex arrays)."""
    raws, log = run_netlist_raws(text, (analysis,), timeout, workdir, forms, extra_files)
    return (*raws[analysis], log)


def run_netlist_raws(text: str, analyses: tuple[str, ...], timeout: float | None = None, workdir=None,
                     forms: tuple[str, ...] = (), extra_files: dict | None = None) -> tuple[dict, str]:
    """`run_netlist` for a netlist of several analyses: ({analysis: (names, data)}, log); the first
    analysis must write data, the others may be missing (empty) when the first failed."""
    from . import veriloga as va
    from .openvaf import tools
    from .runner import run_guarded       # the process guard: timeout, interrupt and SIGTERM kill the child
    exe, _ = tools()
    timeout = timeout or DEFAULT_TIMEOUT_S
    raws = {}
    with tempfile.TemporaryDirectory(prefix="m2s_vc_") as tmp:
        d = Path(workdir or tmp)
        (d / "circuit.sim").write_text(text, encoding="ascii")
        beside = {OSDI[form]: va.compiled(form) for form in forms} | dict(extra_files or {})
        for name, target in beside.items():
            link = d / name
            link.unlink(missing_ok=True)
            link.symlink_to(target)
        try:
            proc = run_guarded([exe, "-qp", "circuit.sim"], d, timeout)
        except Mech2SpiceError as e:
            if "did not finish" in str(e):
                raise Mech2SpiceError(f"VACASK did not finish within {timeout:g} s "
                                      "(simulate --ngspice-timeout sets the limit)") from None
            raise
        log = proc.stdout + "\n" + proc.stderr
        for analysis in analyses:
            raw = d / f"{analysis}.raw"
            raws[analysis] = read_raw_any(raw) if raw.exists() and raw.stat().st_size else ([], np.zeros((0, 0)))
    names, data = raws[analyses[0]]
    # VACASK exits 0 when an analysis aborts: its log says so
    msg = _message(log) if proc.returncode != 0 or not len(data) or _ABORTED.search(log) else None
    if proc.returncode != 0 or msg or not len(data):
        err = Mech2SpiceError(f"VACASK failed (exit {proc.returncode}): {msg or 'no data written'}")
        err.names, err.data, err.log = names, data, log
        raise err
    return raws, log


def read_raw_any(path) -> tuple[list[str], np.ndarray]:
    """A binary raw file, real (spice.runner.read_raw) or complex (rows of complex values)."""
    from .runner import read_raw
    head = Path(path).read_bytes()[:4096]
    if b"Flags: complex" not in head:
        return read_raw(path)
    data = Path(path).read_bytes()
    mark = data.find(b"Binary:\n")
    lines = data[:mark].decode("ascii", "replace").splitlines()
    nvar = int(next(s.split(":", 1)[1] for s in lines if s.startswith("No. Variables")))
    at = next(k for k, s in enumerate(lines) if s.startswith("Variables:"))
    names = [lines[at + 1 + j].split()[1].lower() for j in range(nvar)]
    rows = (len(data) - mark - 8) // (16 * nvar)
    v = np.frombuffer(data, dtype="<f8", offset=mark + 8, count=rows * nvar * 2).reshape(rows, nvar, 2)
    return names, v[..., 0] + 1j * v[..., 1]


def _failure(model: MechModel, err: Mech2SpiceError, probe_values) -> Mech2SpiceError:
    """A failed run's error: DivergenceError naming the DOF if the probes blew up or VACASK's step collapsed
    ('Timestep too small'), else VACASK's own message.  `probe_values(names, data)`: the probes' samples."""
    names, data = getattr(err, "names", []), getattr(err, "data", np.zeros((0, 0)))
    values = probe_values(names, data) if data.ndim == 2 and data.shape[0] else None
    if values is not None:
        check_samples(model, data[:, 0].real, values, probe_dof_names(model))
    if "too small" not in str(err).lower():
        return err
    dofs = probe_dof_names(model) or model.names
    if values is None or not values.size:
        return DivergenceError(dofs[0], math.nan, model.period, math.nan)
    last = np.abs(values[-1])
    k = int(np.argmax(last))
    return DivergenceError(dofs[k], float(data[-1, 0].real), model.period, float(last[k]))


def _columns(vecs: list[str]):
    """probe_values for carrier-level vectors (None when the raw file lacks one)."""
    return lambda names, data: data[:, [names.index(v) for v in vecs]] if set(vecs) <= set(names) else None


def run(model: MechModel, periods: int, stimulus: Stimulus | None = None, options: VacaskOptions | None = None,
        batch_index: int = 0, keep_netlist: str | Path | None = None):
    """One batch member under VACASK (carrier level): a Run with per-period phasors."""
    from .runner import demodulate
    options = options or VacaskOptions()
    t0 = time.perf_counter()
    net = emit(model, periods, stimulus, batch_index, options)
    if keep_netlist:
        Path(keep_netlist).write_text(net.text, encoding="ascii")
    try:
        names, data, log = run_netlist(net.text, timeout=options.time_limit, forms=(CARRIER,))
    except ToolMissingError:
        raise
    except Mech2SpiceError as e:
        raise _failure(model, e, _columns(net.vectors)) from None
    t, x = data[:, 0], data[:, [names.index(v) for v in net.vectors]]
    check_samples(model, t, x, probe_dof_names(model))
    T, h = model.period, options.max_step_periods * model.period
    amp, mean = demodulate(t, x, model.omega, periods)
    dt = np.diff(t)
    uniform = float(np.mean(np.abs(dt - h) < 1e-6 * h)) if dt.size else 0.0
    extra = {"wall_s": time.perf_counter() - t0, "backend": "vacask", "points": int(t.size),
             "uniform_fraction": uniform}
    if options.fixed_step and uniform < 0.9:
        extra["warning"] = (f"only {uniform:.0%} of VACASK's steps were at max_step: the prewarp is inexact "
                            "(raise lteratio or lower max_step_periods)")
    xf = np.zeros((model.n, 1))
    end = np.searchsorted(t, periods * T * (1 + 1e-12))
    xf[list(model.probes.values()), 0] = x[max(end - 1, 0)]
    return Run(list(model.probes), T, (1 + np.arange(periods)) * T, amp[:, :, None], mean[:, :, None],
               xf, np.zeros((model.n, 1)), periods * T, extra=extra)


def run_envelope(model: MechModel, periods: int, stimulus: Stimulus | None = None,
                 options: VacaskEnvelopeOptions | None = None, batch_index: int = 0,
                 keep_netlist: str | Path | None = None) -> tuple[np.ndarray, np.ndarray, dict]:
    """One batch member under VACASK (envelope level): (t_end (P,), amp (P, n_probes) complex, extra)."""
    options = options or VacaskEnvelopeOptions()
    t0 = time.perf_counter()
    net = emit(model, periods, stimulus, batch_index, options, form=ENVELOPE)
    t_emit = time.perf_counter() - t0
    if keep_netlist:
        Path(keep_netlist).write_text(net.text, encoding="ascii")
    u = model.amplitude_unit
    probe = lambda names, data: u * (data[:, [names.index(v) for v in net.vectors[0::2]]]
                                     + 1j * data[:, [names.index(v) for v in net.vectors[1::2]]])
    try:
        names, data, log = run_netlist(net.text, timeout=options.time_limit, forms=(ENVELOPE,))
    except ToolMissingError:
        raise
    except Mech2SpiceError as e:
        raise _failure(model, e, lambda n, d: probe(n, d) if set(net.vectors) <= set(n) else None) from None
    t, z = data[:, 0], probe(names, data)
    check_samples(model, t, z, probe_dof_names(model))
    t_end = (1 + np.arange(periods)) * model.period
    amp = np.stack([np.interp(t_end, t, z[:, j].real) + 1j * np.interp(t_end, t, z[:, j].imag)
                    for j in range(z.shape[1])], axis=1) if z.shape[1] else np.zeros((periods, 0), complex)
    dt = np.diff(t) / model.period
    extra = {"wall_s": time.perf_counter() - t0, "emit_s": t_emit, "points": int(t.size),
             "max_step_used_periods": float(dt.max()) if dt.size else 0.0}
    return t_end, amp, extra


def run_batch(model: MechModel, periods: int, stimulus: Stimulus | None = None,
              options: VacaskOptions | None = None, workers: int | None = None):
    """Every batch member as its own VACASK process (carrier level), stacked along the batch axis."""
    B = stimulus.batch if stimulus is not None else 1
    runs = map_batch(lambda b: run(model, periods, stimulus, options, b), B, workers)
    first = runs[0]
    extra = {"backend": "vacask", **{k: [r.extra[k] for r in runs] for k in ("wall_s", "points", "uniform_fraction")}}
    warn = [r.extra["warning"] for r in runs if "warning" in r.extra]
    if warn:
        extra["warning"] = warn[0]
    return Run(first.probe_names, first.period, first.t_end,
               np.concatenate([r.amp for r in runs], axis=2), np.concatenate([r.mean for r in runs], axis=2),
               np.concatenate([r.x for r in runs], axis=1), np.concatenate([r.v for r in runs], axis=1),
               first.t, extra=extra)


def run_envelope_batch(model: MechModel, periods: int, stimulus: Stimulus | None = None,
                       options: VacaskEnvelopeOptions | None = None, workers: int | None = None):
    """Every batch member of the envelope netlist as its own VACASK process; amplitudes at period ends."""
    options = options or VacaskEnvelopeOptions()
    B = stimulus.batch if stimulus is not None else 1
    parts = map_batch(lambda b: run_envelope(model, periods, stimulus, options, b), B, workers)
    amp = np.stack([p[1] for p in parts], axis=2)
    extra = {"backend": "vacask-envelope", "options": asdict(options),
             **{k: [p[2][k] for p in parts] for k in parts[0][2]}}
    return Run(list(model.probes), model.period, parts[0][0], amp, np.zeros(amp.shape), None, None,
               periods * model.period, extra=extra)


# --- harmonic balance --------------------------------------------------------------------------------------
HB_NHARM = 4        # harmonics of omega kept: the insulator's 2 omega and the channel's 3 omega are ~1e-8 u_R


def _hb_line(model: MechModel, nharm: int) -> str:
    # the frequency must be omega / 2 pi to the last digit: the drives read $abstime, off the HB grid otherwise
    return f"analysis {HB} hb freq=[{num(model.omega / (2 * math.pi))}] nharm={int(nharm)}"


def emit_hb(model: MechModel, nharm: int = HB_NHARM, sweeps: list[tuple[str, list[float]]] = (),
            title: str = "") -> tuple[str, list[str], dict]:
    """A harmonic-balance netlist of `model` with its drives at their constant amplitudes (carrier level, no
    prewarp); `sweeps` are (amplitude-source instance, values), outermost first.  Returns (text, probe
    vectors, drive index -> its amplitude-source instance)."""
    if nharm < 1:
        raise Mech2SpiceError("harmonic balance needs at least one harmonic")
    e = _Emitter(model, 1, None, 0, VacaskOptions(prewarp=False), CARRIER)
    e.circuit()
    sources = {d: f"v{node}" for (d, _), node in e.amp_nodes.items()}     # constant drives: va_<stem>
    lines = [f"{'  ' * k}sweep s{k} instance=\"{inst}\" parameter=\"dc\" values=[{', '.join(num(v) for v in vals)}]"
             for k, (inst, vals) in enumerate(sweeps)]
    lines.append("  " * len(sweeps) + _hb_line(model, nharm))
    return e.text(title or "mech2spice harmonic balance", _osdi_ref(CARRIER, False), lines), \
        e.probe_vectors(), sources


def run_hb(model: MechModel, nharm: int = HB_NHARM, timeout: float | None = None) -> dict:
    """VACASK's harmonic balance of `model` (constant drives): the phasor of each probe at every harmonic."""
    text, vecs, _ = emit_hb(model, nharm)
    t0 = time.perf_counter()
    names, z, _ = run_netlist(text, HB, timeout, forms=(CARRIER,))
    return {"freq": z[:, names.index("frequency")].real, "wall_s": time.perf_counter() - t0,
            "phasors": {p: z[:, names.index(v)] for p, v in zip(model.probes, vecs)}}


def hb_map(levels, p: GateParams = DEFAULT, nharm: int = HB_NHARM, timeout: float | None = None) -> list[dict]:
    """The single gate's channel amplitude by harmonic balance for input levels [(x1, x2)] (fractions of F_R).
    A full grid (every x1 with every x2, x1 outermost) runs as one VACASK process sweeping both inputs, each
    point starting from the last one's solution; other lists, and any point the sweep did not deliver, run
    alone.  {'amp_ur', 'phase_deg', 'converged'} per level."""
    levels = [(float(a), float(b)) for a, b in levels]
    x1, x2 = list(dict.fromkeys(a for a, _ in levels)), list(dict.fromkeys(b for _, b in levels))
    found = _hb_sweep(x1, x2, p, nharm, timeout) if [(a, b) for a in x1 for b in x2] == levels else {}
    for lv in levels:
        if lv not in found:
            found.update(_hb_sweep([lv[0]], [lv[1]], p, nharm, timeout))
    failed = {"amp_ur": math.nan, "phase_deg": math.nan, "converged": False}
    return [found.get(lv, failed) for lv in levels]


def _hb_sweep(x1: list[float], x2: list[float], p: GateParams, nharm: int, timeout) -> dict:
    """HB of the single gate over the grid x1 x x2 in one process; {(x1, x2): result} for the points it
    delivered (read from the sweep variables in the raw file, so a skipped or aborted point is just absent)."""
    from ..physics import nor
    m = nor.single_gate(p)
    (s1, _), (s2, _) = m.design.input_drives
    _, _, sources = emit_hb(m, nharm)
    sweeps = [(sources[s1], [a * p.f_r for a in x1]), (sources[s2], [b * p.f_r for b in x2])]
    text, vecs, _ = emit_hb(m, nharm, sweeps)
    try:
        names, z, _ = run_netlist(text, HB, timeout, forms=(CARRIER,))
    except Mech2SpiceError as e:
        names, z = getattr(e, "names", []), getattr(e, "data", np.zeros((0, 0)))
    if not len(z) or not {"s0", "s1", "frequency"} <= set(names):
        return {}
    level = {round(a * p.f_r, 12): a for a in x1}, {round(b * p.f_r, 12): b for b in x2}
    out = {}
    for row in z[np.abs(z[:, names.index("frequency")].real - m.omega / (2 * math.pi)) < 1e-9 * m.omega]:
        key = (level[0].get(round(row[names.index("s0")].real, 12)), level[1].get(round(row[names.index("s1")].real, 12)))
        a = row[names.index(vecs[0])]
        out[key] = {"amp_ur": float(abs(a) / p.u_r), "phase_deg": float(np.degrees(np.angle(a))), "converged": True}
    return out
