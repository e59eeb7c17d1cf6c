"""`mech2spice montecarlo DESIGN.v`: yield of a design under element spread, on Dask, resumable."""
from __future__ import annotations

from pathlib import Path

from .. import inputs
from ..backends import continuing, engine_class, names
from ..errors import Mech2SpiceError
from ..experiments.trim import add_trim_arguments, spread_spec, trim_json

BACKENDS = names(lambda caps: caps.noise, first="envelope")     # each sample may carry its own thermal noise


def add_parser(subparsers) -> None:
    """Register the `montecarlo` command."""
    s = subparsers.add_parser(
        "montecarlo", help="yield of a design under per-element spread (Monte-Carlo on Dask, resumable)",
        description="Sample the design's mechanical model with a relative Gaussian spread on every element "
                    "(local mismatch, optionally a wafer-level shift per element kind), simulate every input "
                    "vector of each sample, compare every output with the logic oracle. Results stream to a "
                    "JSON-lines file (--out) that a rerun of the same command resumes. Exit 0 when every "
                    "sample passed, 1 otherwise.")
    s.add_argument("design", help="Verilog file (combinational, or clocked with --stimulus)")
    s.add_argument("--set", action="append", metavar="PORT=INT",
                   help="one input vector (repeatable ports; default: every input combination, up to 256)")
    s.add_argument("--stimulus", metavar="FILE.json",
                   help="input vectors: a list of {\"set\": {PORT: INT}} steps; for a clocked design its clock "
                        "cycles, [{\"set\": ..., \"cycles\": N}, ...], compared with the logic oracle every cycle")
    s.add_argument("--backend", default="envelope", choices=BACKENDS)
    s.add_argument("--periods", type=inputs.integer(1, inputs.MAX_PERIODS), default=None,
                   help="simulate exactly this many periods (default: until the outputs settle)")
    s.add_argument("--batch", type=inputs.integer(1, 4096), default=None, metavar="B",
                   help="samples per engine run and task (default 8 on envelope/rk4, 1 on ngspice)")
    add_sweep_arguments(s)
    s.set_defaults(func=cmd_montecarlo)


def add_sweep_arguments(s) -> None:
    """The options every Monte-Carlo command shares: parameters, samples, spread, noise, seed, Dask, results."""
    from ..physics.params import PRESETS
    s.add_argument("--params", default="default",
                   help=f"gate parameters: {', '.join(PRESETS)}, or a JSON file (fields or a block)")
    s.add_argument("--samples", type=inputs.integer(1, 10_000_000), required=True, metavar="N")
    s.add_argument("--spread", required=True, metavar="SIGMA|JSON",
                   help='relative sigma on every element, or {"local": SIGMA|{KIND: SIGMA}, "wafer": '
                        'SIGMA|{KIND: SIGMA}, "wafer_rho": RHO} (inline or a file); kinds k m c spring '
                        'dashpot gamma drive, "*" for all')
    add_trim_arguments(s)
    s.add_argument("--noise", type=inputs.number(0, lo_open=False), default=0.0, metavar="T",
                   help="thermal noise: k_B T in model energy units (docs/robustness.md gives kelvin for a "
                        "1 MHz silicon scaling); a Langevin force on every dashpot, each sample its own seed; "
                        "default 0 (none)")
    s.add_argument("--seed", type=inputs.integer(0, 2 ** 32 - 1), default=0, metavar="S")
    s.add_argument("--scheduler", default="local", metavar="local|inline|ADDRESS", type=_scheduler,
                   help="local: a LocalCluster, one worker per core (default); inline: no Dask; or a "
                        "Dask scheduler address (tcp://host:8786)")
    s.add_argument("--workers", type=inputs.integer(1, 4096), default=None, help="LocalCluster workers")
    s.add_argument("--out", metavar="RESULTS.jsonl",
                   help="results file, appended and resumed (default: a temporary file, removed after)")
    s.add_argument("--json", action="store_true", help="machine-readable output")


