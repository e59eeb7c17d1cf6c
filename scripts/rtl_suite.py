"""The public RTL suite (issue 34): every design of $MECH2SPICE_BENCHMARKS/rtl/manifest.json through
`synth`, `verify --backend logic` and an envelope sample, one row per design.

    python scripts/rtl_suite.py [--jobs N] [--only NAME ...] [--timeout S] [--envelope-gates N]

Each step runs as `python -m mech2spice.cli ...` in a subprocess with a time budget, so a crash or a hang
is a row, not a stop.  Results are cached in build/rtl_suite/ keyed by the design's source digest and the
tool's git commit (plus a digest of uncommitted changes to mech2spice/), so a rerun only measures what
changed.  Writes docs/rtl_suite.md and docs/rtl_suite.json.

The manifest (outside git, like the ISCAS files): {"designs": [{name, file, top, clock, reset,
reset_level, repo, paths, commit, licence, kind, ...}]}, written with the design files by
scripts/rtl_suite_stage.py from mirrors of the source repositories.  Sources are named per design in the table.
"""
from __future__ import annotations

import argparse
import hashlib
import json
import os
import re
import subprocess
import sys
import time
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
FORMAT = 2     # bump when a row's fields change: cached rows of another format are measured again

# Refusal classes, first match wins: (class, pattern on the refusal line).
CLASSES = [
    ("asynchronous set/reset", r"asynchronous set/reset|both an asynchronous set and an asynchronous reset"),
    ("power-up value (declaration initialiser)", r"initial value in its declaration"),
    ("`initial` block", r"`initial`"),
    ("tri-state driver", r"tri-state"),
    ("inout port", r"\binout\b"),
    ("both clock edges", r"falling clock edge and others on the rising one|negative-edge"),
    ("several or derived clocks", r"clocked by several ports|clocked directly by one input port|clock .* also used as data|clocked by logic|takes the clock .* as data|clock is computed from the input port"),
    ("a block testing none of its listed edges (a flip-flop on several clocks)", r"tests none of"),
    ("level-sensitive latch", r"level-sensitive latch"),
    ("undriven net", r"nothing drives it|not driven by anything"),      # before memory: its line names memory words
    ("memory", r"\$mem|memory"),
    ("other sequential cell", r"sequential cell"),
    ("several top modules", r"several top-level modules"),
    ("combinational loop", r"combinational loop"),
    ("$display/$write in the design", r"\$display"),
    ("incomplete sensitivity list", r"sensitivity list"),
    ("a net assigned in an always block", r"is a net \(a wire or a port without `reg`\) assigned in an always block"),
    ("`===` against x or z", r"`===` against a value with x or z"),
    ("Yosys could not read the source", r"yosys error"),
]

# Why an accepted design does not pass `verify --backend logic`, first match wins: (class, pattern on its
# verdict's detail).  The lead re-runs the suite after merging the branches that address these.
VERIFY_CLASSES = [
    ("escaped identifiers in the written-back network", r"gate\.v, line \d+: syntax error"),
    ("memory in the equivalence proof", r"\$memrd|\$memwr|\$mem\b|No SAT model available for cell .*mem"),
    # an unreproduced counterexample: its detail also says "outputs differ", so it is matched first
    ("start state: a counterexample the replay from power-up does not reproduce", r"the start state, not the mapping"),
    ("x in the source past its reset: a counterexample the replay from power-up does not reproduce",
     r"what made the difference is the source's own x"),
    ("x or z in the source: a counterexample on bits the source leaves undefined (a released tri-state output)",
     r"the source reads x or z where they differ"),
    ("equivalence counterexample", r"outputs differ"),
    ("proof budget ran out", r"time budget \(\d+ s\) ran out"),
    ("induction did not close (bounded check found no difference)", r"induction did not close"),
    ("equivalence not proved", r"not proved|unproved|induction"),
    ("co-simulation mismatch in a source that races (blocking '=' between clocked blocks on one edge)",
     r"co-simulation mismatches; the source races"),
    ("co-simulation mismatch", r"co-simulation mismatches"),
    ("Icarus could not run the source", r"iverilog failed"),
]


