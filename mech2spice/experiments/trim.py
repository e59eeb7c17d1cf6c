"""The trim and drift flags of `gate --spread`, `montecarlo` and `cpu montecarlo`: one definition, one parser.

The physics (what is trimmed, the residual, the drift) is physics/spread.py's; docs/robustness.md
("Trimming") describes it.  Every command calls `add_trim_arguments(parser)` once and reads the flags
with `trim_from_args` (gate) or `spread_spec` (the Monte-Carlo commands, whose spread spec carries them).
"""
from __future__ import annotations

from dataclasses import replace

from .. import inputs
from ..errors import Mech2SpiceError
from ..physics import spread

FLAGS = "--trim, --trim-residual and --drift"


def add_trim_arguments(parser) -> None:
    """Register --trim, --trim-residual and --drift on `parser`."""
    parser.add_argument("--trim", choices=spread.TRIMS, default=None,
                        help="after the spread, trim each oscillator back to nominal: f = its total k/m, fc = "
                             "k/m and c/m (through its own spring and dashpot; couplings, gammas, drives and "
                             "insulators keep their spread); fcb = fc with each input pair balanced (its two "
                             "oscillators trimmed with their insulator held at both-inputs-'0', its spring link "
                             "matched to its dashpot link); default none (docs/robustness.md, docs/design.md)")
    parser.add_argument("--trim-residual", type=inputs.number(0, 1, lo_open=False), default=None, metavar="SIGMA",
                        help="relative Gaussian error left on each trimmed quantity (default 0: exact)")
    parser.add_argument("--drift", type=inputs.number(-1, 1), default=None, metavar="REL",
                        help="in service, after the trim: every stiffness times (1 + REL), a common-mode "
                             "temperature drift (default 0; a negative one as --drift=-1e-4)")


def trim_from_args(args, spread_given: bool = True) -> tuple[str, float, float]:
    """(trim mode, residual, drift) from the flags, refused (Mech2SpiceError) where they do not apply."""
    given = [v is not None for v in (args.trim, args.trim_residual, args.drift)]
    if any(given) and not spread_given:
        raise Mech2SpiceError(f"{FLAGS} apply to --spread SIGMA")
    mode = args.trim or "none"
    residual = 0.0 if args.trim_residual is None else args.trim_residual
    drift = 0.0 if args.drift is None else args.drift
    if residual and mode == "none":
        raise Mech2SpiceError("--trim-residual needs --trim f, fc or fcb")
    if not residual < 1:
        raise Mech2SpiceError(f"--trim-residual must be below 1, got {residual:g}")
    if not -1 < drift < 1:
        raise Mech2SpiceError(f"--drift must be a relative change above -1 and below 1, got {drift:g}")
    return mode, residual, drift


def spread_spec(args):
    """--spread's spec with the trim flags in it (refused when --spread's JSON sets a trim too)."""
    from .montecarlo import TRIM_DEFAULTS, parse_spread
    spec = parse_spread(args.spread)
    if not any(v is not None for v in (args.trim, args.trim_residual, args.drift)):
        return spec
    if any(getattr(spec, key) != off for key, off in TRIM_DEFAULTS.items()):
        raise Mech2SpiceError(f"give the trim in --spread's JSON or with {FLAGS}, not both")
    mode, residual, drift = trim_from_args(args)
    return replace(spec, trim=mode, trim_residual=residual, drift=drift)


def trim_json(spec: dict) -> dict:
    """The trim fields of a described spread spec, defaults filled in (the commands' JSON output)."""
    from .montecarlo import TRIM_DEFAULTS
    return {key: spec.get(key, off) for key, off in TRIM_DEFAULTS.items()}
