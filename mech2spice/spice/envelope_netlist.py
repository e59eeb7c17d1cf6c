"""The envelope equations (mech2spice.physics.envelope) as an ngspice netlist, and a runner for it.

Two nodes (Re, Im of A / u_R) per oscillating DOF and the carrier-level mobility form per slow DOF, so
ngspice can take steps of whole drive periods.  The circuit form, element by element: docs/spice.md,
section "The envelope netlist".
"""
from __future__ import annotations

import time
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np
import scipy.sparse as sp

from ..physics.envelope import Envelope
from . import readout
from ..errors import Mech2SpiceError, ToolMissingError
from ..physics.model import MechModel
from ._common import (NgspiceSettings, Namer, check_samples, comment_text, drive_schedule, failure, map_batch, num,
                      probe_dof_names)
from ..physics.stimulus import Stimulus
from ..run_result import Run

DRIVE_RAMP_PERIODS = 0.25       # tanh time constant of a drive-amplitude change (see _EnvEmitter._source)


@dataclass(frozen=True)
class EnvelopeSpiceOptions(NgspiceSettings):
    """ngspice settings for the envelope netlist (defaults measured in reports/speed_accuracy.md, section
    'SPICE on the envelope equations')."""
    max_step_periods: float = 2.0     # ngspice's max step, in drive periods (its LTE control may go lower)
    abstol: float = 1e-12             # currents = amplitude rates in u_R/s
    vntol: float = 1e-7               # voltages = amplitudes in u_R
    trtol: float = 7.0                # ngspice's default truncation-error factor

    def validate(self) -> None:
        """Refuse settings ngspice would reject or misread."""
        super().validate()
        if not (np.isfinite(self.trtol) and self.trtol > 0):
            raise Mech2SpiceError("EnvelopeSpiceOptions.trtol must be positive")


def _amp_scale(model: MechModel) -> float:
    p = model.params
    return float(p.u_r) if p is not None else 1.0


