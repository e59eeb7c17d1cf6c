"""Netlists that read their own result: the header that maps probed nodes to port bits (u_R, the bands),
and, for ngspice, a `.control` block that measures, decodes and prints each output bit and port.

The reading is the one simulation.decode makes: |A| / u_R, A the phasor at omega of the probed displacement
over the last drive period (carrier form) or the envelope amplitude at the end (envelope form), in the bands
of physics.params.  ngspice's control language does it alone (`ngspice -b out.cir`); VACASK's control block
cannot evaluate results without running Python (`postprocess`), so its netlists carry the header only.
See docs/spice.md, section "Netlists that read their own result".
"""
from __future__ import annotations

from dataclasses import dataclass

from ..physics.model import MechModel
from ..identifiers import ngspice_echo, ngspice_echo_text
from ._common import comment_text, num

MAX_VALUE_BITS = 53        # a port's integer is printed from doubles: exact up to 2^53


@dataclass(frozen=True)
class Bit:
    name: str              # port bit ("s[0]"), or the probe's name for a model without ports
    probe: int | None      # index into model.probes, or None for a constant bit
    const: int | None = None


@dataclass(frozen=True)
class Port:
    name: str
    bits: tuple[int, ...]  # indices into the bit list, LSB first
    signed: bool


def about(design, top: str, values: dict[str, int]) -> str:
    """The header's first reading line: design file, top module, the inputs applied."""
    given = ", ".join(f"{k}={v}" for k, v in values.items()) or "all 0"
    return f"design {design}, top {top}; inputs {given} (unset inputs 0)"


def bits_and_ports(model: MechModel) -> tuple[list[Bit], list[Port]]:
    """Every output bit (probed or constant) and port of the model's design; the probes alone without one."""
    probes = list(model.probes)
    nl = model.design.netlist
    if nl is None:
        return [Bit(n, k) for k, n in enumerate(probes)], []
    bits, ports = [], []
    for port, width in nl.outputs.items():
        idx = []
        for i in range(width):
            b = f"{port}[{i}]"
            idx.append(len(bits))
            bits.append(Bit(b, probes.index(b)) if b in model.probes else Bit(b, None, model.design.const_outputs[b]))
        ports.append(Port(port, tuple(idx), port in nl.signed))
    return bits, ports


def header(model: MechModel, nodes: list[str], what: str, about_line: str, prints: bool, run_with: str) -> list[str]:
    """Comment text (no comment marker) explaining how to read the result; `nodes`: each probe's node(s),
    `what`: how the amplitude is taken from them."""
    p, lv = model.params, model.levels
    bits, ports = bits_and_ports(model)
    u = f"u_R = {num(p.u_r)} (reference output amplitude), F_R = {num(p.f_r)} (reference input force)" \
        if p is not None else "u_R = 1 (a model without gate parameters)"
    out = ["--- reading the result (docs/spice.md, 'Netlists that read their own result')"]
    out += [comment_text(about_line)] if about_line else []
    out += [u, f"output bit = {what}",
            f"bands: '0' {lv.band0[0]:g}..{lv.band0[1]:g} u_R, '1' {lv.band1[0]:g}..{lv.band1[1]:g} u_R, "
            "anything else invalid", "probed node -> port bit:"]
    for b in bits:
        src = nodes[b.probe] if b.probe is not None else f"(constant {b.const}, no oscillator)"
        out.append(f"  {src} -> {comment_text(b.name)}")
    for pt in ports:
        out.append(f"port {comment_text(pt.name)}: {len(pt.bits)} bits, {'signed (two' + chr(39) + 's complement)' if pt.signed else 'unsigned'}, "
                   f"bit [0] = LSB")
    out.append(f"run: {run_with}")
    if prints:
        out.append("it prints per bit 'NAME[i] = A u_R -> 0|1|invalid', then per port 'NAME = N (valid)' or "
                   "'NAME = invalid'; exit status 0 when every bit is in a band, 1 otherwise")
    return out


# --- the ngspice .control block ------------------------------------------------------------------------
_label = ngspice_echo            # names and free text in echo strings: mech2spice/identifiers.py
_label_text = ngspice_echo_text


def period_mask(t0: float, t1: float) -> list[str]:
    """Control line setting m2s_w = 1 on the samples in [t0, t1), 0 elsewhere."""
    return [f"let m2s_w = (time ge {num(t0)}) and (time lt {num(t1)})"]


def carrier_amplitude(k: int, node: str, omega: float, t0: float, t1: float, u_r: float, uniform: bool) -> list[str]:
    """Control lines setting m2s_a<k> = |A| / u_R of V(node) at omega over [t0, t1] (needs m2s_w).

    uniform (the step pinned at max_step, the default): A = 2 mean(v e^{-i omega t}) over the samples in
    [t0, t1), the N-point DFT runner.demodulate takes (same digits).  Otherwise (2/T) |integral of
    v e^{-i omega t}| by `meas ... integ` (trapezoidal, its own interpolation at the window's edges)."""
    w = num(omega)
    c, s = f"v({node})*cos({w}*time)", f"v({node})*sin({w}*time)"
    if uniform:
        return [f"let m2s_ic{k} = mean({c}*m2s_w)/mean(m2s_w)", f"let m2s_is{k} = mean({s}*m2s_w)/mean(m2s_w)",
                f"let m2s_a{k} = {num(2 / u_r)}*sqrt(m2s_ic{k}^2 + m2s_is{k}^2)"]
    return [f"let m2s_c{k} = {c}", f"let m2s_s{k} = {s}",
            f"meas tran m2s_ic{k} integ m2s_c{k} from={num(t0)} to={num(t1)}",
            f"meas tran m2s_is{k} integ m2s_s{k} from={num(t0)} to={num(t1)}",
            f"let m2s_a{k} = {num(2 / (u_r * (t1 - t0)))}*sqrt(m2s_ic{k}^2 + m2s_is{k}^2)"]


