"""Issue #25 sweep: ISCAS-89 sequential benchmarks under seeded random stimulus, looking for self-oscillation.

For each circuit ($MECH2SPICE_BENCHMARKS/iscas89/reset/, made by scripts/iscas89_reset.py): synthesise it; build a seeded random
stimulus (cycle 0: RST=1, then N cycles with RST=0 and random inputs); run `logic` and compare every cycle with Icarus
Verilog on the same transformed Verilog (a generated testbench); run the physical engines (`envelope`, on small
circuits `carrier`) on the same stimulus with the default block and with the old insulator Q (q_i=1.5), recording
per cycle: decoded outputs vs logic, valid, stable, growth_rate, mode_period, mode_dofs, min_margin.

Usage:  nice -n 10 python3 scripts/stability_sweep.py [--only s27,s344] [--seeds 1,2] [--cycles N] [--blocks default,q15]
                                                     [--engines envelope,carrier:4] [--out reports/stability_sweep]
Writes <out>.json (every cycle of every run) and <out>.md (the summary).
"""
from __future__ import annotations

import argparse
import json
import os
import platform
import random
import subprocess
import sys
import tempfile
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
# The public netlists are not in the repository: put them (with their reset forms from scripts/iscas89_reset.py)
# in $MECH2SPICE_BENCHMARKS/iscas89 (sources: reports/stability_sweep_summary.md).
DATA = Path(os.environ.get("MECH2SPICE_BENCHMARKS", REPO / "benchmarks")) / "iscas89" / "reset"
Q15 = {"q_i": 1.5, "name": "q15"}          # the pre-#25 insulator Q (s344 self-oscillated with it)
FIXED = {"GND": 0, "VDD": 1}               # supply pins of the ispras Verilog netlists: held, not randomised

# name, file, random cycles after the reset cycle, physical engines with their cycle counts (None: all cycles).
# Cycle counts are sized to this 2-core shared machine (envelope ~5 s a cycle on s344's 1872 oscillators).
CIRCUITS = [
    ("s27", "s27_reset.v", 30, {"envelope": None, "carrier": 10}),
    ("s386", "s386_reset.v", 12, {"envelope": None}),
    ("s400", "s400_tied_reset.v", 12, {"envelope": None}),
    ("s344", "s344_reset.v", 12, {"envelope": None}),
    ("s349", "s349_reset.v", 12, {"envelope": None}),
    ("s510", "s510_reset.v", 12, {"envelope": None}),
    ("s820", "s820_reset.v", 12, {"envelope": None}),
]
REFUSAL_PROBES = {"s400": "s400_reset.v"}   # the faithful netlist, refused by the mapping (recorded, not run)
TIMEOUT_S = 1800


def cli(args: list[str], timeout: float = TIMEOUT_S) -> tuple[int, dict | None, str, float]:
    """Run `mech2spice ARGS --json` from this tree: (exit code, JSON or None, stderr tail, wall seconds)."""
    env = dict(os.environ, PYTHONPATH=str(REPO))
    t0 = time.time()
    try:
        p = subprocess.run([sys.executable, "-m", "mech2spice.cli", *args, "--json"], capture_output=True,
                           text=True, env=env, cwd=REPO, timeout=timeout)
    except subprocess.TimeoutExpired:
        return 124, None, f"timed out after {timeout} s", time.time() - t0
    try:
        data = json.loads(p.stdout)
    except json.JSONDecodeError:
        data = None
    return p.returncode, data, p.stderr[-2000:], time.time() - t0


def random_stimulus(inputs: list[str], n: int, seed: int) -> list[dict]:
    """Cycle 0 resets (RST=1); cycles 1..n random. One clock cycle per step (the s344_two_cycles.json format)."""
    rng = random.Random(seed)
    free = [i for i in inputs if i not in FIXED and i != "RST"]
    steps = []
    for k in range(n + 1):
        s = {"RST": int(k == 0), **{i: v for i, v in FIXED.items() if i in inputs}}
        s.update({i: rng.randint(0, 1) for i in free})
        steps.append({"set": s, "cycles": 1})
    return steps


# --- Icarus Verilog reference ------------------------------------------------------------------------------------
def testbench(top: str, inputs: list[str], outputs: dict[str, int], stim: list[dict]) -> str:
    """A testbench reproducing simulate's clocked trace: trace[k] = outputs after edge k, next step's inputs applied."""
    decl = [f"reg {i};" for i in inputs] + [f"wire [{w - 1}:0] {o};" for o, w in outputs.items()]
    conns = ",".join(f".{p}({p})" for p in ["CK", *inputs, *outputs])
    fmt = " ".join("%0d" for _ in outputs)
    lines = ["module tb;", "reg CK = 0;", *decl, f"{top} dut({conns});", "initial begin"]
    for k, step in enumerate(stim):
        lines.append("  " + " ".join(f"{i} = {v};" for i, v in step["set"].items()))
        if k:  # trace[k-1] is read with this step's inputs applied
            lines.append(f'  #1 $display("{fmt}", {", ".join(outputs)});')
        lines.append("  #1 CK = 1; #1 CK = 0;")
    lines += [f'  #1 $display("{fmt}", {", ".join(outputs)});', "  $finish;", "end", "endmodule"]
    return "\n".join(lines) + "\n"