def main(argv=None) -> int:
    args = _parser().parse_args(argv)
    root = _benchmarks()
    designs = json.loads((root / "manifest.json").read_text())["designs"]
    if args.only:
        unknown = set(args.only) - {d["name"] for d in designs}
        if unknown:
            sys.exit(f"rtl_suite: no design named {', '.join(sorted(unknown))} in the manifest")
        designs = [d for d in designs if d["name"] in args.only]
    tool = _tool_version()
    started = time.time()
    with ThreadPoolExecutor(max(1, args.jobs)) as pool:
        rows = list(pool.map(lambda d: _row(d, root, tool, args), designs))
    if args.only:      # a partial run updates its rows in the stored table
        rows = _merge(rows, args.out)
    _write(rows, tool, time.time() - started, args)
    return 0


def _parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--jobs", type=int, default=1, help="designs measured at once (default 1)")
    p.add_argument("--only", action="append", metavar="NAME", help="only this design (repeatable)")
    p.add_argument("--timeout", type=float, default=300, help="seconds per step (default 300)")
    p.add_argument("--proof-time", type=float, default=240,
                   help="verify's proof budget in seconds (default 240: ITC'99 b14 takes ~90 s alone, more "
                        "beside another design)")
    p.add_argument("--envelope-gates", type=int, default=300,
                   help="largest design (NOR gates) given an envelope sample (default 300)")
    p.add_argument("--envelope-cycles", type=int, default=4, help="clock cycles of the envelope sample")
    p.add_argument("--no-cache", action="store_true", help="measure every design again")
    p.add_argument("--out", type=Path, default=ROOT / "docs", help="folder of rtl_suite.md/.json (default docs/)")
    p.add_argument("--cache", type=Path, default=ROOT / "build" / "rtl_suite", help="the results cache folder")
    return p


def _benchmarks() -> Path:
    base = os.environ.get("MECH2SPICE_BENCHMARKS")
    if not base or not (Path(base) / "rtl" / "manifest.json").is_file():
        sys.exit("rtl_suite: set MECH2SPICE_BENCHMARKS to a folder holding rtl/manifest.json")
    return Path(base) / "rtl"


def _tool_version() -> str:
    """The git commit, plus a digest of uncommitted changes to the package (they change results too)."""
    head = subprocess.run(["git", "rev-parse", "--short=12", "HEAD"], cwd=ROOT, capture_output=True,
                          text=True).stdout.strip() or "unknown"
    diff = subprocess.run(["git", "diff", "HEAD", "--", "mech2spice"], cwd=ROOT, capture_output=True).stdout
    return head + (f"+{hashlib.sha256(diff).hexdigest()[:8]}" if diff else "")


# --------------------------------------------------------------------------- one design

def _row(design: dict, root: Path, tool: str, args) -> dict:
    path = root / design["file"]
    source = path.read_bytes()
    key = hashlib.sha256(json.dumps([FORMAT, tool, hashlib.sha256(source).hexdigest(), design.get("top"),
                                     design.get("reset"), args.timeout, args.proof_time, args.envelope_gates,
                                     args.envelope_cycles]).encode()).hexdigest()[:24]
    cached = args.cache / f"{design['name']}-{key}.json"
    row = None if args.no_cache else _cached_row(cached, design["name"])
    if row is None:
        row = _measure(design, path, args)
        row["tool"] = tool
        args.cache.mkdir(parents=True, exist_ok=True)
        cached.write_text(json.dumps(row, indent=1))
    # what the manifest says of the design (not measured) is read from it now: a corrected note needs no rerun
    row.update(kind=design.get("kind", ""), source=_source(design), licence=design.get("licence", "not stated"))
    print(_line(row), flush=True)
    return row


def _cached_row(cached: Path, name: str) -> dict | None:
    """A cached row, or None (measured again) when there is none or it is not a row of this design: the cache
    is rebuildable data, and what it holds only reaches the table's text."""
    try:
        row = json.loads(cached.read_text())
    except (OSError, ValueError):
        return None
    ok = isinstance(row, dict) and row.get("name") == name and isinstance(row.get("accepted"), bool)
    ok = ok and (isinstance(row.get("verify"), dict) and isinstance(row.get("envelope"), dict)
                 if row["accepted"] else isinstance(row.get("refusal"), str))
    return row if ok else None


