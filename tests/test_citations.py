"""Every repository path and `mech2spice.*` module the prose cites exists (issues #26, #28).

Scanned: README.md, docs/**/*.md, reports/*.md, and the string literals of mech2spice/reports/*.py
(the text the report generators write into reports/*.md, so a stale citation is caught before a
report is re-run), and the "command" fields of reports/*.json (rendered into the reports as the
command that reproduces a run).  Found, per source line:

* repository paths: a token that starts with one of the repository's folders (``mech2spice/``,
  ``scripts/``, ``tests/``, ``docs/``, ``reports/``, ``verilog/``, ``programs/``, ``subckts/``,
  ``veriloga/``, ``benchmarks/``, ``.ci/``) or with a subpackage of mech2spice (``physics/steady.py``
  is read as ``mech2spice/physics/steady.py``; ``reports/...`` is the repository's reports folder, so
  a generator is cited as ``mech2spice/reports/gate.py``);
* ``folder/module.attr`` (``cpu/physical.PhysicalCPU``): the module file must exist and define it;
* bare ``.py`` names (``network.py``, ``report_adder.py``): some file of that name must exist in the
  repository (the prose names them inside a folder's context).  Other bare names (``ck.json``,
  ``stats.json``) are mostly what a command writes and are not checked; a profile listing's
  ``file.py:LINE(function)`` names third-party files and is skipped;
* markdown link targets ``[text](target)``: resolved from the file's folder (reports/ for the
  generators' strings, which end up in reports/*.md); URLs and anchors are not checked;
* absolute paths (``/work/...``, ``/home/...``): a citation outside the repository is stale, except
  the shared reference folder, which must be cited as ``../shared/...`` (the folder beside the
  repository) and is checked only where that folder is present;
* dotted module names ``mech2spice.a.b``: must resolve to a module file, a trailing part to a name
  the module defines;
* ``module.name`` in inline code, where the module is one of mech2spice's by its file name
  (``simulation.clock_timing``, ``clocking.block_slowdown``): some module of that name defines it;
* commands ``mech2spice WORD`` (at a command's start, or after ``python -m``) in code (inline code, fenced blocks, the
  data files' commands): WORD must be a subcommand of the command line.

Excluded, by one rule (`_placeholder`): tokens with a placeholder (an all-capitals word such as ``NAME``,
``FILE``, ``DIR``, ``DESIGN.v``, ``PROG.asm``; ``*``, ``{...}``, ``<...>``, ``...``), temporary paths
(``/tmp/``), and what the code writes at run time (`GENERATED`, a short list).  The test fails listing
``source:line: token (why)``; ``python3 tests/test_citations.py`` prints the same list.
"""
import ast
import importlib
import importlib.util
import json
import re
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
SHARED = ROOT.parent / "shared"

TOP_DIRS = ("mech2spice", "scripts", "tests", "docs", "reports", "verilog", "programs", "subckts",
            "veriloga", "benchmarks", ".ci")
SUBPACKAGES = tuple(sorted(p.name for p in (ROOT / "mech2spice").iterdir()
                           if p.is_dir() and (p / "__init__.py").exists()))

# Outputs a documented command writes, not files the repository holds.  Keep short: each entry is
# named in an example command line whose output it is.
GENERATED = {
    # numba's on-disk kernel cache, created beside the kernels on the first run (README, docs/latency.md)
    "mech2spice/backends/__pycache__",
    # scripts/stability_sweep.py --out STEM writes STEM.json and STEM.md (the commands in its reports)
    "reports/stability_sweep", "reports/stability_sweep_carrier", "reports/stability_sweep_carrier6",
    "reports/stability_sweep_long", "reports/stability_sweep_long2",
}

_CHAR = r"[A-Za-z0-9_.\-/{}<>*]"
_PATH = re.compile(
    r"(?<![A-Za-z0-9_./\-])"
    r"((?:\.\./shared/|/work/|/home/|/root/|/tmp/|(?:" + "|".join(re.escape(d) for d in TOP_DIRS + SUBPACKAGES)
    + r")/)" + _CHAR + r"*)")
# a path in another repository, as rtl_suite.md's sources name it: `owner/repo @ commit: path, path`
_FOREIGN = re.compile(r"[\w.-]+/[\w.-]+ @ [0-9a-f]{7,40}: (?:[^|,\s]+, )*$")
_BARE = re.compile(r"(?<![A-Za-z0-9_./\-])([A-Za-z0-9_\-]+\.py)(?![A-Za-z0-9_/\-]|:\d+\()")
_LINK = re.compile(r"\]\(([^()\s]+)\)")
_COMMAND = re.compile(r"(?:^|[;&|(]|\$ |python3? -m )\s*(?:[A-Z_]+=\S*\s+)*"   # where a command starts
                      r"mech2spice(?:\.cli)?[ \t]+([a-z][a-z0-9_\-]*)(?![A-Za-z0-9_./])")
