"""reports/spice.md: the electrical analogy and the ngspice-vs-RK4 comparison suite, rendered from spice.json
(mech2spice/studies/spice.py measures it).

Run: mech2spice report spice [--render]
"""
from __future__ import annotations

import textwrap
from pathlib import Path

from ._common import measured_on, out_dir, read_json, stored, write_json


def write(directory="reports", render: bool = False) -> Path:
    """Run the comparison suite into spice.json (unless `render`) and write spice.md from it (its form paragraph
    from DIR/speed_accuracy.json)."""
    d = out_dir(directory)
    if not render:
        from ..studies import spice as study          # measuring loads the engines; rendering does not
        write_json(d / "spice.json", study.measure())
    data = stored(d / "spice.json", "spice")
    res = data["scenes"]
    table = "\n".join(f"| {n} | {r['cases']} | {r['probes']} | {r['periods']} | {r['max_amp_err']:.1e} | "
                      f"{r['max_phase_err']:.2f} | {r['rk4_s']:.1f} | {r['ngspice_s']:.1f} |" for n, r in res.items())
    ok = all(r["max_amp_err"] < 0.01 and r["max_phase_err"] < 2 for r in res.values())
    (d / "spice.md").write_text(SPICE_MD.format(machine=measured_on(data["conditions"]), table=table,
                                                opts=data["options"], verdict="all within" if ok else "NOT all within",
                                                why=why_this_form(d / "speed_accuracy.json")))
    return d / "spice.md"


UNMEASURED_WHY = """**Why this form.** `../shared/reference/toolchain-notes.md` measured it as the fastest of the forms
tried on this ngspice build (no KLU): POLY sources, inductor currents inside `B` expressions and the
force-voltage (impedance/loop) form were about 2x slower. We did not re-measure the alternatives;
the analogy's cost here is dominated by device loading (scaling table in `speed_accuracy.md`)."""

FORM_NAMES = {"impedance (force-voltage)": "the impedance (force-voltage) analogy (per DOF a series loop, "
                                           "L = m, R = c, C = 1/k, couplings as controlled voltage sources)",
              "mobility, inductor springs": "the mobility analogy with springs as inductors L = 1/k"}


def why_this_form(json_path) -> str:
    """The 'Why this form' paragraph from the measured form comparison in speed_accuracy.json
    (`mech2spice report speed_accuracy --only forms`); the unmeasured note if there is none.
    A form counts as slower/faster where its CPU time differs from the package form's by more than
    PAR (10 %), else as on par."""
    res = read_json(json_path, {})
    fm = res.get("forms")
    if not fm:
        return UNMEASURED_WHY
    key = "cpu_s" if all("cpu_s" in r for d in fm.values() for r in d["rows"] if "amp_err_ur" in r) else "wall_s"
    o = next(iter(fm.values()))["options"]
    base = {n: next(r for r in d["rows"] if "package" in r["form"]) for n, d in fm.items()}
    parts, faster, words = [], [], {}
    for form, desc in FORM_NAMES.items():
        cells, ratios = [], []
        for name, d in fm.items():
            r = next((r for r in d["rows"] if r["form"] == form and key in r), None)
            if r is None:
                cells.append(f"failed on {name}")
                continue
            ratio = r[key] / base[name][key]
            ratios.append(ratio)
            if ratio < 1 - PAR:
                faster.append(f"{form} on {name}")
            cells.append(f"{ratio:.2f}x on {name} ({r.get('equations', '?')} circuit equations against "
                         f"{base[name].get('equations', '?')})")
        words[form] = ("slower on every design" if ratios and min(ratios) >= 1 + PAR else
                       "on par on every design" if ratios and max(abs(x - 1) for x in ratios) < PAR else
                       "mixed")
        parts.append(f"{desc}: {', '.join(cells)}")
    runs = [r.get("cpus" if key == "cpu_s" else "walls", []) for d in fm.values() for r in d["rows"]]
    spread = max((max(x) / min(x) - 1 for x in runs if len(x) > 1), default=None)
    err = max(r["amp_err_ur"] for d in fm.values() for r in d["rows"] if "amp_err_ur" in r)
    ph = max(r["phase_err_deg"] for d in fm.values() for r in d["rows"] if "phase_err_deg" in r)
    designs = "; ".join(f"{n}: {d['cases']} case(s), {d['periods']} periods" for n, d in fm.items())
    summary = "; ".join(f"{form}: {w}" for form, w in words.items())
    if faster:
        verdict = (f"an alternative was faster by more than {PAR:.0%} ({', '.join(faster)}); the package keeps its "
                   "form for now, and switching is the open question this measurement raises")
    else:
        fewest = all((base[n].get("equations") or 0) <= min((r.get("equations") or 1e9) for r in d["rows"])
                     for n, d in fm.items())
        verdict = (f"no alternative was faster by more than {PAR:.0%} on any design ({summary}), so the package "
                   "keeps its form" + ("; it also has the fewest circuit equations on every design" if fewest else ""))
        if words.get("mobility, inductor springs", "").startswith("on par"):
            verdict += (". Between the two mobility variants speed does not decide; VCCS springs read the "
                        "displacement node that the quadratic couplings, the probes and the `.control` read-out need "
                        "anyway, where inductor springs add a branch current per spring")
    text = (f"**Why this form (measured).** `mech2spice report speed_accuracy --only forms` ran the same designs in "
            f"three analogy forms with the same ngspice options (method {o['method']}, max step "
            f"T/{round(1 / o['max_step_periods'])} pinned, reltol {o['reltol']:g}, every reactive element "
            f"prewarped) on the {res.get('machine', '?')} ({designs}). {'CPU' if key == 'cpu_s' else 'Wall'} time "
            "relative to the package's form - " + "; ".join(parts)
            + (f" (run-to-run spread of the repeated runs up to {spread:.0%})" if spread is not None else "")
            + f". Every form's settled error against RK4 is at most {err:.4f} u_R and {ph:.2f} deg"
            + (": the form changes the cost, not the answer" if err < 0.01 and ph < 2 else "")
            + f". By measurement, {verdict}. The table is in "
              "`speed_accuracy.md`, \"Analogy form, measured\". `../shared/reference/toolchain-notes.md` had put the "
              "force-voltage form at about 2x; its other slow candidates (POLY sources, inductor currents inside `B` "
              "expressions) were not re-measured.")
    return textwrap.fill(text, width=104, break_long_words=False, break_on_hyphens=False)


