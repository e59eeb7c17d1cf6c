"""`mech2spice gate`: the NOR gate's characterisation, or its sensitivities and tolerance."""
from __future__ import annotations

from .. import inputs
from ..errors import Mech2SpiceError
from ..experiments.trim import add_trim_arguments, trim_from_args
from ._output import log as _log, print_json as _print_json


def add_parser(sub) -> None:
    """Register the `gate` command."""
    g = sub.add_parser("gate", help="characterise the NOR gate against the paper's six requirements",
                       description="Characterise the mechanical NOR gate: truth table decoded from RK4, "
                                   "steady-state map and margin, cascade, delay, fan-out, requirements.")
    g.add_argument("--params", default="default", help="'default', 'printed' (Appendix A), a shipped block "
                   "('robust', 'classic') or a JSON file (fields, or a block file: docs/design.md)")
    g.add_argument("--quick", action="store_true", help="shorter runs (about 1 minute)")
    g.add_argument("--report", metavar="DIR", help="also write DIR/gate.md and PNG figures")
    g.add_argument("--json", action="store_true", help="machine-readable output")
    g.add_argument("--sens", action="store_true",
                   help="sensitivity of the outputs and margins to every element (docs/robustness.md)")
    g.add_argument("--spread", type=inputs.number(0, 1), metavar="SIGMA",
                   help="relative Gaussian spread on every element: yield, margin quantiles, tolerance")
    g.add_argument("--samples", type=inputs.integer(1, 100_000), metavar="N",
                   help="Monte-Carlo samples for --spread (default 200)")
    g.add_argument("--seed", type=inputs.integer(0, 2 ** 32 - 1), metavar="S",
                   help="random seed for --spread (default 0)")
    add_trim_arguments(g)
    g.set_defaults(func=cmd_gate)


def cmd_gate(args) -> int:
    """`mech2spice gate`: characterise the NOR gate (or --sens/--spread); print text or JSON, return 0."""
    from ..experiments import characterise
    from ..physics.params import load_params
    p = load_params(args.params)
    trim = trim_from_args(args, args.spread is not None)
    if args.sens or args.spread is not None:
        return _gate_robustness(args, p, trim)
    if args.samples is not None or args.seed is not None:
        raise Mech2SpiceError("--samples and --seed apply to --spread SIGMA")
    out = characterise.characterise(p, quick=args.quick, log=_log(args))
    if out.get("diverged"):
        raise Mech2SpiceError(f"parameters '{p.name}': the RK4 truth-table run failed: {out['diverged']}")
    if args.report:
        from ..reports.gate import write_gate_report
        write_gate_report(out, args.report, log=_log(args))
    out.pop("_figures", None)             # the report's plot data, not part of the result
    out["pass"] = bool(out.get("switches")) and out.get("min_margin", -1) > 0 and all(
        r["pass"] for r in out.get("requirements", {}).values())
    if args.json:
        _print_json(out)
    else:
        _print_gate(out)
    return 0


def _gate_robustness(args, p, trim) -> int:
    """`gate --sens` / `gate --spread`: sensitivities and tolerance instead of the characterisation."""
    from ..experiments import tolerance
    if args.quick or args.report:
        raise Mech2SpiceError("--quick and --report apply to the characterisation, not to --sens/--spread")
    if args.spread is None and (args.samples is not None or args.seed is not None):
        raise Mech2SpiceError("--samples and --seed apply to --spread SIGMA")
    out = tolerance.robustness(p, args.sens, args.spread, 200 if args.samples is None else args.samples,
                               0 if args.seed is None else args.seed, log=_log(args), trim=trim)
    if args.json:
        _print_json(out)
    else:
        print(tolerance.text(out))
    return 0


def _print_gate(out: dict) -> None:
    print(f"parameters: {out['params']['name']}   omega = {out['params']['omega']:.6g} rad/s")
    print("truth table (RK4, amplitudes in u_R):")
    for r in out["truth_table"]:
        logic = "invalid" if r["logic"] is None else r["logic"]
        print(f"  {r['inputs'][0]}{r['inputs'][1]} -> {r['output_amplitude']:.4f}  logic {logic}  "
              f"(NOR = {r['expected']}, margin {r['margin']:+.3f})")
    print(f"gate switches: {'yes' if out['switches'] else 'NO'}")
    print(f"RK4 vs steady state: {out['rk4_vs_steady']:.2e} u_R; "
          f"halving the RK4 step changes outputs by {out['step_halving_change']:.1e} u_R")
    print(f"min margin over valid inputs (steady state): {out['min_margin']:+.4f} of a band "
          f"at inputs {out['min_margin_detail'].get('at_inputs')}")
    if "omega_scan" in out:
        s = out["omega_scan"]
        print(f"scan over omega: largest channel amplitude {s['max_channel_amplitude']:.3g} u_R, "
              f"largest 00-vs-11 contrast {s['max_switch_contrast']:.2e} u_R (at omega = {s['at_omega']:.3g})")
    if "delay_periods" in out:
        print(f"delay: {out['delay_periods']:.0f} periods per gate (mean), {out['delay_max_periods']:.0f} max")
    for name, r in out.get("requirements", {}).items():
        print(f"  [{'pass' if r['pass'] else 'FAIL'}] {name}: {r['figure']}")
