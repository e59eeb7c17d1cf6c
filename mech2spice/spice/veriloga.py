"""The gate and its couplings as Verilog-A modules (compiled to OSDI by OpenVAF, loaded by VACASK).

Two libraries of the same equations (physics/model.py):

* carrier level (``m2s_carrier.va``): the mobility analogy of spice/oscillator_netlist.py, one module per element.
  Each oscillating DOF has a displacement node x and a velocity node v; force balance is the current
  balance at v:  I(v) <+ ddt(m w V(v)) + c V(v) + k V(x) + couplings - drives,  and  I(x) <+ ddt(w V(x)) - V(v)
  makes V(x) the integral of V(v).  w is the trapezoidal prewarp of spice/oscillator_netlist.py (a model parameter:
  one value per circuit; slow DOFs use a model with w = 1).  Drives read $abstime, which VACASK's
  transient and harmonic-balance analyses both supply.
* envelope level (``m2s_envelope.va``): physics/envelope.py's equations in real time.  An oscillating DOF
  has two nodes, V(ar) + i V(ai) = A / u (u = u_R, a model parameter, so voltage tolerances read in u_R);
  its row  (2 i omega m + c) A' + (k - omega^2 m + i omega c) A + (G s) A - F^ = 0  is the current balance at
  ar (real part) and ai (imaginary part).  A complex 'capacitance' 2 i omega m is a charge that depends on
  the other node: no capacitor can be it, a Verilog-A ddt() can.  Slow DOFs keep the mobility form
  (nodes sx, sv); their force -gamma |A|^2 / 2 is the period average of -gamma u_f^2.

Every stiffness and damping an element holds is LOCAL (total minus the couplings attached, may be
negative), as in the ngspice library; coupling modules add the rest, so the circuit's matrices are the
model's K and C.  Parameter defaults are the nominal gate (physics.params.DEFAULT) so a hand-written
netlist needs no parameters; instance parameters carry (*type="instance"*) (OpenVAF treats a bare
parameter as a model parameter, which VACASK does not accept on an instance line).

``library()`` gives the files; ``write_library(dir)`` writes them byte-stable (checked in under
``veriloga/``); ``compiled(form)`` compiles one (spice/openvaf.py).
"""
from __future__ import annotations

from pathlib import Path

from ..physics.params import DEFAULT, GateParams
from ._common import comment_text
# tools is re-exported for reports/vacask.py until it moves (#28); new code imports openvaf
from .openvaf import compile_va, module_text, tools  # noqa: F401

CARRIER, ENVELOPE = "carrier", "envelope"
FILES = {CARRIER: "m2s_carrier.va", ENVELOPE: "m2s_envelope.va"}

# the NOR block's roles: (suffix, role of the DOF) in port order after the channel
GATE_ROLES = ("1s", "1d", "2s", "2d")


# --- text helpers ----------------------------------------------------------------------------------------
def _sum(terms: list[str]) -> str:
    return " + ".join(terms).replace("+ -", "- ")


def _roles(p: GateParams) -> list[tuple[str, float, float, float]]:
    """(suffix, m, k, c) of the NOR block's oscillating DOFs: channel, then the four input gates."""
    return [("c", p.m_c, p.k_c, p.c_c)] + [(r, p.m_g, p.k_g, p.c_g) for r in GATE_ROLES]


def _gammas(p: GateParams) -> list[tuple[str, float]]:
    return [("gc", -p.gamma_ic)] + [(f"g{r}", p.gamma_ig) for r in GATE_ROLES]


def _block_params(p: GateParams) -> list[tuple[str, float, bool]]:
    out = []
    for r, m, k, c in _roles(p)[:1] + [("i", p.m_i, p.k_i, p.c_i)] + _roles(p)[1:]:
        out += [(f"m{r}", m, True), (f"k{r}", k, True), (f"c{r}", c, True)]
    return out + [(g, v, True) for g, v in _gammas(p)] + [("psrc", 0.0, True)]