PAR = 0.10


SPICE_MD = """# The SPICE analogy

Generated by `mech2spice report spice` (comparison) on {machine}; the integrator study
behind the defaults is `reports/speed_accuracy.md` (`mech2spice report speed_accuracy`).

## Mapping (mobility analogy: force = current, velocity = voltage)

| mechanics | circuit (per DOF u: a velocity node v and a displacement node x) |
|---|---|
| mass m | capacitor C = m from v to ground |
| local damping c | conductance c from v to ground (may be negative) |
| local spring k | VCCS k V(x) from v to ground (may be negative) |
| displacement | 1 F capacitor at x fed by the VCCS V(v): V(x) = u |
| coupling spring k_ij | VCCS k_ij (V(x_i) - V(x_j)) between v_i and v_j |
| coupling dashpot c_ij | conductance c_ij between v_i and v_j |
| quadratic coupling gamma u_f^2 u_s | `B` current sources -2 gamma V(x_f) V(x_s) into v_f and -gamma V(x_f)^2 into v_s |
| drive a sin(omega t + phase) | `B` current source; the amplitude a(t) is a PWL voltage, so schedules and clocks need no new netlist |

Each DOF's own elements carry its *local* values (total minus its couplings), which are negative for
the dashpot gates and the channels; with the coupling elements the circuit's admittance matrices are
exactly the model's K and C, whose diagonals are the *totals*. ngspice accepts negative R and VCCS
gains; a 3-DOF chain with negative middle k and c reproduces the exact phasors to 7e-12
(`speed_accuracy.md`, "Prewarp").

{why}

**Prewarping the trapezoidal rule.** At a fixed step h, trapezoidal integration answers a sinusoid at
omega as the continuous circuit would at (2/h) tan(omega h/2): for Q = 200 oscillators at T/40 that is
a 2000 ppm frequency error and wrong amplitudes by tens of percent (`speed_accuracy.md`). Scaling the
capacitors of oscillating DOFs by w = (omega h/2)/tan(omega h/2) makes the response at the drive
frequency exact whatever h, provided every step is h (trtol 1e4 pins it; a warning is raised
otherwise). The price: slow envelope dynamics run omega h / sin(omega h) slower, +0.4 % at T/40.
Gear (BDF) damps numerically (Q 200 -> 149 at T/40) and is not recommended.

Defaults: `{opts}`.

## Library and emission

`subckts/` holds `m2s_osc` (one DOF), `m2s_nor2` (the NOR block: ports for its two input pairs and its
channel), `m2s_couple` (spring + dashpot), `m2s_drive` and `m2s_pairdrive` (external and constant-level
drives), and `m2s_params.inc`, generated by `mech2spice subckts` (a test fails if regenerating changes a
byte). `mech2spice emit DESIGN.v --set ... -o OUT.cir` writes a self-contained netlist with the library
inlined, hierarchical `X` instances, PWL amplitudes, `.tran`, `.options`, `.save` of the probes only
and a `.control` block, so `ngspice -b OUT.cir` prints each output bit's amplitude at omega, its value
and each port's integer (docs/spice.md). User names are sanitised to `[a-z0-9_]`, made unique and never
start a card.

## Comparison suite: ngspice (defaults) vs RK4 (80 steps/period)

Settled amplitude and phase of every probe after the given periods, from rest; wall times measured in
this run (ngspice: two processes at a time).

| scene | cases | probes | periods | max amplitude error (u_R) | max phase error (deg) | RK4 (s) | ngspice (s) |
|---|---|---|---|---|---|---|---|
{table}

Criterion (issue): 0.01 u_R and 2 degrees - {verdict}. The CI suite (`tests/test_spice.py`, marker
`ngspice`) runs the gate, chain and fan-out cases; the adder case is in `tests/test_simulate.py`.
"""