def check_out(args, read: dict) -> None:
    """--out, before any work: none of the command's files (design or program, --stimulus, --params,
    --spread), and if it exists a results file (resumed; its records are checked before any sample runs)."""
    from ..experiments import montecarlo as mc
    from ..experiments.mc_run import RESULTS_KIND
    from ..physics.params import params_file
    if args.out:
        read = {**read, "the --params file": params_file(args.params),
                "the --spread file": mc.spread_file(args.spread)}
        inputs.check_output_file(args.out, read, "results file", kind=RESULTS_KIND, remedy="give another --out")


def _scheduler(text: str) -> str:
    """An argparse type: mc_run.check_scheduler, its refusal as a usage error (before any work)."""
    import argparse
    from ..experiments.mc_run import check_scheduler
    try:
        return check_scheduler(text)
    except Mech2SpiceError as err:
        raise argparse.ArgumentTypeError(str(err)) from None


def vectors_of(args, netlist) -> list[dict[str, int]]:
    """The input vectors: --set (one), --stimulus (a list of sets) or every combination."""
    from ..synthesis.ports import pack_inputs
    from ..experiments import montecarlo as mc
    if args.set and args.stimulus:
        raise Mech2SpiceError("give --set or --stimulus, not both")
    if args.stimulus:
        steps = inputs.stimulus_steps(args.stimulus, {}, engine_class(args.backend))
        if any(step["cycles"] != 1 for step in steps):    # it was ignored: each step is one vector here
            raise Mech2SpiceError(f"{netlist.top} is combinational: each step of --stimulus is one input vector, "
                                  "and 'cycles' applies to clocked designs")
        vecs = [step.get("set", {}) for step in steps]
    elif args.set:
        vecs = [inputs.parse_sets(args.set)]
    else:
        vecs = mc.all_vectors(netlist)
    for v in vecs:
        pack_inputs(netlist, v)
    return vecs


def job_of(args) -> dict:
    """The job a results file is keyed by."""
    from ..physics import network
    from ..synthesis.synth import synthesize
    from ..experiments import montecarlo as mc
    path = mc.design_path(args.design).resolve()
    nl = synthesize(path, max_fanout=network.MAX_FANOUT)
    if nl.clocked:
        return _clocked_job(args, nl, path)
    job = {"design": str(path), "design_sha256": mc.netlist_sha256(nl), "params": args.params,
           "vectors": vectors_of(args, nl), "backend": args.backend,
           "spread": spread_spec(args).describe(), "seed": args.seed, "periods": args.periods,
           "union": args.batch}
    if args.noise:                   # only then: results files of noiseless sweeps keep their keys
        job["noise"] = args.noise
    return job


def _clocked_job(args, nl, path) -> dict:
    """A clocked design's job: its stimulus of clock cycles (--stimulus), run one sample per task."""
    from ..experiments import montecarlo as mc
    from ..experiments.mc_clocked import CLOCKED_BACKENDS
    if not args.stimulus:
        raise Mech2SpiceError(f"{nl.top} is clocked: give its cycles with --stimulus FILE.json "
                              "([{\"set\": {PORT: INT}, \"cycles\": N}, ...])")
    if args.set or args.periods:
        raise Mech2SpiceError("--set and --periods apply to combinational designs (a clocked one takes --stimulus)")
    if args.backend not in CLOCKED_BACKENDS:
        raise Mech2SpiceError(f"clocked montecarlo runs on {', '.join(CLOCKED_BACKENDS)}, not '{args.backend}'")
    steps = inputs.stimulus_steps(args.stimulus, {}, engine_class(args.backend))
    job = {"design": str(path), "design_sha256": mc.netlist_sha256(nl), "params": args.params, "steps": steps,
           "backend": args.backend, "spread": spread_spec(args).describe(), "seed": args.seed,
           "union": 1}
    if args.noise:
        job["noise"] = args.noise
    return job