# --- carrier level -------------------------------------------------------------------------------------
def _osc_rows(x: str, v: str, m: str, k: str, c: str, extra: list[str], w: str = "w") -> list[str]:
    """Force balance at v (extra: coupling/drive terms, already signed) and V(x) = integral of V(v)."""
    scale = f"{m}*{w}" if w else m
    return [f"I({v}) <+ {_sum([f'ddt({scale}*V({v}))', f'{c}*V({v})', f'{k}*V({x})', *extra])};",
            f"I({x}) <+ {_sum([f'ddt({w}*V({x}))' if w else f'ddt(V({x}))', f'-V({v})'])};"]


def _carrier_modules(p: GateParams) -> list[str]:
    model = [("omega", p.omega, False), ("w", 1.0, False)]
    osc = module_text("m2s_osc", ["x", "v"], [], model[1:] + [("mass", 1.0, True), ("k", 1.0, True), ("c", 0.0, True)],
                      _osc_rows("x", "v", "mass", "k", "c", []),
                      "m2s_osc: one oscillator, mobility analogy (V(v) velocity, V(x) displacement).\n"
                      "mass u'' = -k u - c u' + forces (currents into v); k, c LOCAL; w: prewarp (model parameter).")
    # NOR block: channel c, insulator i (internal, slow, w = 1), input gates 1s 1d 2s 2d
    body = []
    for (r, *_), (g, _) in zip(_roles(p), _gammas(p)):
        extra = [f"2*{g}*V(x{r})*V(xi)"] + (["-V(asrc)*sin(omega*$abstime + psrc)"] if r == "c" else [])
        body += _osc_rows(f"x{r}", f"v{r}", f"m{r}", f"k{r}", f"c{r}", extra)
    body += _osc_rows("xi", "vi", "mi", "ki", "ci", [f"{g}*V(x{r})*V(x{r})" for (r, *_), (g, _) in
                                                     zip(_roles(p), _gammas(p))], w="")
    ports = ["xc", "vc", "asrc"] + [f"{n}{r}" for r in GATE_ROLES for n in ("x", "v")]
    nor2 = module_text("m2s_nor2", ports, ["xi", "vi"], model + _block_params(p), body,
                       "m2s_nor2: one NOR gate block (paper Fig. 3c): channel c driven by V(asrc) sin(omega t + psrc),\n"
                       "slow insulator i (internal nodes xi, vi), input gates 1s 1d 2s 2d (spring-, dashpot-coupled).\n"
                       "Quadratic couplings V = g u_f^2 u_i: force -2 g u_f u_i on each gate, -sum g u_f^2 on i.\n"
                       "Defaults: an unconnected gate's totals; gc = -gamma_ic, g1s.. = gamma_ig.")
    couple = module_text("m2s_couple", ["xc", "vc", "xs", "vs", "xd", "vd"], [],
                         [("k", p.k_couple, True), ("c", p.c_couple, True)],
                         ["I(vc) <+ k*(V(xc) - V(xs)) + c*(V(vc) - V(vd));",
                          "I(vs) <+ k*(V(xs) - V(xc));", "I(vd) <+ c*(V(vd) - V(vc));"],
                         "m2s_couple: an upstream channel (xc, vc) driving a gate pair: spring k to the spring gate\n"
                         "(xs, vs), dashpot c to the dashpot gate (xd, vd); action = reaction.")
    spring = module_text("m2s_spring", ["xa", "va", "xb", "vb"], [], [("k", 1.0, True)],
                         ["I(va) <+ k*(V(xa) - V(xb));", "I(vb) <+ k*(V(xb) - V(xa));"],
                         "m2s_spring: a coupling spring k between two DOFs.")
    dashpot = module_text("m2s_dashpot", ["xa", "va", "xb", "vb"], [], [("c", 1.0, True)],
                          ["I(va) <+ c*(V(va) - V(vb));", "I(vb) <+ c*(V(vb) - V(va));"],
                          "m2s_dashpot: a coupling dashpot c between two DOFs.")
    quad = module_text("m2s_quad", ["xf", "vf", "xs", "vs"], [], [("g", 1.0, True)],
                       ["I(vf) <+ 2*g*V(xf)*V(xs);", "I(vs) <+ g*V(xf)*V(xf);"],
                       "m2s_quad: potential g u_f^2 u_s between an oscillating DOF f and a slow DOF s.")
    drive = module_text("m2s_drive", ["x", "v", "amp"], [], [("omega", p.omega, False), ("ph", 0.0, True)],
                        ["I(v) <+ -V(amp)*sin(omega*$abstime + ph);"],
                        "m2s_drive: force V(amp) sin(omega t + ph) into the velocity node v.")
    pair = module_text("m2s_pairdrive", ["xs", "vs", "xd", "vd", "amps", "ampd"], [],
                       [("omega", p.omega, False), ("ps", 0.0, True), ("pd", 1.5707963267948966, True)],
                       ["I(vs) <+ -V(amps)*sin(omega*$abstime + ps);", "I(vd) <+ -V(ampd)*sin(omega*$abstime + pd);"],
                       "m2s_pairdrive: an external input on a gate pair, as an upstream channel would drive it:\n"
                       "V(amps) sin(omega t + ps) on the spring gate, V(ampd) sin(omega t + pd) on the dashpot gate.")
    return [osc, nor2, couple, spring, dashpot, quad, drive, pair]


