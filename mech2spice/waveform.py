"""Waveforms as VCD files (IEEE 1364 value change dump), the format GTKWave and Surfer open.

A `Waveform` is named signals over numbered timesteps (one per clock cycle, or one per processor read):
decoded bits as wires (a port as one vector, most significant bit first, an invalid bit as `x`) and
amplitudes in u_R as real variables.  The file is written by `pyvcd` (the format's escaping, identifier
codes and header are its to get right) and read back by its tokenizer (`read_vcd`, for tests and tools).
"""
from __future__ import annotations

import io
import math
from dataclasses import dataclass, field

from .errors import Mech2SpiceError
from .inputs import write_text

TIMESCALE = "1 ns"          # one time unit per timestep: the unit is nominal, the comment says what a step is
WIRE_CHARS = frozenset("01xz")          # z: a bit a simulator reads undriven (verify's Icarus side)


@dataclass(frozen=True)
class Signal:
    """One variable: a wire of `width` bits (values: an int, None for all bits invalid, or a string over
    "01xz" of `width` characters, most significant first) or, with width None, a real (values: floats)."""
    scope: tuple[str, ...]          # module path, outermost first, e.g. ("counter4", "outputs")
    name: str
    width: int | None
    values: tuple

    @property
    def real(self) -> bool:
        return self.width is None

    def path(self) -> str:
        """The hierarchical name viewers show: scopes and name joined by dots."""
        return ".".join((*self.scope, self.name))


@dataclass
class Waveform:
    """Signals sampled at `times` (one value per signal per time, in `TIMESCALE` units); `comment` says
    what a timestep is (it is written into the file's header)."""
    times: list[int]
    signals: list[Signal] = field(default_factory=list)
    comment: str = ""

    def add_wire(self, scope, name: str, width: int, values) -> None:
        """A wire of `width` bits; each value an int, None (all x) or a "01xz" string (MSB first)."""
        self.signals.append(Signal(tuple(scope), name, int(width), tuple(wire_value(v, width) for v in values)))

    def add_bits(self, scope, name: str, per_step: list[list[int | None]]) -> None:
        """A wire from its bits, least significant first per timestep (None: invalid, written x)."""
        width = len(per_step[0]) if per_step else 1
        self.add_wire(scope, name, width, [bits_string(b) for b in per_step])

    def add_real(self, scope, name: str, values) -> None:
        """A real variable (amplitudes in u_R): one finite float per timestep."""
        vals = tuple(float(v) for v in values)
        if not all(math.isfinite(v) for v in vals):
            raise Mech2SpiceError(f"waveform {name}: a real value is not finite")
        self.signals.append(Signal(tuple(scope), name, None, vals))

    def signal(self, path: str) -> Signal:
        """The signal of hierarchical name `path` (scopes.name)."""
        for s in self.signals:
            if s.path() == path:
                return s
        raise KeyError(path)


def bits_string(bits: list[int | None]) -> str:
    """Bits least significant first (None: invalid) as a VCD vector string, most significant first."""
    return "".join("x" if b is None else str(int(bool(b))) for b in reversed(bits))


def wire_value(value, width: int) -> str:
    """A wire's value as `width` characters over "01xz" (MSB first): an int (two's complement if negative),
    None (all x) or such a string."""
    if value is None:
        return "x" * width
    if isinstance(value, str):
        v = value.lower()
        if len(v) != width or not set(v) <= WIRE_CHARS:
            raise Mech2SpiceError(f"waveform value {value!r}: expected {width} characters of 0, 1, x or z")
        return v
    return format(int(value) & ((1 << width) - 1), f"0{width}b")


def _check_name(name: str) -> str:
    """A VCD reference or scope name: printable, no white space (which ends a name in the format), no dot
    (the scope separator of readers)."""
    if not name or not name.isprintable() or any(c.isspace() for c in name) or "." in name:
        raise Mech2SpiceError(f"waveform name {name!r}: expected printable characters without spaces or dots")
    return name