def cmd_montecarlo(args) -> int:
    """Run the sweep; print the summary (text or JSON); 0 if every sample passed, else 1."""
    import tempfile
    from ._output import log as _log, print_json as _print_json, progress as _progress
    from ..experiments import mc_run, montecarlo as mc
    check_out(args, {**dict(inputs.design_inputs(mc.design_path(args.design))), "the --stimulus file": args.stimulus})
    job = job_of(args)
    log = _log(args)
    with tempfile.TemporaryDirectory() as tmp:
        out = Path(args.out) if args.out else Path(tmp) / "results.jsonl"
        res = mc_run.run(job, args.samples, out, scheduler=args.scheduler, workers=args.workers,
                         progress=_progress(args), log=log)
    res.update({"design": job["design"], "backend": job["backend"], "spread": job["spread"], "seed": job["seed"],
                "noise": job.get("noise", 0.0), **trim_json(job["spread"])})
    if not args.out:
        res.pop("out")
    if args.json:
        _print_json(res)
    else:
        _print(res)
    return 0 if res["failures"] == 0 else 1


def _print(res: dict) -> None:
    lo, hi = res["yield_ci95"]
    print(f"{res['samples']} samples, {res['failures']} failures: yield {res['yield']:.4f} (95 % CI {lo:.4f} - {hi:.4f})")
    stopped = sum(res["reasons"].values())       # samples that diverged or did not run: they have no margin
    if res["margin_quantiles"]:
        print("margin quantiles (band widths): " + ", ".join(f"{q} {v:+.3f}" for q, v in res["margin_quantiles"].items())
              + (f" (over the {res['margin_samples']} samples with a margin)" if stopped else ""))
    elif stopped:
        print("margin quantiles: none (every sample diverged or did not run)")
    if stopped:
        print(f"{stopped} samples stopped early: " + "; ".join(
            f"{k} x {reason}" for reason, k in sorted(res["reasons"].items(), key=lambda kv: -kv[1])[:5]))
    if res["failing_bits"]:
        print("failing bits (samples): " + ", ".join(f"{b} {n}" for b, n in res["failing_bits"].items()))
    if res["gate_failure_rate"] is not None:
        print(f"gate failure rate {res['gate_failure_rate']:.3g} per gate and sample ({res['gates']} gates)")
    print(f"{res['ran']} run here ({res['resumed']} resumed), {res['samples_per_s']:.2f} samples/s on "
          f"{res['workers']} worker(s), {res['wall_s']:.1f} s")


# --- `mech2spice cpu montecarlo PROG.asm`: the processor's yield ---------------------------------------
def add_cpu_parser(sub) -> None:
    """Register `cpu montecarlo` under the `cpu` command's subparsers."""
    c = sub.add_parser(
        "montecarlo", help="yield of the processor under per-element spread, compared with the ISS every cycle",
        description="Sample the processor's oscillator model with a relative Gaussian spread on every element, "
                    "run PROG for --cycles cycles on each sample and compare every cycle (pc, phase, read "
                    "address and data, write enable, address and data) with the instruction-set simulator. "
                    "Results stream to --out (resumable). An envelope sample costs about 0.05 s of CPU per "
                    "cycle at the processor's defaults (reports/cpu_physical.md), far more with --noise (the "
                    "noisy envelope steps at most one period and never freezes a gate). Exit 0 when every "
                    "sample passed, 1 otherwise.")
    c.add_argument("program", help="assembly source (.asm) or binary image")
    c.add_argument("--cycles", type=inputs.integer(1, 100_000), default=30, help="clock cycles per sample (default 30)")
    c.add_argument("--backend", default="envelope", choices=names(continuing, first="envelope"))
    max_fanout_arg(c)
    c.add_argument("--step", type=inputs.number(0), default=None, metavar="PERIODS",
                   help="envelope: the step in drive periods (default: the processor's own, 16 (20 where ETDRK4 "
                        "steps the amplitudes) or the largest of 16, 8, 4 .. within the model's stability bound; a "
                        "whole number up to that bound, e.g. 10 where the ladder gives 8: fewer steps, but a marginal sample may fail at another cycle: "
                        "docs/design.md, 'A cheaper sample')")
    add_sweep_arguments(c)
    c.set_defaults(func=cmd_cpu_montecarlo)


