"""Gate parameters, drive frequency and logic bands.

Stiffness and damping here are *totals* as one oscillator sees them inside a
network; the model subtracts what coupling springs and dashpots contribute to
get each oscillator's local value.  Damping is given as a quality factor:
c = m * sqrt(k_total / m) / Q.

Two sets ship with the package:
  * ``printed`` - Appendix A of the paper as printed (no drive frequency given;
    we use the channel's natural frequency). It does not switch: see reports/gate.md.
  * ``default`` - the working set from ../shared/reference/gate-operating-point.md,
    re-verified by this package (``mech2spice gate``), with the insulator's Q lowered from 1.5 to 1.0 so
    that no network state admits a growing mode (docs/stability.md).
"""
from __future__ import annotations

import math
import os
from collections.abc import Mapping
from dataclasses import asdict, dataclass, field, fields, replace
from pathlib import Path

from ..errors import Mech2SpiceError
from .blocks import BlockSpec



@dataclass(frozen=True)
class Levels:
    """A block's logic levels, as fractions of F_R (input forces) or u_R (output amplitudes): the band each
    bit may take and the nominal value a constant input is driven at.

    They are the block's design data, not physics constants: the window a threshold must fall in is set by
    the top of band 0 against the bottom of band 1 (docs/robustness.md).  A block must drive itself: its
    outputs for inputs anywhere in the bands must land inside the bands, which the margin measures."""
    band0: tuple[float, float] = (0.365, 0.67)
    band1: tuple[float, float] = (0.92, 1.025)
    nominal0: float = 0.5      # a constant logical '0' is a force of 0.5 F_R
    nominal1: float = 0.97

    def __post_init__(self):
        # JSON gives lists; the record is hashable and compares equal however it was read
        object.__setattr__(self, "band0", tuple(float(v) for v in self.band0))
        object.__setattr__(self, "band1", tuple(float(v) for v in self.band1))

    def band(self, bit: int) -> tuple[float, float]:
        """The band of logical `bit`."""
        return self.band1 if bit else self.band0

    def nominal(self, bit: int) -> float:
        """The level a constant logical `bit` is driven at."""
        return self.nominal1 if bit else self.nominal0

    def band_of(self, x: float) -> int | None:
        """0, 1, or None (ambiguous) for an amplitude/force given in units of u_R / F_R."""
        if self.band0[0] <= x <= self.band0[1]:
            return 0
        if self.band1[0] <= x <= self.band1[1]:
            return 1
        return None

    def margin(self, x: float, expected: int | None = None) -> float:
        """Signed distance to the nearest edge of the band (expected, or x's own), in widths of band 0.

        Positive inside the band, negative outside (how far out)."""
        if expected is None:
            expected = self.band_of(x)
            if expected is None:
                edges = (*self.band0, *self.band1)
                return -min(abs(x - e) for e in edges) / self.width(0)
        lo, hi = self.band(expected)
        return min(x - lo, hi - x) / self.width(expected)

    def width(self, bit: int) -> float:
        lo, hi = self.band(bit)
        return hi - lo

    def validate(self, where: str = "levels") -> None:
        """Raise Mech2SpiceError unless 0 <= band0 < band1 (each low < high) and each nominal in its band."""
        values = (*self.band0, *self.band1, self.nominal0, self.nominal1)
        if len(self.band0) != 2 or len(self.band1) != 2 or not all(math.isfinite(v) for v in values):
            raise Mech2SpiceError(f"{where}: band0 and band1 must be two finite numbers each, "
                                  f"nominal0 and nominal1 finite numbers")
        (lo0, hi0), (lo1, hi1) = self.band0, self.band1
        if not 0 <= lo0 < hi0 < lo1 < hi1:
            raise Mech2SpiceError(f"{where}: the bands must satisfy 0 <= band0 low < band0 high < band1 low "
                                  f"< band1 high, got band0 {self.band0}, band1 {self.band1}")
        for bit in (0, 1):
            if self.band_of(self.nominal(bit)) != bit:
                raise Mech2SpiceError(f"{where}: nominal{bit} = {self.nominal(bit)} lies outside band{bit} "
                                      f"{self.band(bit)}")

    def to_dict(self) -> dict:
        return {"band0": list(self.band0), "band1": list(self.band1),
                "nominal0": self.nominal0, "nominal1": self.nominal1}

    @classmethod
    def from_dict(cls, data, where: str = "levels") -> "Levels":
        """Levels from a JSON object {band0: [lo, hi], band1: [lo, hi], nominal0?, nominal1?}."""
        from ..inputs import is_number, type_name
        if not isinstance(data, dict):
            raise Mech2SpiceError(f"{where}: levels must be a JSON object, not {type_name(data)}")
        unknown = set(data) - {"band0", "band1", "nominal0", "nominal1"}
        if unknown or not {"band0", "band1"} <= set(data):
            raise Mech2SpiceError(f"{where}: levels need band0 and band1 (and may give nominal0, nominal1); "
                                  f"unknown: {', '.join(sorted(unknown)) or 'none'}")
        for key in ("band0", "band1"):
            v = data[key]
            if not (isinstance(v, list) and len(v) == 2 and all(is_number(x) for x in v)):
                raise Mech2SpiceError(f"{where}: {key} must be a list of two numbers [low, high]")
        for key in ("nominal0", "nominal1"):
            if key in data and not is_number(data[key]):
                raise Mech2SpiceError(f"{where}: {key} must be a finite number")
        b0, b1 = data["band0"], data["band1"]
        lv = cls(tuple(b0), tuple(b1), float(data.get("nominal0", sum(b0) / 2)),
                 float(data.get("nominal1", sum(b1) / 2)))
        lv.validate(where)
        return lv