def _measure(design: dict, path: Path, args) -> dict:
    top = ["--top", design["top"]] if design.get("top") else []
    row = {"name": design["name"], "kind": design.get("kind", ""), "source": _source(design),
           "clock": design.get("clock"), "licence": design.get("licence", "not stated")}
    synth = _cli(["synth", "--json", *top, str(path)], args.timeout)
    row["synth_s"] = synth["wall_s"]
    if synth["status"] != "ok":
        row.update(accepted=False, refusal=synth["line"], status=synth["status"])
        return row
    out = synth["json"]
    row.update(accepted=True, gates=out["logic_gates"], nor_total=out["gates"], latches=out["latches"],
               oscillators=out["oscillators"], clocked=bool(out.get("clock") or out.get("sampled_clocks")),
               sampled_clocks=out.get("sampled_clocks") or [])
    reset = _reset_flag(design)
    verify = _cli(["verify", "--json", "--backend", "logic", "--proof-time", str(args.proof_time), *top, *reset,
                   str(path)], args.timeout)
    row["verify"] = _verdict(verify)
    if out["gates"] <= args.envelope_gates:
        sample = ["--cycles", str(args.envelope_cycles)] if row["clocked"] else ["--vectors", "4"]
        env = _cli(["verify", "--json", "--backend", "envelope", "--no-equivalence", *sample, *top, *reset,
                    str(path)], args.timeout)
        row["envelope"] = _verdict(env)
    else:
        row["envelope"] = {"verdict": "skipped", "detail": f"{out['gates']} gates > {args.envelope_gates}"}
    return row


def _source(design: dict) -> str:
    paths = ", ".join(design.get("paths", []))
    return f"{design.get('repo', '?')} @ {str(design.get('commit', '?'))[:10]}: {paths}"


def _reset_flag(design: dict) -> list[str]:
    """No flag: verify reads each reset port and its level from the design (docs/verify.md, Resets).  The
    manifest's bare port name used to be passed here, and `--reset NAME` takes its level from the name: the
    GCD's active-high `rst_n` was asserted at 0 and the FIFO's active-low `reset` at 1, so neither was reset.
    The row records the resets verify chose (`resets`), to be read against the manifest's `reset_level`."""
    return []


def _cli(argv: list[str], timeout: float) -> dict:
    """Run one command of the tool; status ok | refused (exit 2, its line) | failed (exit 1) | crash | timeout."""
    t0 = time.time()
    try:
        proc = subprocess.run([sys.executable, "-m", "mech2spice.cli", *argv], cwd=ROOT, capture_output=True,
                              text=True, timeout=timeout)
    except subprocess.TimeoutExpired:
        return {"status": "timeout", "line": f"no result within {timeout:.0f} s", "wall_s": time.time() - t0}
    res = {"wall_s": round(time.time() - t0, 2), "rc": proc.returncode}
    try:
        res["json"] = json.loads(proc.stdout)
    except json.JSONDecodeError:
        res["json"] = None
    lines = [ln for ln in proc.stderr.splitlines() if ln.strip()]
    res["line"] = lines[-1] if lines else ""
    if proc.returncode == 2:
        res["status"] = "refused"
    elif proc.returncode in (0, 1) and res["json"] is not None:
        res["status"] = "ok"
    else:
        res["status"] = "crash"
        res["line"] = res["line"] or f"exit {proc.returncode}"
    return res


def _verdict(res: dict) -> dict:
    """verify's verdict, its equivalence status and co-simulation agreement, or why there is none."""
    if res["status"] != "ok":
        return {"verdict": res["status"], "detail": res["line"], "wall_s": res["wall_s"]}
    out = res["json"]
    eq = out.get("equivalence") or {}
    cosim = out.get("cosim") or {}
    detail = eq.get("detail", "") if eq.get("status") not in (None, "proved") else ""
    if cosim and not cosim.get("agree", True):
        detail = (detail + "; " if detail else "") + f"{len(cosim.get('mismatches', []))} co-simulation mismatches"
    if out.get("races"):                        # the source's meaning depends on the simulator (docs/rtl.md)
        names = sorted({r["variable"] for r in out["races"]})
        detail += (f"; the source races: {len(out['races'])} values passed by blocking '=' between clocked "
                   f"blocks on one edge ({', '.join(names)})")
    resets = [f"{r['port']}={r['level']} ({r.get('rule', '?')})" for r in cosim.get("resets") or []]
    return {"verdict": out.get("verdict"), "equivalence": eq.get("status"), "cosim_agree": cosim.get("agree"),
            "resets": resets,
            "stable": cosim.get("stable"), "min_margin": cosim.get("min_margin"), "detail": detail,
            "wall_s": res["wall_s"]}