# --- envelope level ------------------------------------------------------------------------------------
def _env_rows(r: str, i: str, m: str, k: str, c: str, extra_r: list[str], extra_i: list[str]) -> list[str]:
    """Re and Im of (2 i omega m + c) A' + (k - omega^2 m + i omega c) A + extra = 0, A = u (V(r) + i V(i))."""
    kk = f"({k} - omega*omega*{m})"
    return [f"I({r}) <+ {_sum([f'ddt(u*({c}*V({r}) - 2*omega*{m}*V({i})))', f'u*({kk}*V({r}) - omega*{c}*V({i}))', *extra_r])};",
            f"I({i}) <+ {_sum([f'ddt(u*({c}*V({i}) + 2*omega*{m}*V({r})))', f'u*({kk}*V({i}) + omega*{c}*V({r}))', *extra_i])};"]


def _slow_rows(x: str, v: str, m: str, k: str, c: str, extra: list[str]) -> list[str]:
    return _osc_rows(x, v, m, k, c, extra, w="")


def _env_drive(r: str, i: str, amp: str, ph: str) -> tuple[str, str]:
    """-F^ for F^ = -i a e^{i ph}: (Re, Im) terms."""
    return f"-V({amp})*sin({ph})", f"V({amp})*cos({ph})"


def _envelope_modules(p: GateParams) -> list[str]:
    model = [("omega", p.omega, False), ("u", p.u_r, False)]
    osc = module_text("m2s_env_osc", ["ar", "ai"], [], model + [("mass", 1.0, True), ("k", 1.0, True), ("c", 0.0, True)],
                      _env_rows("ar", "ai", "mass", "k", "c", [], []),
                      "m2s_env_osc: the envelope A = u (V(ar) + i V(ai)) of one oscillating DOF, u = u_R.\n"
                      "(2 i omega m + c) A' + (k - omega^2 m + i omega c) A = F^ (currents into ar, ai); k, c LOCAL.")
    slow = module_text("m2s_env_slow", ["sx", "sv"], [], [("mass", 1.0, True), ("k", 1.0, True), ("c", 0.0, True)],
                       _slow_rows("sx", "sv", "mass", "k", "c", []),
                       "m2s_env_slow: a slow DOF (insulator), mobility form: V(sv) velocity, V(sx) displacement.")
    body = []
    for (r, *_), (g, _) in zip(_roles(p), _gammas(p)):
        er, ei = [f"2*{g}*V(sx)*u*V(ar{r})"], [f"2*{g}*V(sx)*u*V(ai{r})"]
        if r == "c":
            dr, di = _env_drive("arc", "aic", "asrc", "psrc")
            er, ei = er + [dr], ei + [di]
        body += _env_rows(f"ar{r}", f"ai{r}", f"m{r}", f"k{r}", f"c{r}", er, ei)
    body += _slow_rows("sx", "sv", "mi", "ki", "ci",
                       [f"{g}*u*u*(V(ar{r})*V(ar{r}) + V(ai{r})*V(ai{r}))/2"
                        for (r, *_), (g, _) in zip(_roles(p), _gammas(p))])
    ports = ["arc", "aic", "asrc"] + [f"{n}{r}" for r in GATE_ROLES for n in ("ar", "ai")]
    nor2 = module_text("m2s_env_nor2", ports, ["sx", "sv"], model + _block_params(p), body,
                       "m2s_env_nor2: the NOR block's envelope equations: channel c (source V(asrc) sin(omega t + psrc)),\n"
                       "input gates 1s 1d 2s 2d as amplitude node pairs, the slow insulator inside (sx, sv).\n"
                       "Quadratic couplings: (G s) A = 2 g s A on each gate row, g |A|^2 / 2 on the insulator.")
    couple_body = ["I(arc) <+ u*k*(V(arc) - V(ars));", "I(aic) <+ u*k*(V(aic) - V(ais));",
                   "I(ars) <+ u*k*(V(ars) - V(arc));", "I(ais) <+ u*k*(V(ais) - V(aic));"]
    couple_body += _env_dashpot("arc", "aic", "ard", "aid")
    couple = module_text("m2s_env_couple", ["arc", "aic", "ars", "ais", "ard", "aid"], [],
                         model + [("k", p.k_couple, True), ("c", p.c_couple, True)], couple_body,
                         "m2s_env_couple: an upstream channel driving a gate pair, envelope form: spring k to the\n"
                         "spring gate, dashpot c to the dashpot gate ((c d/dt + i omega c) on the amplitudes).")
    spring = module_text("m2s_env_spring", ["ara", "aia", "arb", "aib"], [], [("u", p.u_r, False), ("k", 1.0, True)],
                         ["I(ara) <+ u*k*(V(ara) - V(arb));", "I(aia) <+ u*k*(V(aia) - V(aib));",
                          "I(arb) <+ u*k*(V(arb) - V(ara));", "I(aib) <+ u*k*(V(aib) - V(aia));"],
                         "m2s_env_spring: a coupling spring k between two oscillating DOFs.")
    dashpot = module_text("m2s_env_dashpot", ["ara", "aia", "arb", "aib"], [], model + [("c", 1.0, True)],
                          _env_dashpot("ara", "aia", "arb", "aib"),
                          "m2s_env_dashpot: a coupling dashpot c between two oscillating DOFs.")
    quad = module_text("m2s_env_quad", ["ar", "ai", "sx", "sv"], [], [("u", p.u_r, False), ("g", 1.0, True)],
                       ["I(ar) <+ 2*g*V(sx)*u*V(ar);", "I(ai) <+ 2*g*V(sx)*u*V(ai);",
                        "I(sv) <+ g*u*u*(V(ar)*V(ar) + V(ai)*V(ai))/2;"],
                       "m2s_env_quad: potential g u_f^2 u_s, averaged over a period: 2 g s A on f, g |A|^2 / 2 on s.")
    dr, di = _env_drive("ar", "ai", "amp", "ph")
    drive = module_text("m2s_env_drive", ["ar", "ai", "amp"], [], [("ph", 0.0, True)],
                        [f"I(ar) <+ {dr};", f"I(ai) <+ {di};"],
                        "m2s_env_drive: the envelope -i a e^{i ph} of a force V(amp) sin(omega t + ph).")
    sr, si = _env_drive("ars", "ais", "amps", "ps")
    qr, qi = _env_drive("ard", "aid", "ampd", "pd")
    pair = module_text("m2s_env_pairdrive", ["ars", "ais", "ard", "aid", "amps", "ampd"], [],
                       [("ps", 0.0, True), ("pd", 1.5707963267948966, True)],
                       [f"I(ars) <+ {sr};", f"I(ais) <+ {si};", f"I(ard) <+ {qr};", f"I(aid) <+ {qi};"],
                       "m2s_env_pairdrive: an external input on a gate pair (spring gate phase ps, dashpot gate pd).")
    return [osc, slow, nor2, couple, spring, dashpot, quad, drive, pair]