def envelope_amplitude(k: int, re_node: str, im_node: str) -> list[str]:
    """Control lines setting m2s_a<k> = |A| / u_R from the envelope nodes (already in u_R) at the run's last
    point, tstop (`meas ... at=tstop` misses it by rounding)."""
    last = [f"v({n})[length(v({n}))-1]" for n in (re_node, im_node)]
    return [f"let m2s_a{k} = sqrt({last[0]}^2 + {last[1]}^2)"]


def _decode_bit(k: int, label: str, levels) -> list[str]:
    """m2s_b<k> = 0, 1 or -1 (invalid) from m2s_a<k> and the block's bands (inclusive, as Levels.band_of);
    print it."""
    a, b = f"m2s_a{k}", f"m2s_b{k}"
    (lo0, hi0), (lo1, hi1) = levels.band0, levels.band1
    return [f"let {b} = -1",
            f"if {a} ge {lo0!r} and {a} le {hi0!r}", f"  let {b} = 0", "end",
            f"if {a} ge {lo1!r} and {a} le {hi1!r}", f"  let {b} = 1", "end",
            f"if {b} lt 0", f'  echo "{label} = $&{a} u_R -> invalid"',
            "else", f'  echo "{label} = $&{a} u_R -> $&{b}"', "end"]


def _print_port(j: int, port: Port, bits: list[Bit]) -> list[str]:
    """Sum the port's bits into m2s_p<j> (two's complement when signed) and print it, or 'invalid'."""
    label, v, ok = _label(port.name), f"m2s_p{j}", f"m2s_ok{j}"
    w = len(port.bits)
    terms = [f"{1 << i}*{f'm2s_b{k}' if bits[k].probe is not None else bits[k].const}" for i, k in enumerate(port.bits)]
    out = [f"let {ok} = 1"]
    for k in port.bits:
        if bits[k].probe is not None:
            out += [f"if m2s_b{k} lt 0", f"  let {ok} = 0", "end"]
    if w > MAX_VALUE_BITS:        # doubles cannot hold it exactly: the bits above are the reading
        return out + [f"if {ok} eq 0", f'  echo "{label} = invalid"', "else",
                      f'  echo "{label} = (wider than {MAX_VALUE_BITS} bits: read its bits above) (valid)"', "end"]
    out += [f"let {v} = " + " + ".join(terms)]
    if port.signed:
        out += [f"if {v} ge {1 << (w - 1)}", f"  let {v} = {v} - {1 << w}", "end"]
    return out + [f"if {ok} eq 0", f'  echo "{label} = invalid"', "else", *_print_int(v, w, label), "end"]


def _print_int(v: str, width: int, label: str) -> list[str]:
    """Echo `label = <v> (valid)` digit by digit: echo prints a number with 6 significant digits only."""
    out = [f'  echo -n "{label} = "', f"  if {v} lt 0", '    echo -n "-"', f"    let {v} = -{v}", "  end"]
    for i in range(len(str(1 << width)) - 1, 0, -1):
        hi, lo = num(10.0 ** i), num(10.0 ** (i + 1))
        out += [f"  if {v} ge {hi}", f"    let m2s_d = floor({v}/{hi}) - 10*floor({v}/{lo})",
                '    echo -n "$&m2s_d"', "  end"]
    return out + [f"  let m2s_d = {v} - 10*floor({v}/10)", '  echo "$&m2s_d (valid)"']


def control_block(model: MechModel, amplitude, what: str, setup: list[str] = ()) -> list[str]:
    """The .control block: run, `setup`, then `amplitude(k, probe)` (control lines setting m2s_a<k>) per probed
    bit, its decoded bit, and each port's value; `what` names the amplitude in the first printed line."""
    bits, ports = bits_and_ports(model)
    out = [".control", "run", *setup, "echo", f'echo "--- mech2spice reading: {_label_text(what)}"']
    for k, b in enumerate(bits):
        if b.probe is None:
            out.append(f'echo "{_label(b.name)} = constant -> {b.const}"')
            continue
        out += amplitude(k, b.probe) + _decode_bit(k, _label(b.name), model.levels)
    for j, port in enumerate(ports):
        out += _print_port(j, port, bits)
    # the exit status says whether every bit was in a band, as `simulate` does (ngspice's own would be 1:
    # batch mode finds no .print line to run)
    bad = [f"m2s_b{k} lt 0" for k, b in enumerate(bits) if b.probe is not None]
    out += ["let m2s_valid = 1"] + [x for c in bad for x in (f"if {c}", "  let m2s_valid = 0", "end")]
    return out + ["if m2s_valid eq 0", "  quit 1", "end", "quit 0", ".endc"]


def period_window(periods: int, T: float) -> tuple[float, float]:
    """The last drive period of the run, [(P-1) T, P T]: the one simulation.decode reads."""
    return (periods - 1) * T, periods * T


__all__ = ["about", "bits_and_ports", "control_block", "header", "carrier_amplitude", "period_mask", "envelope_amplitude",
           "period_window"]