def _verify_class(verdict: dict) -> str:
    if verdict["verdict"] in ("timeout", "crash"):
        return verdict["verdict"]
    for name, pattern in VERIFY_CLASSES:
        if re.search(pattern, verdict.get("detail") or ""):
            return name
    return "other"


def _refusal_class(row: dict) -> str:
    """The class of a refused row, from its refusal line (at render time: a new class needs no rerun)."""
    status = row.get("status", row.get("crash"))
    if status in ("timeout", "crash"):
        return status
    for name, pattern in CLASSES:
        if re.search(pattern, row["refusal"]):
            return name
    return "other"


# --------------------------------------------------------------------------- output

def _line(row: dict) -> str:
    if not row["accepted"]:
        return f"{row['name']:24s} REFUSED  {_refusal_class(row)}: {row['refusal'][:150]}"
    v, e = row["verify"], row["envelope"]
    return (f"{row['name']:24s} accepted {row['gates']:6d} gates {row['latches']:4d} latches "
            f"{row['oscillators']:7d} osc  verify {v['verdict']}"
            f"{'' if not v.get('equivalence') else ' (' + v['equivalence'] + ')'}  envelope {e['verdict']}")


def _merge(rows: list[dict], out: Path) -> list[dict]:
    stored = out / "rtl_suite.json"
    old = json.loads(stored.read_text())["rows"] if stored.is_file() else []
    new = {r["name"]: r for r in rows}
    merged = [new.pop(r["name"], r) for r in old]
    return merged + list(new.values())


def _summary(rows: list[dict]) -> dict:
    accepted = [r for r in rows if r["accepted"]]
    single = [r for r in rows if r.get("clock") is None or "," not in str(r.get("clock"))]
    classes: dict[str, list[str]] = {}
    for r in rows:
        if not r["accepted"]:
            classes.setdefault(_refusal_class(r), []).append(r["name"])
    failing: dict[str, list[str]] = {}
    for r in accepted:
        if r["verify"]["verdict"] != "pass":
            failing.setdefault(_verify_class(r["verify"]), []).append(r["name"])
    return {"designs": len(rows), "accepted": len(accepted), "refused": len(rows) - len(accepted),
            "verify_failure_classes": dict(sorted(failing.items(), key=lambda kv: -len(kv[1]))),
            "verify_pass": sum(r["verify"]["verdict"] == "pass" for r in accepted),
            "single_clock": len(single),
            "sampled_clocks": sorted(r["name"] for r in accepted if r.get("sampled_clocks")),
            "single_clock_verify_pass": sum(r["accepted"] and r["verify"]["verdict"] == "pass" for r in single),
            "envelope_pass": sum(r["envelope"]["verdict"] == "pass" for r in accepted),
            "envelope_run": sum(r["envelope"]["verdict"] != "skipped" for r in accepted),
            "refusal_classes": dict(sorted(classes.items(), key=lambda kv: -len(kv[1])))}


def _write(rows: list[dict], tool: str, wall: float, args) -> None:
    summary = _summary(rows)
    load = os.getloadavg()
    meta = {"tool": tool, "date": time.strftime("%Y-%m-%d %H:%M UTC", time.gmtime()),
            "load_avg": [round(x, 2) for x in load], "cpus": os.cpu_count(), "wall_s": round(wall, 1),
            "timeout_s": args.timeout, "proof_time_s": args.proof_time, "envelope_gates": args.envelope_gates,
            "envelope_cycles": args.envelope_cycles}
    docs = args.out
    docs.mkdir(parents=True, exist_ok=True)
    (docs / "rtl_suite.json").write_text(json.dumps({"meta": meta, "summary": summary, "rows": rows}, indent=1) + "\n")
    (docs / "rtl_suite.md").write_text(_markdown(rows, summary, meta))
    s = summary
    print(f"\n{s['accepted']}/{s['designs']} accepted, verify pass {s['verify_pass']}; single-clock "
          f"{s['single_clock_verify_pass']}/{s['single_clock']} pass; envelope {s['envelope_pass']}/{s['envelope_run']}")
    for name, names in s["refusal_classes"].items():
        print(f"  {len(names):3d} refused: {name}")
    for name, names in s["verify_failure_classes"].items():
        print(f"  {len(names):3d} accepted, verify not passing: {name}")