def vcd_text(wave: Waveform) -> str:
    """The waveform as VCD text: a scope per module, a `wire [w-1:0]` per port, a `real` per amplitude,
    a timestamp per timestep with the values that changed."""
    from vcd import VCDWriter
    _check(wave)
    out = io.StringIO()
    writer = VCDWriter(out, timescale=TIMESCALE, date="", comment=wave.comment, version="mech2spice")
    handles = []
    for s in wave.signals:
        scope = [_check_name(x) for x in s.scope]
        if s.real:
            var = writer.register_var(scope, _check_name(s.name), "real", init=s.values[0] if s.values else 0.0)
        else:
            var = writer.register_var(scope, _check_name(s.name), "wire", size=s.width,
                                      init=s.values[0] if s.values else "x" * s.width,
                                      bit_index=(s.width - 1, 0) if s.width > 1 else None)
        handles.append((var, s))
    for k, t in enumerate(wave.times):
        for var, s in handles:
            writer.change(var, t, s.values[k])
    writer.close(wave.times[-1] + 1 if wave.times else 0)     # a last timestamp so viewers show the last step
    return out.getvalue()


def _check(wave: Waveform) -> None:
    if any(b <= a for a, b in zip(wave.times, wave.times[1:])) or any(t < 0 for t in wave.times):
        raise Mech2SpiceError("waveform times must be increasing and not negative")
    seen = set()
    for s in wave.signals:
        if len(s.values) != len(wave.times):
            raise Mech2SpiceError(f"waveform {s.path()}: {len(s.values)} values for {len(wave.times)} timesteps")
        if s.path() in seen:
            raise Mech2SpiceError(f"waveform {s.path()}: two signals of that name")
        seen.add(s.path())


def write_vcd(path, wave: Waveform) -> None:
    """Write `wave` to `path` as VCD, whole or not at all (the caller checked the path: inputs.check_output_file)."""
    write_text(path, vcd_text(wave), encoding="utf-8")


def is_vcd(path) -> bool:
    """Whether a file looks like a VCD file (what `--vcd` may replace without --force)."""
    from .inputs import head
    text = head(path, 4096).decode("utf-8", "replace")
    return "$timescale" in text or "$enddefinitions" in text or "$var" in text


def read_vcd(path, times=None) -> Waveform:
    """A VCD file as a Waveform sampled at `times` (default: each timestamp the file names but the last,
    which ends the dump): each signal's value as of its last change at or before the time; wires as "01x"
    strings (MSB first), reals as floats.  VCD omits a timestamp where nothing changed, so a caller that
    knows its timesteps passes them."""
    from vcd.reader import TokenKind, tokenize
    scope: list[str] = []
    decl: list[tuple[str, tuple[str, ...], str, int | None]] = []
    changes: dict[str, list[tuple[int, object]]] = {}
    stamps: list[int] = []
    with open(path, "rb") as f:
        for tok in tokenize(f):
            if tok.kind is TokenKind.SCOPE:
                scope.append(tok.scope.ident)
            elif tok.kind is TokenKind.UPSCOPE:
                scope.pop()
            elif tok.kind is TokenKind.VAR:
                v = tok.var
                decl.append((v.id_code, tuple(scope), _reference(v), None if v.type_.value == "real" else v.size))
            elif tok.kind is TokenKind.CHANGE_TIME:
                stamps.append(tok.time_change)
            elif tok.kind in (TokenKind.CHANGE_SCALAR, TokenKind.CHANGE_VECTOR, TokenKind.CHANGE_REAL):
                changes.setdefault(tok.data.id_code, []).append((stamps[-1] if stamps else 0, tok.data.value))
    times = list(stamps[:-1] if len(stamps) > 1 else stamps) if times is None else list(times)
    wave = Waveform(times)
    for code, sc, ref, width in decl:
        hist = changes.get(code, [])
        wave.signals.append(Signal(sc, ref, width, tuple(_read_value(_at(hist, t), width) for t in times)))
    return wave


def _reference(var) -> str:
    """The name a variable was written with: the tokenizer splits "q[0]" into "q" and bit 0 (kept), and a
    vector's "q[3:0]" into "q" and its range (dropped: the width says it)."""
    return var.reference + (f"[{var.bit_index}]" if isinstance(var.bit_index, int) else "")


def _at(history: list[tuple[int, object]], t: int):
    """The last value of a change history at or before time t (None before the first)."""
    value = None
    for when, v in history:
        if when > t:
            break
        value = v
    return value


def _read_value(value, width: int | None):
    if value is None:
        return None
    if width is None:
        return float(value)
    if isinstance(value, int):
        return format(value, f"0{width}b")
    v = str(value).lower()
    return (v[0] if v[0] in "xz" else "0") * (width - len(v)) + v    # VCD left-extends shortened vectors