def icarus(path: Path, top: str, inputs: list[str], outputs: dict[str, int], stim: list[dict]) -> list[dict]:
    """Per-cycle outputs of the transformed Verilog under Icarus (ints; None where Icarus says x/z)."""
    with tempfile.TemporaryDirectory() as tmp:
        tb = Path(tmp) / "tb.v"
        tb.write_text(testbench(top, inputs, outputs, stim))
        vvp = Path(tmp) / "sim.vvp"
        subprocess.run(["iverilog", "-o", str(vvp), "-s", "tb", str(tb), str(path)], check=True,
                       capture_output=True, text=True)
        out = subprocess.run(["vvp", "-n", str(vvp)], check=True, capture_output=True, text=True).stdout
    rows = [ln.split() for ln in out.splitlines() if ln and not ln.startswith(("VCD", "tb.v"))]
    return [{o: (int(v) if v.isdigit() else None) for o, v in zip(outputs, r)} for r in rows]


# --- mech2spice runs -----------------------------------------------------------------------------------------------
def simulate(path: Path, top: str, stim: list[dict], backend: str, params: str | None) -> dict:
    """One `simulate` run over the whole stimulus: the JSON, exit code and wall time."""
    with tempfile.NamedTemporaryFile("w", suffix=".json", delete=False) as f:
        json.dump(stim, f)
    args = ["simulate", str(path), "--top", top, "--stimulus", f.name, "--backend", backend]
    if params:
        args += ["--params", params]
    rc, data, err, wall = cli(args)
    os.unlink(f.name)
    return {"rc": rc, "data": data, "stderr": err if data is None else "", "wall_s": round(wall, 1)}


def cycle_record(k: int, entry: dict, logic: dict | None) -> dict:
    """The per-cycle verdict fields of one trace entry, with its agreement with the logic engine."""
    st = entry.get("stability") or {}
    return {"cycle": k, "outputs": entry["outputs"],
            "equals_logic": None if logic is None else entry["outputs"] == logic,
            "valid": entry.get("valid"), "stable": entry.get("stable"), "settled": entry.get("settled"),
            "min_margin": entry.get("min_margin"), "growth_rate": st.get("growth_rate"),
            "mode_period": st.get("mode_period"), "mode_dofs": st.get("mode_dofs"),
            "fixed_point_distance": st.get("fixed_point_distance"), "stability_from": st.get("stability_from")}


def physical_run(path: Path, top: str, stim: list[dict], backend: str, params: str | None,
                 logic_trace: list[dict]) -> dict:
    run = simulate(path, top, stim, backend, params)
    trace = (run["data"] or {}).get("trace", [])
    cycles = [cycle_record(k, e, logic_trace[k] if k < len(logic_trace) else None) for k, e in enumerate(trace)]
    rates = [(c["growth_rate"], c["cycle"]) for c in cycles if c["growth_rate"] is not None]
    worst = max(rates) if rates else (None, None)
    return {"backend": backend, "block": params or "default", "rc": run["rc"], "wall_s": run["wall_s"],
            "stderr": run["stderr"], "valid": (run["data"] or {}).get("valid"),
            "stable": (run["data"] or {}).get("stable"), "cycles": cycles,
            "cycles_run": len(cycles), "agree": sum(bool(c["equals_logic"]) for c in cycles),
            "stable_cycles": sum(c["stable"] is True for c in cycles),
            "unstable_cycles": sum(c["stable"] is False for c in cycles),
            "valid_cycles": sum(c["valid"] is True for c in cycles),
            "worst_growth_rate": worst[0], "worst_cycle": worst[1],
            "worst_mode": next((c for c in cycles if c["cycle"] == worst[1]), {}).get("mode_dofs")}