DEFAULT_LEVELS = Levels()
# Today's bands under their old names, for code that has no block at hand (a block's own are p.levels).
BAND0, BAND1 = DEFAULT_LEVELS.band0, DEFAULT_LEVELS.band1
NOMINAL0, NOMINAL1 = DEFAULT_LEVELS.nominal0, DEFAULT_LEVELS.nominal1


@dataclass(frozen=True)
class GateParams:
    """A NOR gate's parameters: masses, Qs, total stiffnesses, gammas, F_R, u_R, source F_C and omega."""
    m_g: float = 0.2
    q_g: float = 200.0
    k_g: float = 467.6433
    m_i: float = 1.0
    q_i: float = 1.0      # 1.5 in the reference set; at 1.5 the gates' insulator mode (~85 drive periods) is
                          # pushed past neutral by the gate oscillators' back-action in networks (a counter's
                          # latch, ISCAS-89 s344): docs/stability.md.  Steady states do not depend on it.
    k_i: float = 0.7345
    m_c: float = 6.0
    q_c: float = 200.0
    k_c: float = 14311.8
    gamma_ig: float = 9.894
    gamma_ic: float = 578.15
    f_r: float = 0.7
    u_r: float = 0.0182
    f_c: float = 1.326
    omega: float = 48.754145
    name: str = "default"
    levels: Levels = DEFAULT_LEVELS   # the block's logic bands and nominal constants
    # the block structure (physics/blocks.py); None: the classic block built from the fields above
    block: BlockSpec | None = field(default=None, repr=False)

    def __post_init__(self):
        # to_dict's plain records read back: GateParams(**p.to_dict()) == p
        if isinstance(self.levels, Mapping):
            object.__setattr__(self, "levels", Levels.from_dict(dict(self.levels)))
        if isinstance(self.block, Mapping):
            object.__setattr__(self, "block", BlockSpec.from_dict(dict(self.block)))
        # "default" names the default values only: GateParams(q_g=150.0) or replace(DEFAULT, ...) would
        # otherwise call itself default in every result, report and JSON file
        if self.name == "default" and any(getattr(self, f.name) != f.default for f in fields(self)):
            object.__setattr__(self, "name", "custom")

    # --- derived quantities -------------------------------------------------
    @property
    def period(self) -> float:
        """The drive period 2 pi / omega."""
        return 2 * math.pi / self.omega

    @property
    def k_couple(self) -> float:
        """Coupling spring k = F_R/u_R: an output amplitude in a band gives an input force in the same band."""
        return self.f_r / self.u_r

    @property
    def c_couple(self) -> float:
        """Coupling dashpot k/omega: same force magnitude as the spring, 90 degrees ahead."""
        return self.k_couple / self.omega

    def damping(self, m: float, k: float, q: float) -> float:
        """Damping c = m sqrt(k/m) / Q for mass m, total stiffness k and quality factor q."""
        return m * math.sqrt(k / m) / q

    @property
    def c_g(self) -> float:
        """The gate oscillators' total damping."""
        return self.damping(self.m_g, self.k_g, self.q_g)

    @property
    def c_i(self) -> float:
        """The insulator's total damping."""
        return self.damping(self.m_i, self.k_i, self.q_i)

    @property
    def c_c(self) -> float:
        """The channel's total damping."""
        return self.damping(self.m_c, self.k_c, self.q_c)

    def force(self, level: float) -> float:
        """Drive force for a logic level given as a fraction of F_R."""
        return level * self.f_r

    def validate(self) -> None:
        """Raise Mech2SpiceError unless every field is finite and masses, Qs, stiffnesses, omega, F_R, u_R > 0."""
        for f in fields(self):
            v = getattr(self, f.name)
            if f.name not in ("name", "block", "levels") and not _finite_number(v):
                raise Mech2SpiceError(f"gate parameter {f.name} = {v!r:.60} is not a finite number")
        if not isinstance(self.name, str) or not self.name.isprintable():
            raise Mech2SpiceError(f"gate parameter name = {self.name!r:.60} is not one line of text")
        if not isinstance(self.levels, Levels):
            raise Mech2SpiceError(f"gate parameter levels = {self.levels!r:.60} is not a Levels (or its dict)")
        if self.block is not None and not isinstance(self.block, BlockSpec):
            raise Mech2SpiceError(f"gate parameter block = {self.block!r:.60} is not a BlockSpec (or its dict)")
        for name in ("m_g", "m_i", "m_c", "q_g", "q_i", "q_c", "k_g", "k_i", "k_c", "omega", "f_r", "u_r"):
            if getattr(self, name) <= 0:
                raise Mech2SpiceError(f"gate parameter {name} = {getattr(self, name)} must be positive")
        if self.block is not None:
            self.block.validate()
        self.levels.validate(f"gate parameters {self.name}")

    @property
    def structure(self) -> BlockSpec:
        """The block structure add_nor builds: the file's, or the classic one from these fields."""
        from .blocks import classic
        return self.block if self.block is not None else classic(self)

    def to_dict(self) -> dict:
        """The fields as a plain dict (with the block structure only when there is one)."""
        out = {f.name: getattr(self, f.name) for f in fields(self) if f.name not in ("block", "levels")}
        out["levels"] = self.levels.to_dict()
        if self.block is not None:
            out["block"] = self.block.to_dict()
        return out


