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

# Logic bands, as fractions of F_R (inputs) or u_R (outputs).
BAND0 = (0.365, 0.67)
BAND1 = (0.92, 1.025)
NOMINAL0 = 0.5      # a constant logical '0' is a force of 0.5 F_R
NOMINAL1 = 0.97


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
    # the block structure (physics/blocks.py); None: the classic block built from the fields above
    block: BlockSpec | None = field(default=None, repr=False)

    def __post_init__(self):
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
            if f.name not in ("name", "block") and not (isinstance(v, (int, float)) and math.isfinite(v)):
                raise Mech2SpiceError(f"gate parameter {f.name} = {v!r} is not a finite number")
        for name in ("m_g", "m_i", "m_c", "q_g", "q_i", "q_c", "k_g", "k_i", "k_c", "omega", "f_r", "u_r"):
            if getattr(self, name) <= 0:
                raise Mech2SpiceError(f"gate parameter {name} = {getattr(self, name)} must be positive")
        if self.block is not None:
            self.block.validate()

    @property
    def structure(self) -> BlockSpec:
        """The block structure add_nor builds: the file's, or the classic one from these fields."""
        from .blocks import classic
        return self.block if self.block is not None else classic(self)

    def to_dict(self) -> dict:
        """The fields as a plain dict (with the block structure only when there is one)."""
        out = {f.name: getattr(self, f.name) for f in fields(self) if f.name != "block"}
        if self.block is not None:
            out["block"] = self.block.to_dict()
        return out


PRINTED = GateParams(
    k_g=25.582, k_i=0.394784, q_i=1.5, q_c=1.5, gamma_ig=12.0, gamma_ic=6.0,
    # The paper never states omega; the channel's natural frequency is the
    # only choice that gives the channel any resonant gain.
    omega=math.sqrt(14311.8 / 6.0), name="printed")
DEFAULT = GateParams()

BUILTIN = {"default": DEFAULT, "printed": PRINTED}
BLOCK_PRESETS = ("robust", "classic")        # block files shipped under mech2spice/data/blocks/


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
        return block_params(data, spec)
    known = {f.name for f in fields(GateParams)} - {"block"}
    unknown = set(data) - known
    if unknown:
        raise Mech2SpiceError(f"parameter file {spec}: unknown field(s) {', '.join(sorted(unknown))} "
                              f"(known: {', '.join(sorted(known))})")
    for name, value in data.items():
        ok = is_name(value) if name == "name" else is_number(value)
        if not ok:
            want = f"a string of at most {MAX_NAME} printable characters" if name == "name" else "a finite number"
            raise Mech2SpiceError(f"parameter file {spec}: {name} must be {want}, not {type_name(value)}")
    p = replace(DEFAULT, **{"name": Path(spec).stem, **data})
    p.validate()
    return p


def block_params(data: dict, where: str = "block file") -> GateParams:
    """GateParams for a block file {"block": {...}, f_r, u_r, omega[, name, search...]}.  The classic
    fields (m_c, k_c, ...) are taken from the block's DOFs C, I, G1s and quads where it has them, so
    the library defaults of the SPICE emitters match a classic-shaped block."""
    from ..inputs import MAX_NAME, is_name, is_number
    unknown = set(data) - {"block", *GATE_FIELDS, *EXTRA_KEYS}
    if unknown:
        raise Mech2SpiceError(f"block file {where}: unknown key(s) {', '.join(sorted(unknown))} "
                              f"(known: block, {', '.join(GATE_FIELDS + EXTRA_KEYS)})")
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
    p = replace(DEFAULT, **roles, **{k: float(data[k]) for k in GATE_FIELDS[:3] if k in data},
                f_c=spec.source_force, name=str(name), block=spec)
    p.validate()
    return p


def band_of(x: float) -> int | None:
    """0, 1, or None (ambiguous) for an amplitude/force given in units of u_R / F_R."""
    if BAND0[0] <= x <= BAND0[1]:
        return 0
    if BAND1[0] <= x <= BAND1[1]:
        return 1
    return None


def margin(x: float, expected: int | None = None) -> float:
    """Signed distance to the nearest edge of the band (expected, or x's own), as a fraction of band width.

    Positive inside the band, negative outside (how far out, in band widths)."""
    if expected is None:
        expected = band_of(x)
        if expected is None:
            lo0, hi0 = BAND0
            lo1, hi1 = BAND1
            return -min(abs(x - lo0), abs(x - hi0), abs(x - lo1), abs(x - hi1)) / (hi0 - lo0)
    lo, hi = BAND1 if expected else BAND0
    return min(x - lo, hi - x) / (hi - lo)