class _EnvEmitter:
    def __init__(self, model: MechModel, stimulus: Stimulus | None, periods: int, opts: EnvelopeSpiceOptions,
                 batch_index: int):
        model.check()
        opts.validate()
        if periods < 1:
            raise Mech2SpiceError("periods must be at least 1")
        self.m, self.opt, self.periods, self.b = model, opts, int(periods), batch_index
        self.env = Envelope.of(model)
        self.T = model.period
        self.u = _amp_scale(model)
        self.stimulus = stimulus
        namer = Namer()
        self.stem = [namer(n) for n in model.names]
        self.amp_namer = Namer()
        self.amp_nodes: dict[tuple, str] = {}
        self.amp_lines: list[str] = []
        self.lines: list[str] = []
        self.n_elem = {"C": 0, "G": 0, "F": 0, "B": 0, "V": 0}

    # node names
    def ar(self, j: int) -> str:
        """The node holding Re A_j / u_R of fast DOF j."""
        return f"ar_{self.stem[self.env.fast[j]]}"

    def ai(self, j: int) -> str:
        """The node holding Im A_j / u_R of fast DOF j."""
        return f"ai_{self.stem[self.env.fast[j]]}"

    def sx(self, j: int) -> str:
        """The displacement node of slow DOF j."""
        return f"sx_{self.stem[self.env.slow[j]]}"

    def sv(self, j: int) -> str:
        """The velocity node of slow DOF j."""
        return f"sv_{self.stem[self.env.slow[j]]}"

    def add(self, kind: str, text: str) -> None:
        """Append an element of type `kind` (C, G, F, B, V), numbered in order, with the rest of its line."""
        self.n_elem[kind] += 1
        self.lines.append(f"{kind}{self.n_elem[kind]} {text}")

    # drive amplitudes: one voltage source per distinct schedule
    def schedule(self, d: int) -> tuple[tuple[float, float], ...]:
        """The (time, amplitude) points of drive d for this batch member over the run."""
        return drive_schedule(self.m, self.stimulus, self.b, d, self.periods * self.T)

    def amp_node(self, d: int) -> str:
        """The amplitude node of drive d: one DC or B voltage source per distinct schedule."""
        sched = self.schedule(d)
        if sched not in self.amp_nodes:
            node = f"a_{self.amp_namer(self.m.drives[d].name or 'drive')}"
            self.amp_nodes[sched] = node
            src = self._source(sched)
            self.amp_lines.append(f"{'B' if src.startswith('V =') else 'V'}{node} {node} 0 {src}")
        return self.amp_nodes[sched]

    def _source(self, sched) -> str:
        """DC, or a B voltage source: each change a -> a' at t1 a smooth step (a'-a)/2 (1 + tanh((t-t1)/tau)),
        tau = DRIVE_RAMP_PERIODS T, centred on t1 like the envelope integrator's step change.  Not PWL: its
        corners are ngspice breakpoints, and right after one (adder, reltol 1e-5) the step fell by 4x per
        point to delmin = 1e-11 tmax and stayed there (a stall, no error)."""
        if len(sched) == 1:
            return f"DC {num(sched[0][1])}"
        tau = DRIVE_RAMP_PERIODS * self.T
        terms = [num(sched[0][1])]
        for (_, a0), (t1, a1) in zip(sched, sched[1:]):
            terms.append(f"{num((a1 - a0) / 2)}*(1 + tanh((time - {num(t1)})/{num(tau)}))")
        return "V = " + " + ".join(terms)

    # complex coupling k -> j as VCCS: inject Re/Im(z * A_k) into ar_j / ai_j
    def vccs(self, j: int, k: int, z: complex) -> None:
        """Inject Re / Im of z * A_k into ar_j / ai_j with up to four G sources."""
        zr, zi = float(z.real), float(z.imag)
        for out, coefs in ((self.ar(j), ((self.ar(k), zr), (self.ai(k), -zi))),
                           (self.ai(j), ((self.ar(k), zi), (self.ai(k), zr)))):
            for node, g in coefs:
                if g != 0.0:
                    self.add("G", f"0 {out} {node} 0 {num(g)}")

    def fast(self) -> None:
        """Emit the fast DOFs' rows: capacitors, derivative CCCS, linear VCCS, drives, quadratic B sources."""
        env = self.env
        nf = env.fast.size
        bdiag = env.Bop.diagonal()
        if np.any(bdiag == 0):
            raise Mech2SpiceError("the envelope operator has a zero diagonal (a massless oscillating DOF)")
        Boff = sp.coo_matrix(env.Bop - sp.diags(bdiag))
        Boff.eliminate_zeros()
        sensed = set(int(k) for k in Boff.col)
        for j in range(nf):
            for node, kind in ((self.ar(j), "r"), (self.ai(j), "i")):
                if j in sensed:
                    mid = f"d{kind}_{self.stem[env.fast[j]]}"
                    self.lines.append(f"Cd{kind}_{self.stem[env.fast[j]]} {node} {mid} 1")
                    self.lines.append(f"Vd{kind}_{self.stem[env.fast[j]]} {mid} 0 0")
                else:
                    self.add("C", f"{node} 0 1")
        # derivative couplings (fast-fast dashpots): inject -beta A_k' through CCCS
        for j, k, v in zip(Boff.row, Boff.col, Boff.data):
            beta = complex(v) / bdiag[j]
            br, bi = beta.real, beta.imag
            sk = self.stem[env.fast[k]]
            for out, coefs in ((self.ar(j), ((f"Vdr_{sk}", -br), (f"Vdi_{sk}", bi))),
                               (self.ai(j), ((f"Vdr_{sk}", -bi), (f"Vdi_{sk}", -br)))):
                for src, g in coefs:
                    if g != 0.0:
                        self.add("F", f"0 {out} {src} {num(g)}")
        # linear terms
        Z = sp.coo_matrix(env.Z0)
        for j, k, z in zip(Z.row, Z.col, Z.data):
            if z != 0:
                self.vccs(int(j), int(k), -complex(z) / bdiag[j])
        # drives
        D = sp.coo_matrix(env.Dmap)
        for j, d, v in zip(D.row, D.col, D.data):
            kappa = complex(v) / (bdiag[j] * self.u)
            node = self.amp_node(int(d))
            for out, g in ((self.ar(j), kappa.real), (self.ai(j), kappa.imag)):
                if g != 0.0:
                    self.add("G", f"0 {out} {node} 0 {num(g)}")
        # quadratic couplings: -(G s)_j A_j / b_j
        G = env.G.tocsr()
        for j in range(nf):
            lo, hi = G.indptr[j], G.indptr[j + 1]
            if lo == hi:
                continue
            gs = " + ".join(f"{num(g)}*V({self.sx(int(s))})" for s, g in zip(G.indices[lo:hi], G.data[lo:hi]))
            c = 1 / bdiag[j]
            cr, ci = float(c.real), float(c.imag)
            # Re(-gs c A) = gs (-cr ar + ci ai);  Im(-gs c A) = gs (-ci ar - cr ai)
            self.add("B", f"0 {self.ar(j)} I = ({gs})*({num(-cr)}*V({self.ar(j)}) + {num(ci)}*V({self.ai(j)}))")
            self.add("B", f"0 {self.ai(j)} I = ({gs})*({num(-ci)}*V({self.ar(j)}) + {num(-cr)}*V({self.ai(j)}))")

    def slow(self) -> None:
        """Emit the slow DOFs in mobility form (sv, sx nodes, K_s, C_s VCCS) and their -H |A|^2 / 2 force."""
        env = self.env
        for j in range(env.slow.size):
            self.add("C", f"{self.sv(j)} 0 {num(env.ms[j])}")
            self.add("C", f"{self.sx(j)} 0 1")
            self.add("G", f"0 {self.sx(j)} {self.sv(j)} 0 1")
        for M, nodes in ((env.Ks, self.sx), (env.Cs, self.sv)):
            M = sp.coo_matrix(M)
            for j, k, v in zip(M.row, M.col, M.data):
                if v != 0:
                    self.add("G", f"{self.sv(int(j))} 0 {nodes(int(k))} 0 {num(v)}")
        # force -H |A|^2 / 2 (amplitudes in u_R: |A|^2 = u^2 (ar^2 + ai^2))
        H = env.H.tocsr()
        for j in range(env.slow.size):
            lo, hi = H.indptr[j], H.indptr[j + 1]
            if lo == hi:
                continue
            terms = [f"{num(h * self.u ** 2 / 2)}*(V({self.ar(int(f))})*V({self.ar(int(f))}) + "
                     f"V({self.ai(int(f))})*V({self.ai(int(f))}))" for f, h in zip(H.indices[lo:hi], H.data[lo:hi])]
            self.add("B", f"{self.sv(j)} 0 I = " + " + ".join(terms))

    def probe_rows(self) -> list[int]:
        """The fast-DOF row of each probe (model.probes order); a probe on a slow DOF is an error."""
        pos = {int(d): k for k, d in enumerate(self.env.fast)}
        rows = []
        for name, dof in self.m.probes.items():
            if dof not in pos:
                raise Mech2SpiceError(f"probe '{name}' is on a slow DOF; the envelope netlist probes oscillating DOFs")
            rows.append(pos[dof])
        return rows

    def analysis(self, rows: list[int]) -> list[str]:
        """The .options, .tran, .save and .meas lines for the probed rows."""
        o = self.opt
        h = o.max_step_periods * self.T
        opts = (f".options method={o.method} reltol={num(o.reltol)} abstol={num(o.abstol)} "
                f"vntol={num(o.vntol)} chgtol={num(o.chgtol)} trtol={num(o.trtol)}")
        if o.method == "gear":
            opts += f" maxord={o.maxord}"
        out = [opts, f".tran {num(h)} {num(self.periods * self.T)} 0 {num(h)} uic"]
        nodes = [f"v({n(j)})" for j in rows for n in (self.ar, self.ai)]
        for k in range(0, len(nodes), 8):
            out.append(".save " + " ".join(nodes[k:k + 8]))
        return out

    READING = "|A| / u_R at the end of the run, A = V(ar) + i V(ai) (the nodes hold A in u_R)"

    def readout(self, rows: list[int]) -> list[str]:
        """The .control block a standalone `ngspice -b` run prints its decoded result with (not with -r)."""
        return readout.control_block(self.m, lambda k, i: readout.envelope_amplitude(
            k, self.ar(rows[i]), self.ai(rows[i])), self.READING)

    def reading_head(self, rows: list[int], about: str) -> list[str]:
        """The header's explanation of the result: probed nodes -> port bit, u_R, bands, how to run it."""
        nodes = [f"v({self.ar(j)}) v({self.ai(j)})" for j in rows]
        what = f"{self.READING}, t = {num(self.periods * self.T)}"
        return [f"* {s}" for s in readout.header(self.m, nodes, what, about, True, "ngspice -b THIS_FILE")]

    def netlist(self, title: str, reading: bool = False, about: str = "") -> tuple[str, list[str]]:
        """Emit every element; return the netlist text and the probes' raw-file vectors (`reading`: with the
        header and .control block that print the decoded result)."""
        self.fast()
        self.slow()
        rows = self.probe_rows()
        m, o = self.m, self.opt
        head = [f"* {comment_text(title or 'mech2spice envelope netlist')}",
                f"* mech2spice envelope form: {self.env.fast.size} oscillating DOFs (2 amplitude nodes each), "
                f"{self.env.slow.size} slow DOFs; {self.periods} periods of T = {num(self.T)} s (real time);",
                f"* amplitudes V(ar_*) + i V(ai_*) in u_R = {num(self.u)}; method={o.method}, max step "
                f"{num(o.max_step_periods)} T.  See docs/spice.md for the circuit form.",
                "* probe -> amplitude nodes:"]
        head += [f"*   {comment_text(n)} -> {self.ar(j)} {self.ai(j)}" for n, j in zip(m.probes, rows)]
        if reading:
            head = head[:3] + self.reading_head(rows, about) + head[3:]
        body = ["* --- circuit", *self.lines, "* --- drive amplitudes", *self.amp_lines,
                *self.analysis(rows), *(self.readout(rows) if reading else []), ".end"]
        vecs = [f"v({n(j)})".lower() for j in rows for n in (self.ar, self.ai)]
        return "\n".join(head + body) + "\n", vecs