def _finite_number(v) -> bool:
    """An int or float (not a bool) that is finite as a float (10**400 is not)."""
    if isinstance(v, bool) or not isinstance(v, (int, float)):
        return False
    try:
        return math.isfinite(float(v))
    except OverflowError:
        return False


PRINTED = GateParams(
    k_g=25.582, k_i=0.394784, q_i=1.5, q_c=1.5, gamma_ig=12.0, gamma_ic=6.0,
    # The paper never states omega; the channel's natural frequency is the
    # only choice that gives the channel any resonant gain.
    omega=math.sqrt(14311.8 / 6.0), name="printed")
DEFAULT = GateParams()

BUILTIN = {"default": DEFAULT, "printed": PRINTED}
BLOCK_PRESETS = ("robust", "classic", "centered", "centered_fc", "centered2", "centered_fc2")   # block files under mech2spice/data/blocks/


class _Presets(Mapping):
    """Every name `--params` takes: the built-in sets, then the shipped blocks (each read from its file when
    asked for: `mech2spice design` may install a better 'robust')."""

    def __getitem__(self, name: str) -> GateParams:
        if name in BUILTIN:
            return BUILTIN[name]
        if name in BLOCK_PRESETS:
            return _block_preset(name)
        raise KeyError(name)

    def __contains__(self, name) -> bool:          # without reading a block file
        return name in BUILTIN or name in BLOCK_PRESETS

    def __iter__(self):
        return iter((*BUILTIN, *BLOCK_PRESETS))

    def __len__(self) -> int:
        return len(BUILTIN) + len(BLOCK_PRESETS)

    def __repr__(self) -> str:
        return f"PRESETS({', '.join(self)})"


PRESETS = _Presets()


def _block_preset(name: str) -> GateParams:
    from .. import data as pkg_data
    path = pkg_data.path("blocks", f"{name}.json")
    if not path.is_file():
        raise Mech2SpiceError(f"the '{name}' block is not installed ({path}): run `mech2spice design` first")
    return load_params(str(path))


GATE_FIELDS = ("f_r", "u_r", "omega", "name")   # what a block file may set beside its "block"
EXTRA_KEYS = ("search", "measured", "note")   # a block file's record of how it was found (not read)


def params_file(spec):
    """The file a --params value reads (the package's file for a shipped block; None for a preset)."""
    if spec in BLOCK_PRESETS:                     # shipped blocks are files (PRESETS names them too)
        from .. import data
        return data.path("blocks", f"{spec}.json")
    if spec is None or spec in PRESETS:
        return None
    return spec