def _env_dashpot(ra: str, ia: str, rb: str, ib: str) -> list[str]:
    """Rows of a dashpot c between DOFs a and b: Re, Im of c (d/dt + i omega) (A_a - A_b) on a, minus on b."""
    out = []
    for (r1, i1), (r2, i2) in (((ra, ia), (rb, ib)), ((rb, ib), (ra, ia))):
        dr, di = f"(V({r1}) - V({r2}))", f"(V({i1}) - V({i2}))"
        out += [f"I({r1}) <+ ddt(u*c*{dr}) - u*omega*c*{di};", f"I({i1}) <+ ddt(u*c*{di}) + u*omega*c*{dr};"]
    return out


# --- the library -----------------------------------------------------------------------------------------
def library(p: GateParams = DEFAULT) -> dict[str, str]:
    """filename -> Verilog-A text of both libraries, defaults from `p`."""
    head = (f"// mech2spice Verilog-A library ({{form}} level), generated by `python -m mech2spice.spice.veriloga`;\n"
            f"// defaults: gate parameters '{comment_text(p.name)}'.  Edit mech2spice/spice/veriloga.py, not this file.\n"
            '`include "disciplines.vams"\n\n')
    return {FILES[CARRIER]: head.format(form=CARRIER) + "\n".join(_carrier_modules(p)),
            FILES[ENVELOPE]: head.format(form=ENVELOPE) + "\n".join(_envelope_modules(p))}