def emit_envelope_with_probes(model: MechModel, stimulus: Stimulus | None = None, periods: int = 1000,
                              opts: EnvelopeSpiceOptions = EnvelopeSpiceOptions(), batch_index: int = 0,
                              title: str = "", reading: bool = False, about: str = "") -> tuple[str, list[str]]:
    """The netlist and the raw-file vectors (Re, Im per probe, model.probes order); without `reading` it is
    the form `ngspice -b -r out.raw` runs (no .control block)."""
    return _EnvEmitter(model, stimulus, periods, opts, batch_index).netlist(title, reading, about)


def emit_envelope(model: MechModel, stimulus: Stimulus | None = None, periods: int = 1000,
                  opts: EnvelopeSpiceOptions = EnvelopeSpiceOptions(), batch_index: int = 0, title: str = "",
                  about: str = "") -> str:
    """A self-contained netlist of the envelope equations that reads its own result: `ngspice -b file.cir`
    prints each output bit's amplitude and value and each port's integer (readout.py)."""
    return emit_envelope_with_probes(model, stimulus, periods, opts, batch_index, title, True, about)[0]


# --- running ---------------------------------------------------------------------------------------
NODE_PREFIXES = ("ar", "ai", "sx", "sv", "dr", "di")     # the envelope netlist's top-level node kinds