def study(name: str, fname: str, n: int, engines: dict, seed: int, blocks: list, log) -> dict:
    path = DATA / fname
    rec = {"circuit": name, "file": str(path.relative_to(REPO)), "seed": seed, "random_cycles": n}
    if name in REFUSAL_PROBES:
        rc, data, err, _ = cli(["synth", str(DATA / REFUSAL_PROBES[name]), "--top", name])
        rec["faithful_netlist_refusal"] = err.strip().splitlines()[-1] if rc else None
    rc, syn, err, wall = cli(["synth", str(path), "--top", name])
    if rc:
        rec["refused"] = err.strip().splitlines()[-1]
        return rec
    rec["synth"] = {k: syn[k] for k in ("gates", "latches", "oscillators", "logic_gates", "logic_depth")}
    inputs, outputs = list(syn["inputs"]), dict(syn["outputs"])
    stim = random_stimulus(inputs, n, seed)
    rec["stimulus"] = stim
    ref = icarus(path, name, inputs, outputs, stim)
    logic = simulate(path, name, stim, "logic", None)
    ltrace = [e["outputs"] for e in logic["data"]["trace"]]
    rec["logic"] = {"wall_s": logic["wall_s"], "cycles": len(ltrace),
                    "equals_icarus": [a == b for a, b in zip(ltrace, ref)], "icarus": ref, "trace": ltrace}
    log(f"{name}: {rec['synth']}; logic==icarus {sum(rec['logic']['equals_icarus'])}/{len(ref)}")
    rec["runs"] = []
    for backend, cyc in engines.items():
        sub = stim if cyc is None else stim[:cyc]
        # a truncated run's last read sees its own inputs, not the next cycle's: compare with logic on `sub`
        lsub = ltrace if cyc is None else [e["outputs"] for e in simulate(path, name, sub, "logic", None)["data"]["trace"]]
        for params in blocks:
            r = physical_run(path, name, sub, backend, params, lsub)
            log(f"{name} {backend} {r['block']}: rc {r['rc']} {r['wall_s']} s, agree {r['agree']}/{r['cycles_run']},"
                f" stable {r['stable_cycles']}, unstable {r['unstable_cycles']}, worst {r['worst_growth_rate']}")
            rec["runs"].append(r)
    return rec


# --- summary -----------------------------------------------------------------------------------------------------
def _fmt(x, spec=".2e"):
    return "-" if x is None else format(x, spec)


def _diff(got: dict, want: dict) -> str:
    return ", ".join(f"{k} {got.get(k)} vs {v}" for k, v in want.items() if got.get(k) != v)


def _least_damped(results: list[dict], block: str) -> str:
    """One line per block: cycles judged, unstable ones, and the least damped mode seen (where)."""
    cyc = [(c["growth_rate"], r["circuit"], r["seed"], run["backend"], c["cycle"], c["stable"])
           for r in results for run in r.get("runs", []) if run["block"] == block for c in run["cycles"]
           if c["growth_rate"] is not None]
    if not cyc:
        return f"- block {block}: not run"
    g = max(cyc)
    return (f"- block {block}: {len(cyc)} cycles judged, {sum(c[5] is False for c in cyc)} unstable; least damped "
            f"mode {g[0]:+.2e}/period ({g[1]} seed {g[2]}, {g[3]}, cycle {g[4]})")


def markdown(results: list[dict], metas: list[dict]) -> str:
    passes = [f"- `scripts/stability_sweep.py {m['argv']}`: seeds {m['seeds']}, wall time {m['wall_s']:.0f} s "
              f"({m['date']})" for m in metas]
    lines = ["# Stability sweep on ISCAS-89 sequential benchmarks (issue #25)", "",
             f"Machine: {metas[0]['machine']}. Passes:", "", *passes, "",
             "Netlists: `$MECH2SPICE_BENCHMARKS/iscas89/` (not in the repository; sources in each file's "
             "header), transformed by `scripts/iscas89_reset.py` (posedge flip-flops with synchronous reset RST, "
             "state exposed as STATE). Stimulus: cycle 0 RST=1, then random inputs (GND=0, VDD=1 held).", "",
             "Blocks: `default` (insulator Q q_i=1.0, the #25 fix) and `q15` (q_i=1.5, the block before the fix). "
             "growth_rate: the least damped envelope mode's growth per drive period at the fixed point nearest each "
             "cycle's state (positive = self-oscillation).", "",
             "| circuit | seed | gates / latches / oscillators | cycles | logic = Icarus | engine | block | cycles run | "
             "outputs = logic | valid | stable | unstable | worst growth_rate (cycle) | mode period | wall s | exit |",
             "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|"]
    for r in results:
        if "refused" in r:
            lines.append(f"| {r['circuit']} | {r['seed']} | refused: {r['refused']} |" + " |" * 13)
            continue
        s, lg = r["synth"], r["logic"]
        head = (f"| {r['circuit']} | {r['seed']} | {s['gates']} / {s['latches']} / {s['oscillators']} | {lg['cycles']} | "
                f"{sum(lg['equals_icarus'])}/{len(lg['equals_icarus'])} |")
        for run in r["runs"]:
            worst = next((c for c in run["cycles"] if c["cycle"] == run["worst_cycle"]), {})
            lines.append(f"{head} {run['backend']} | {run['block']} | {run['cycles_run']} | "
                         f"{run['agree']}/{run['cycles_run']} | {run['valid_cycles']} | {run['stable_cycles']} | "
                         f"{run['unstable_cycles']} | {_fmt(run['worst_growth_rate'], '+.2e')} ({run['worst_cycle']})"
                         f" | {_fmt(worst.get('mode_period'), '.0f')} | {run['wall_s']} | {run['rc']} |")
            head = "| | | | | |"
    refused = {r["circuit"]: r["faithful_netlist_refusal"].replace(str(REPO) + "/", "")
               for r in results if r.get("faithful_netlist_refusal")}
    notes = [f"- {c}: the faithful netlist is refused by the mapping: {msg}" for c, msg in refused.items()]
    unstable = [(f"{r['circuit']} seed {r['seed']}", run["backend"], run["block"], c["cycle"], c["growth_rate"],
                 c["mode_dofs"])
                for r in results for run in r.get("runs", []) for c in run["cycles"] if c["stable"] is False]
    lines += ["", "## Findings", ""] + notes + [_least_damped(results, b) for b in ("default", "q15")]
    wrong = [f"- {r['circuit']} seed {r['seed']} {run['backend']} {run['block']} cycle {c['cycle']}: "
             f"{_diff(c['outputs'], r['logic']['trace'][c['cycle']])} (valid {c['valid']}, stable {c['stable']}, "
             f"min_margin {_fmt(c['min_margin'], '.3f')})"
             for r in results for run in r.get("runs", []) for c in run["cycles"] if c["equals_logic"] is False]
    lines += ["", "Cycles whose decoded outputs differ from logic (engine, got vs logic; a valid one is a silent "
              "error):", ""] + (wrong or ["- none"])
    lines += ["", "Unstable cycles (circuit, engine, block, cycle, growth_rate, mode DOFs):", ""]
    lines += [f"- {u[0]} {u[1]} {u[2]} cycle {u[3]}: {u[4]:+.2e}/period, {', '.join(u[5] or [])}" for u in unstable]
    if not unstable:
        lines.append("- none")
    return "\n".join(lines) + "\n"