_CODE_SPAN = re.compile(r"`([^`]+)`")
_ATTR = re.compile(r"(?<![A-Za-z0-9_./\-])([a-z_][a-z0-9_]*)\.([A-Za-z_][A-Za-z0-9_]*)(?![A-Za-z0-9_/])")
_MODULE = re.compile(r"(?<![A-Za-z0-9_./\-])(mech2spice(?:\.[A-Za-z_][A-Za-z0-9_]*)+)")


def _placeholder(token):
    """A token that stands for a name the reader supplies, or a temporary file."""
    if token.startswith("/tmp/") or any(c in token for c in ("*", "{", "}", "<", ">", "...")):
        return True
    words = re.split(r"[/.]", token)
    return any(re.fullmatch(r"[A-Z][A-Z0-9_]*", w) and w != "README" for w in words)


def _sources():
    """(label, lines) for every scanned source: a file's lines, or (line number, text) pairs for the
    generators' string literals (one pair per line of a literal) and the data files' commands (line 0)."""
    files = [ROOT / "README.md", *sorted((ROOT / "docs").rglob("*.md")), *sorted((ROOT / "reports").glob("*.md"))]
    for f in files:
        yield f.relative_to(ROOT).as_posix(), f.read_text(encoding="utf-8").splitlines()
    for f in sorted((ROOT / "mech2spice" / "reports").glob("*.py")):
        source = f.read_text(encoding="utf-8")
        raw, lines = source.splitlines(), []
        for node in ast.walk(ast.parse(source)):
            if isinstance(node, ast.Constant) and isinstance(node.value, str):
                for piece in node.value.splitlines():
                    # the source line that holds this piece (a literal's own line numbers are off inside f-strings)
                    at = next((n for n in range(node.lineno, len(raw) + 1) if piece.strip() in raw[n - 1]), node.lineno)
                    lines.append((at, piece))
        yield f.relative_to(ROOT).as_posix(), lines
    for f in sorted((ROOT / "reports").glob("*.json")):
        commands = []
        _commands(json.loads(f.read_text(encoding="utf-8")), commands)
        yield f.relative_to(ROOT).as_posix(), [(0, c) for c in commands]


def _commands(node, found):
    """The "command" strings of a report's data file: the generators print them as the command that
    reproduces the run.  (Other strings there are measurement records, e.g. the checkpoints a run read.)"""
    if isinstance(node, dict):
        for key, value in node.items():
            if key == "command" and isinstance(value, str):
                found.append(value)
            else:
                _commands(value, found)
    elif isinstance(node, list):
        for value in node:
            _commands(value, found)


_ALL_NAMES = None


def _basenames():
    global _ALL_NAMES
    if _ALL_NAMES is None:
        _ALL_NAMES = {p.name for p in ROOT.rglob("*") if ".git" not in p.parts}
    return _ALL_NAMES


def _check_path(token):
    """None when the cited path exists, else why not."""
    token = token.rstrip(".,;:)/`'\"") or token
    if token in GENERATED:
        return None
    if token.startswith(("/work/", "/home/", "/root/")):
        if "/shared/" in token:
            return "absolute path; cite the shared folder as ../shared/" + token.split("/shared/", 1)[1]
        return "path outside the repository"
    if token.startswith("../shared/"):
        if not SHARED.is_dir():
            return None
        return None if (ROOT / token).exists() else "missing in ../shared"
    head = token.split("/", 1)[0]
    candidates = []
    if head in TOP_DIRS:
        candidates.append(ROOT / token)
    elif head in SUBPACKAGES:
        candidates.append(ROOT / "mech2spice" / token)
    if any(c.exists() for c in candidates):
        return None
    stem, _, attr = token.rpartition(".")
    if stem and "/" in stem and re.fullmatch(r"[A-Za-z_][A-Za-z0-9_]*", attr) and not (ROOT / token).suffix[1:] in (
            "py", "md", "v", "asm", "json", "png", "va", "txt", "sh"):
        dotted = ("" if head == "mech2spice" else "mech2spice.") + stem.replace("/", ".") + "." + attr
        return _check_module(dotted)
    return "no such path"


def _check_module(token):
    parts = token.split(".")
    for n in range(len(parts), 0, -1):
        base = ROOT.joinpath(*parts[:n])
        if base.with_suffix(".py").is_file() or (base / "__init__.py").is_file():
            rest = parts[n:]
            break
    else:
        return "no such module"
    if not rest:
        return None
    try:
        obj = importlib.import_module(".".join(parts[:n]))
        for name in rest:
            obj = getattr(obj, name)
    except (ImportError, AttributeError):
        return f"{'.'.join(parts[:n])} has no {'.'.join(rest)}"
    return None