def max_fanout_arg(parser) -> None:
    """--max-fanout: the processor's buffer trees (synthesis.synth.limit_fanout), a physical run's lever."""
    from ..physics.network import MAX_FANOUT
    parser.add_argument("--max-fanout", type=inputs.integer(2, 64), default=None, metavar="N",
                        help=f"envelope, carrier, rk4: give every gate driving more than N loads a tree of buffer "
                             f"pairs (default {MAX_FANOUT}; fewer loads per gate, more gates: docs/design.md)")


def cpu_job_of(args) -> dict:
    """The processor job a results file is keyed by (the program by path and content hash)."""
    import hashlib
    path = Path(args.program)
    if not path.exists():
        raise Mech2SpiceError(f"no such program: {args.program}")
    return {"program": str(path.resolve()), "program_sha256": hashlib.sha256(path.read_bytes()).hexdigest(),
            "cycles": args.cycles, "params": args.params, "backend": args.backend,
            "spread": spread_spec(args).describe(), "seed": args.seed, "union": 1,
            **({"noise": args.noise} if args.noise else {}),      # noiseless files keep their keys
            **_fanout_key(args.max_fanout), **_step_key(args), **_integrator_key(args)}


def _step_key(args) -> dict:
    """The job's envelope step, only when set (results files of the default step keep their keys)."""
    step = getattr(args, "step", None)
    if step is None:
        return {}
    if args.backend != "envelope":
        raise Mech2SpiceError(f"--step applies to the envelope backend, not {args.backend}")
    return {"step": step}


def _integrator_key(args) -> dict:
    """The envelope's exponential step with ETDRK4 (each amplitude's own rate exact, backends/envelope.py), the
    processor's step cap under it (cpu/physical.ETD_PROCESSOR_STEP), its latency calm rule (LATENCY_CALM) and wake
    threshold (LATENCY_WAKE): a job of its own, so a results file written before any of them resumes with the
    settings it was written with."""
    from ..cpu.physical import ETD_PROCESSOR_STEP, LATENCY_CALM, LATENCY_WAKE
    return ({"integrator": "etd", "etd_step": ETD_PROCESSOR_STEP, "latency_calm": LATENCY_CALM,
             "latency_wake": LATENCY_WAKE}
            if args.backend == "envelope" else {})


def _step_key_of(job: dict) -> dict:
    return {"step": job["step"]} if "step" in job else {}


def _fanout_key(max_fanout: int | None) -> dict:
    """The job's max_fanout, only when it is not the network's own limit (results files keep their keys)."""
    from ..physics.network import MAX_FANOUT
    return {"max_fanout": max_fanout} if max_fanout and max_fanout != MAX_FANOUT else {}


def cmd_cpu_montecarlo(args) -> int:
    """Run the processor sweep; print the summary; 0 if every sample passed, else 1."""
    import tempfile
    from ._output import log as _log, print_json as _print_json, progress as _progress
    from ..experiments import mc_run
    from ..physics import network
    check_out(args, {"the program": args.program})
    job = cpu_job_of(args)
    if "step" in job:
        mc_run.design_for(job)           # an explicit step is checked against the stability bound before any work
    with tempfile.TemporaryDirectory() as tmp:
        out = Path(args.out) if args.out else Path(tmp) / "results.jsonl"
        res = mc_run.run(job, args.samples, out, scheduler=args.scheduler, workers=args.workers,
                         progress=_progress(args), log=_log(args))
    res.update({"program": job["program"], "cycles": job["cycles"], "backend": job["backend"],
                "max_fanout": job.get("max_fanout", network.MAX_FANOUT), **_step_key_of(job),
                "spread": job["spread"], "seed": job["seed"], "noise": job.get("noise", 0.0), **trim_json(job["spread"])})
    if not args.out:
        res.pop("out")
    if args.json:
        _print_json(res)
    else:
        _print(res)
    return 0 if res["failures"] == 0 else 1