def _engines(spec: str | None, table: dict) -> dict:
    """'envelope,carrier:4' -> {'envelope': None, 'carrier': 4}; None keeps the circuit's table entry."""
    if spec is None:
        return table
    return {e.split(":")[0]: (int(e.split(":")[1]) if ":" in e else None) for e in spec.split(",")}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--only", default=None, help="comma-separated circuit names")
    ap.add_argument("--seeds", default="1", help="comma-separated stimulus seeds")
    ap.add_argument("--cycles", type=int, default=None, help="random cycles after the reset (overrides the table)")
    ap.add_argument("--blocks", default="default,q15", help="default and/or q15")
    ap.add_argument("--engines", default=None, help="e.g. envelope or carrier:4 (overrides the table)")
    ap.add_argument("--out", default=str(REPO / "reports" / "stability_sweep"))
    ap.add_argument("--merge", nargs="+", default=None, help="JSON files of earlier passes: one summary of them all")
    args = ap.parse_args(argv)
    if args.merge:
        passes = [json.loads(Path(f).read_text()) for f in args.merge]
        results = [r for p in passes for r in p["results"]]
        Path(args.out + ".md").write_text(markdown(results, [p["meta"] for p in passes]))
        return 0
    only = set(args.only.split(",")) if args.only else None
    t0 = time.time()
    log = lambda msg: print(f"[{time.time() - t0:7.1f}s] {msg}", file=sys.stderr, flush=True)  # noqa: E731
    with tempfile.NamedTemporaryFile("w", suffix=".json", delete=False) as f:
        json.dump(Q15, f)
    blocks = [{"default": None, "q15": f.name}[b] for b in args.blocks.split(",")]
    seeds = [int(s) for s in args.seeds.split(",")]
    results = []
    for seed in seeds:
        for name, fname, n, engines in CIRCUITS:
            if only is None or name in only:
                results.append(study(name, fname, args.cycles or n, _engines(args.engines, engines), seed, blocks, log))
                Path(args.out + ".json").write_text(json.dumps({"results": results}, indent=1))
    os.unlink(f.name)
    for r in results:
        for run in r.get("runs", []):
            run["block"] = "q15" if run["block"] == f.name else run["block"]
    meta = {"seeds": seeds, "blocks": args.blocks.split(","), "wall_s": time.time() - t0, "date": time.strftime("%Y-%m-%d"),
            "argv": " ".join(sys.argv[1:]), "machine": f"2-core shared Debian 12 sandbox ({platform.processor() or platform.machine()}, "
                       f"{os.cpu_count()} CPUs, Python {platform.python_version()})", "q15_params": Q15}
    Path(args.out + ".json").write_text(json.dumps({"meta": meta, "results": results}, indent=1))
    Path(args.out + ".md").write_text(markdown(results, [meta]))
    return 0


if __name__ == "__main__":
    sys.exit(main())