def _complex(names, data, vecs, u: float) -> np.ndarray:
    cols = [names.index(v) for v in vecs]
    x = data[:, cols]
    return u * (x[:, 0::2] + 1j * x[:, 1::2])


def run_one(model: MechModel, periods: int, stimulus: Stimulus | None = None,
            opts: EnvelopeSpiceOptions = EnvelopeSpiceOptions(), batch_index: int = 0,
            timeout: float | None = None, keep_netlist: str | Path | None = None):
    """One batch member under ngspice: (t_end (P,), amp (P, n_probes) complex, extra dict)."""
    from .runner import run_netlist
    t0 = time.perf_counter()
    text, vecs = emit_envelope_with_probes(model, stimulus, periods, opts, batch_index)
    t_emit = time.perf_counter() - t0
    if keep_netlist:
        Path(keep_netlist).write_text(text, encoding="ascii")
    try:
        names, data, _ = run_netlist(text, timeout=timeout or opts.time_limit)
    except ToolMissingError:
        raise
    except Mech2SpiceError as e:
        raise failure(model, e, lambda names, data: _complex(names, data, vecs, _amp_scale(model)) if set(vecs) <= set(names)
                      else None, NODE_PREFIXES) from None
    missing = [v for v in vecs if v not in names]
    if missing or names[:1] != ["time"]:
        raise Mech2SpiceError(f"ngspice raw file lacks {missing or ['time']}")
    T = model.period
    t = data[:, 0]
    z = _complex(names, data, vecs, _amp_scale(model))
    check_samples(model, t, z, probe_dof_names(model))
    t_end = (1 + np.arange(periods)) * T
    amp = np.stack([np.interp(t_end, t, z[:, j].real) + 1j * np.interp(t_end, t, z[:, j].imag)
                    for j in range(z.shape[1])], axis=1) if z.shape[1] else np.zeros((periods, 0), complex)
    dt = np.diff(t) / T
    extra = {"wall_s": time.perf_counter() - t0, "emit_s": t_emit, "points": int(t.size),
             "max_step_used_periods": float(dt.max()) if dt.size else 0.0,
             "median_step_periods": float(np.median(dt)) if dt.size else 0.0}
    return t_end, amp, extra


def run_envelope_spice(model: MechModel, periods: int, stimulus: Stimulus | None = None,
                       opts: EnvelopeSpiceOptions = EnvelopeSpiceOptions(), workers: int | None = None,
                       timeout: float | None = None):
    """The envelope netlist of every batch member of `stimulus` under ngspice (one process each, up to
    `workers` at a time); a Run whose per-period amplitudes are the envelope at each period's end."""
    B = stimulus.batch if stimulus is not None else 1
    parts = map_batch(lambda b: run_one(model, periods, stimulus, opts, b, timeout), B, workers)
    T = model.period
    amp = np.stack([p[1] for p in parts], axis=2)
    extra = {"backend": "ngspice-envelope", "options": asdict(opts),
             **{k: [p[2][k] for p in parts] for k in parts[0][2]}}
    return Run(list(model.probes), T, parts[0][0], amp, np.zeros(amp.shape), None, None, periods * T, extra=extra)