def load_params(spec: str | None) -> GateParams:
    """'default', 'printed', a shipped block ('robust', 'classic'), a JSON file with any subset of the
    fields (rest from default), or a block file (a "block" structure: physics/blocks.py)."""
    from ..inputs import MAX_NAME, is_name, is_number, read_json, type_name, value_kind
    if spec is not None and not isinstance(spec, (str, os.PathLike)):
        raise Mech2SpiceError(f"params must be a preset ({', '.join(PRESETS)}) or a JSON file "
                              f"path, not {value_kind(spec)}")
    spec = None if spec is None else os.fspath(spec)
    if spec is None or spec in PRESETS:
        return PRESETS[spec or "default"]
    data = read_json(spec, "parameter file")
    if not isinstance(data, dict):
        raise Mech2SpiceError(f"parameter file {spec} must hold a JSON object of fields "
                              f"(e.g. {{\"q_c\": 150}}), not {type_name(data)}")
    if "block" in data:
        return self_driving(block_params(data, spec), f"block file {spec}")
    known = {f.name for f in fields(GateParams)} - {"block"}
    unknown = set(data) - known
    if unknown:
        raise Mech2SpiceError(f"parameter file {spec}: unknown field(s) {', '.join(sorted(unknown))} "
                              f"(known: {', '.join(sorted(known))})")
    if "levels" in data:
        data = {**data, "levels": Levels.from_dict(data["levels"], f"parameter file {spec}")}
    for name, value in data.items():
        if name == "levels":
            continue
        ok = is_name(value) if name == "name" else is_number(value)
        if not ok:
            want = f"a string of at most {MAX_NAME} printable characters" if name == "name" else "a finite number"
            got = f"{value!r:.60}" if isinstance(value, str) else type_name(value)   # a string: which one
            raise Mech2SpiceError(f"parameter file {spec}: {name} must be {want}, not {got}")
    p = replace(DEFAULT, **{"name": Path(spec).stem, **data})
    p.validate()
    return self_driving(p, f"parameter file {spec}") if "levels" in data else p


# Checks every block file passes on load, (p, where) -> None or Mech2SpiceError.  physics/loaded.py adds its
# check_self_drive when the physics package is imported (it builds the gate from this module, which therefore
# cannot import it: the check is handed down instead).
LOAD_CHECKS: list = []


def self_driving(p: GateParams, where: str) -> GateParams:
    """`p` once it passes LOAD_CHECKS (loaded.check_self_drive: its outputs lie in its own input bands; a block
    is refused on load, not after a run that decodes wrong bits as valid).  Checked for block files and files
    with their own levels; a file of a few classic fields on the default bands is a variant to characterise
    (`gate`, `--sens`), whose failures those commands report."""
    for check in LOAD_CHECKS:
        check(p, where)
    return p


def block_params(data: dict, where: str = "block file") -> GateParams:
    """GateParams for a block file {"block": {...}, f_r, u_r, omega[, name, search...]}.  The classic
    fields (m_c, k_c, ...) are taken from the block's DOFs C, I, G1s and quads where it has them, so
    the library defaults of the SPICE emitters match a classic-shaped block."""
    from ..inputs import MAX_NAME, is_name, is_number
    unknown = set(data) - {"block", "levels", *GATE_FIELDS, *EXTRA_KEYS}
    if unknown:
        raise Mech2SpiceError(f"block file {where}: unknown key(s) {', '.join(sorted(unknown))} "
                              f"(known: block, levels, {', '.join(GATE_FIELDS + EXTRA_KEYS)})")
    for key in GATE_FIELDS[:3]:
        if key in data and not is_number(data[key]):
            raise Mech2SpiceError(f"block file {where}: {key} must be a finite number")
    if "name" in data and not is_name(data["name"]):
        raise Mech2SpiceError(f"block file {where}: name must be a string of at most {MAX_NAME} printable characters")
    spec = BlockSpec.from_dict(data["block"], f"block file {where}")
    roles = {}
    for dof, suffix in (("C", "c"), ("I", "i"), ("G1s", "g")):
        if dof in {d.name for d in spec.dofs}:
            d = spec.dof(dof)
            roles.update({f"m_{suffix}": d.m, f"k_{suffix}": d.k, f"q_{suffix}": d.q})
    gam = {(f, s): g for f, s, g in spec.quads}
    if ("C", "I") in gam:
        roles["gamma_ic"] = -gam[("C", "I")]
    if ("G1s", "I") in gam:
        roles["gamma_ig"] = gam[("G1s", "I")]
    name = data.get("name", Path(str(where)).stem)
    if "levels" in data:
        roles["levels"] = Levels.from_dict(data["levels"], f"block file {where}")
    p = replace(DEFAULT, **roles, **{k: float(data[k]) for k in GATE_FIELDS[:3] if k in data},
                f_c=spec.source_force, name=str(name), block=spec)
    p.validate()
    return p


def band_of(x: float) -> int | None:
    """The default levels' band of x (a block's own: p.levels.band_of)."""
    return DEFAULT_LEVELS.band_of(x)


def margin(x: float, expected: int | None = None) -> float:
    """The default levels' margin of x (a block's own: p.levels.margin)."""
    return DEFAULT_LEVELS.margin(x, expected)