def _cell(text) -> str:
    """A table cell: the benchmarks folder written as the variable naming it, the command's prefix dropped."""
    rtl = str(_benchmarks())
    text = str(text).replace("mech2spice: error: ", "").replace(rtl, "$MECH2SPICE_BENCHMARKS/rtl")
    return text.replace("|", "\\|").replace("\n", " ")


def _markdown(rows: list[dict], s: dict, meta: dict) -> str:
    out = ["# Public RTL suite", "",
           "Written by `scripts/rtl_suite.py` (issue 34) from `$MECH2SPICE_BENCHMARKS/rtl/manifest.json`; "
           "the design files stay outside git (their licences vary; each row names its source).  "
           f"Tool {meta['tool']}, {meta['date']}, {meta['cpus']} CPUs, load averages {meta['load_avg']}, "
           f"{meta['wall_s']} s for the rows measured in this run (cached rows cost nothing); "
           f"{meta['timeout_s']:.0f} s budget per step, {meta.get('proof_time_s', 120):.0f} s for the proof.", "",
           "Columns: *gates* are the logic NOR gates (with the fan-out buffers `synth` inserts by default), *osc.* the oscillators of the "
           "mechanical model; *verify* is `mech2spice verify --backend logic` (formal equivalence with Yosys, "
           "then Icarus co-simulation: pass needs both); *envelope* is `verify --backend envelope "
           f"--no-equivalence` on {meta['envelope_cycles']} clock cycles (4 vectors when combinational) for "
           f"designs of at most {meta['envelope_gates']} NOR gates: the physical network against Icarus.", "",
           "## Summary", "",
           f"- designs: {s['designs']}; accepted by `synth`: **{s['accepted']}**; refused: {s['refused']}",
           f"- `verify --backend logic` pass: **{s['verify_pass']}** of {s['accepted']} accepted",
           f"- single-clock designs passing verify: **{s['single_clock_verify_pass']} of {s['single_clock']}**",
           f"- envelope samples passing: {s['envelope_pass']} of {s['envelope_run']} run",
           f"- clocks sampled (several clocks, both edges, a clock read as data; docs/rtl.md): "
           f"{len(s.get('sampled_clocks', []))} ({', '.join(s.get('sampled_clocks', [])) or 'none'})", "",
           "Refusals by class (designs blocked):", "", "| class | designs | names |", "|---|---|---|"]
    for name, names in s["refusal_classes"].items():
        out.append(f"| {_cell(name)} | {len(names)} | {', '.join(names)} |")
    out += ["", "Accepted designs that do not pass `verify --backend logic`, by cause:", "",
            "| cause | designs | names |", "|---|---|---|"]
    for name, names in s["verify_failure_classes"].items():
        out.append(f"| {_cell(name)} | {len(names)} | {', '.join(names)} |")
    out += ["", "## Designs", "",
            "| design | kind | synth | gates | latches | osc. | verify (logic) | envelope | refusal / detail |",
            "|---|---|---|---|---|---|---|---|---|"]
    for r in rows:
        if not r["accepted"]:
            out.append(f"| {r['name']} | {_cell(r['kind'])} | refused | | | | | | {_cell(r['refusal'])} |")
            continue
        v, e = r["verify"], r["envelope"]
        ver = v["verdict"] + (f" ({v['equivalence']})" if v.get("equivalence") else "")
        resets = f"reset {', '.join(v['resets'])}" if v.get("resets") else ""
        sampled = f"clocks sampled: {', '.join(r['sampled_clocks'])}" if r.get("sampled_clocks") else ""
        detail = "; ".join(x for x in (sampled, v.get("detail"), e.get("detail"), resets) if x)
        out.append(f"| {r['name']} | {_cell(r['kind'])} | accepted | {r['gates']} | {r['latches']} | "
                   f"{r['oscillators']} | {_cell(ver)} | {_cell(e['verdict'])} | {_cell(detail)} |")
    out += ["", "## Sources", "", "| design | repository @ commit: paths | licence |", "|---|---|---|"]
    out += [f"| {r['name']} | {_cell(r['source'])} | {_cell(r['licence'])} |" for r in rows]
    return "\n".join(out) + "\n"


if __name__ == "__main__":
    sys.exit(main())