_SUBCOMMANDS = None


def _subcommands():
    """The first word of every `mech2spice` command line."""
    global _SUBCOMMANDS
    if _SUBCOMMANDS is None:
        import argparse
        from mech2spice.cli import build_parser
        actions = [a for a in build_parser()._actions if isinstance(a, argparse._SubParsersAction)]
        _SUBCOMMANDS = set(actions[0].choices)
    return _SUBCOMMANDS


_STEMS = None
_EXTENSIONS = {"py", "md", "json", "sim", "cir", "v", "asm", "va", "osdi", "txt", "png", "npz", "raw", "subckt", "inc"}
_NOT_MODULES = {"mech2spice", "model"}      # the package; `model.design`: a MechModel in the prose


def _check_attr(stem, name):
    """None when some mech2spice module named `stem` defines `name` (or has it as a submodule); else why
    not; None too when no module has that name (then it is not a citation of ours)."""
    global _STEMS
    if _STEMS is None:
        _STEMS = {}
        for p in (ROOT / "mech2spice").rglob("*.py"):
            parts = p.relative_to(ROOT).with_suffix("").parts
            parts = parts[:-1] if parts[-1] == "__init__" else parts
            _STEMS.setdefault(parts[-1], []).append(".".join(parts))
    modules = _STEMS.get(stem, [])
    if not modules or stem in _NOT_MODULES or name in _EXTENSIONS:
        return None
    for module in modules:
        if importlib.util.find_spec(f"{module}.{name}") if (ROOT / module.replace(".", "/") / "__init__.py").exists() \
                else False:
            return None
        if hasattr(importlib.import_module(module), name):
            return None
    return f"no module {stem} defines {name}"


def _code(label, lines):
    """(line number, code text) of a source: inline code and fenced blocks of markdown; every line of the
    generators' literals is searched for inline code; a data file's commands are code throughout."""
    fenced = False
    for lineno, text in lines:
        if label.endswith(".json"):
            yield lineno, text
            continue
        if text.lstrip().startswith("```"):
            fenced = not fenced
            continue
        if fenced:
            yield lineno, text
        else:
            for span in _CODE_SPAN.findall(text):
                yield lineno, span


def _drop_urls(text):
    """A URL's path is not a repository path."""
    return re.sub(r"https?://\S+", " ", text)


def find_stale():
    stale = []
    for label, lines in _sources():
        numbered = lines if lines and isinstance(lines[0], tuple) else list(enumerate(lines, 1))
        for lineno, code in _code(label, numbered):
            if not label.endswith(".json"):
                for m in _ATTR.finditer(code):
                    why = _check_attr(*m.groups())
                    if why:
                        stale.append(f"{label}:{lineno}: {m.group(0)} ({why})")
            for m in _COMMAND.finditer(code):
                if m.group(1) not in _subcommands():
                    where = f"{label}:{lineno}" if lineno else f"{label} (a command)"
                    stale.append(f"{where}: mech2spice {m.group(1)} (no such subcommand)")
        for lineno, text in numbered:
            where = f"{label}:{lineno}" if lineno else f"{label} (a command)"
            text = _drop_urls(text)
            for m in _PATH.finditer(text):
                token = m.group(1)
                if _placeholder(token) or _FOREIGN.search(text[:m.start()]):
                    continue
                why = _check_path(token)
                if why:
                    stale.append(f"{where}: {token} ({why})")
            for m in _BARE.finditer(text):
                token = m.group(1)
                if _placeholder(token) or token in GENERATED or token in _basenames():
                    continue
                stale.append(f"{where}: {token} (no file of that name in the repository)")
            for m in _LINK.finditer(text):
                target = m.group(1).split("#")[0]
                if not target or re.match(r"[a-z]+:", target) or _placeholder(target):
                    continue
                base = ROOT / "reports" if label.endswith((".py", ".json")) else (ROOT / label).parent
                path = (base / target).resolve()
                if path.is_relative_to(SHARED.resolve(strict=False)) or path.is_relative_to(ROOT.parent / "shared"):
                    if SHARED.is_dir() and not path.exists():
                        stale.append(f"{where}: ]({target}) (missing in ../shared)")
                elif not path.is_relative_to(ROOT):
                    stale.append(f"{where}: ]({target}) (link outside the repository)")
                elif not path.exists():
                    stale.append(f"{where}: ]({target}) (link target missing)")
            for m in _MODULE.finditer(text):
                why = _check_module(m.group(1))
                if why:
                    stale.append(f"{where}: {m.group(1)} ({why})")
    return sorted(set(stale))


def test_cited_paths_and_modules_exist():
    stale = find_stale()
    assert not stale, "stale citations:\n" + "\n".join(stale)


if __name__ == "__main__":
    print("\n".join(find_stale()))