def write_library(directory, p: GateParams = DEFAULT) -> list[Path]:
    """Write the .va files (both libraries and the processor's memory) into `directory` (created); returns
    their paths, sorted."""
    from . import memory                  # the processor's memory (spice/memory.py), checked in beside them
    d = Path(directory)
    d.mkdir(parents=True, exist_ok=True)
    out = []
    for name, text in sorted({**library(p), memory.FILE: memory.library(p)}.items()):
        path = d / name
        path.write_text(text, encoding="ascii", newline="\n")
        out.append(path)
    return out


# --- compiling ----------------------------------------------------------------------------------------------
def compiled(form: str, p: GateParams = DEFAULT) -> Path:
    """The .osdi of one library (CARRIER or ENVELOPE), compiled on first use."""
    name = FILES[form]
    return compile_va(library(p)[name], name)[0]


def combined(p: GateParams = DEFAULT) -> str:
    """Both libraries in one file (module names differ: m2s_* and m2s_env_*), as `emit --format veriloga` writes."""
    lib = library(p)
    carrier, envelope = lib[FILES[CARRIER]], lib[FILES[ENVELOPE]]
    return carrier + "\n" + envelope.split('`include "disciplines.vams"\n\n', 1)[1]


def main(argv: list[str] | None = None) -> int:
    """`python -m mech2spice.spice.veriloga [DIR]`: regenerate the checked-in library (default veriloga/)."""
    import sys
    args = sys.argv[1:] if argv is None else argv
    for path in write_library(args[0] if args else "veriloga"):
        print(path)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
