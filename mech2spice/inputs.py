"""Every user-supplied value is checked here before work starts: numbers, JSON files read, paths written.

Each check raises Mech2SpiceError with one line naming the option or file and what was expected
(the command line prints it and exits 2).  The argparse ``type=`` factories raise
``argparse.ArgumentTypeError`` instead, which the parser turns into the same one line.
"""
from __future__ import annotations

import argparse
import dataclasses
import json
import math
import numbers
import os
import re
import stat
import tempfile
from collections.abc import Mapping
from pathlib import Path

from .errors import Mech2SpiceError

# Resource guards.  The logic backend keeps a trace entry per cycle (~4 KB with its JSON: 1e6 cycles is
# ~4 GB); a physical cycle is a few thousand drive periods, kept as amplitudes per observed bit.
MAX_CYCLES = 1_000_000
MAX_PHYSICAL_CYCLES = 10_000
MAX_PERIODS = 10_000_000          # drive periods of one run (memory grows ~16 B per period and probe)
MAX_STEPS = 100_000               # steps per drive period
MAX_CPU_CYCLES = 1_000_000_000    # `cpu run --max-cycles`: no per-cycle memory, only time
MAX_FANOUT_LIMIT = 10 ** 6        # `--max-fanout`: beyond it, no buffer is ever inserted


# --------------------------------------------------------------------------- numbers (argparse types)

def integer(lo: int, hi: int):
    """An argparse type: a whole decimal number in [lo, hi]."""
    def parse(text: str) -> int:
        try:
            value = int(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"expected a whole number from {lo} to {hi:,}, got {text!r}") \
                from None
        if not lo <= value <= hi:
            raise argparse.ArgumentTypeError(_out_of_range(lo, hi, value))
        return value
    parse.__name__ = "integer"
    return parse


def _out_of_range(lo: int, hi: int, value) -> str:
    return f"must be from {lo} to {hi:,}, got {value}"


def number(lo: float, hi: float = math.inf, *, lo_open: bool = True):
    """An argparse type: a finite float in (lo, hi] ([lo, hi] with lo_open=False); NaN and inf refused."""
    def parse(text: str) -> float:
        try:
            value = float(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"expected a number, got {text!r}") from None
        low_ok = value > lo if lo_open else value >= lo
        if not (math.isfinite(value) and low_ok and value <= hi):
            span = f"{'above' if lo_open else 'at least'} {lo:g}" + ("" if hi == math.inf else f" and at most {hi:g}")
            raise argparse.ArgumentTypeError(f"must be a finite number {span}, got {text!r}")
        return value
    parse.__name__ = "number"
    return parse


def number_or_off(lo: float, hi: float):
    """An argparse type: 'off' (0.0) or a finite float in (lo, hi)."""
    def parse(text: str) -> float:
        if text.strip().lower() == "off":
            return 0.0
        try:
            value = float(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"expected a number or 'off', got {text!r}") from None
        if not (math.isfinite(value) and lo < value < hi):
            raise argparse.ArgumentTypeError(f"must be 'off' or a number above {lo:g} and below {hi:g}, got {text!r}")
        return value
    parse.__name__ = "number_or_off"
    return parse


def envelope_speed_args(parser) -> None:
    """The speed-up flags of the envelope (docs/latency.md) and the carrier's latency, on `simulate` and `cpu run`."""
    parser.add_argument("--latency", type=number_or_off(0, 1), default=None, metavar="TOL|off",
                        help="envelope, carrier: freeze settled gates until an input moves by TOL u_R (off: "
                             "integrate every gate; docs/latency.md, docs/carrier.md)")
    parser.add_argument("--exponential", choices=["on", "off"], default=None,
                        help="envelope: step the insulators exactly and, where they bound the step, each "
                             "amplitude's own rate too (ETDRK4), which lifts the stability bound on the step")
    parser.add_argument("--parallel", choices=["on", "off"], default=None,
                        help="envelope: the rates on all cores (without latency; slower on a busy machine)")


def parse_sets(items: list[str] | None) -> dict[str, int]:
    """--set PORT=INT ... -> {port: value}; ranges are checked against the design (ports.pack_inputs)."""
    values = {}
    for item in items or []:
        port, sep, val = item.rpartition("=")      # a value holds no "=", an escaped port name may
        if not sep or not port.strip():
            raise Mech2SpiceError(f"--set expects PORT=INT, got {item!r}")
        if port.strip() in values:
            raise Mech2SpiceError(f"--set {port.strip()} is given twice: give each input once")
        values[port.strip()] = integer_text(val, f"--set {port.strip()}")
    return values


_INTEGER = re.compile(r"[+-]?(?:0[xX][0-9a-fA-F_]+|0[bB][01_]+|0[oO][0-7_]+|[0-9][0-9_]*)")
MAX_DIGITS = 1000        # far above any port's width in digits; Python itself stops at 4300


def integer_text(text: str, what: str) -> int:
    """A whole number written in ASCII: decimal (leading zeros allowed: 09 is 9), 0x, 0b or 0o, `_` between
    digits.  int() alone took '٣' (an Arabic-Indic three) as 3 and refused 09."""
    t = text.strip()
    if len(t) > MAX_DIGITS:
        raise Mech2SpiceError(f"{what}: a number of {len(t):,} characters (at most {MAX_DIGITS:,} are read)")
    if not _INTEGER.fullmatch(t) or "__" in t or t.endswith("_"):
        raise Mech2SpiceError(f"{what}: {_shown_text(text)} is not a whole number (decimal, 0x, 0b or 0o)")
    body = t.lstrip("+-")
    value = int(body, 0) if body[:2].lower() in ("0x", "0b", "0o") else int(body, 10)
    return -value if t.startswith("-") else value


def _shown_text(text: str) -> str:
    """A user's text in a message: quoted, control characters escaped, at most 40 characters."""
    return repr(text[:40]) + ("…" if len(text) > 40 else "")


# --------------------------------------------------------------------------- files read

MAX_INPUT_BYTES = 256 << 20      # a user's design, stimulus or parameter file: far above any real one


def read_input(path, what: str, limit: int = MAX_INPUT_BYTES) -> bytes:
    """A user's input file's bytes; one clear error if unreadable or past `limit` (/dev/zero read until the
    memory ran out, then the design was blamed for its size)."""
    if _named_pipe(path):
        raise Mech2SpiceError(f"cannot read {what} {path}: a named pipe, not a file (reading it waits for a "
                              "writer that may never come)")
    try:
        with open(path, "rb") as f:
            data = f.read(limit + 1)
    except OSError as err:
        raise Mech2SpiceError(f"cannot read {what} {path}: {err.strerror or err}") from None
    if len(data) > limit:
        raise Mech2SpiceError(f"{what} {path} holds more than {limit >> 20} MiB: not a file this reads")
    return data


def _named_pipe(path) -> bool:
    """Whether `path` is a FIFO in the file system (standard input, piped, is left to be read)."""
    try:
        return stat.S_ISFIFO(os.stat(path).st_mode) and str(path) not in ("-", "/dev/stdin") \
            and not os.path.samefile(path, "/proc/self/fd/0")
    except (OSError, ValueError, TypeError):
        return False


# --------------------------------------------------------------------------- JSON files

def _unique_keys(pairs: list) -> dict:
    """A JSON object whose keys are all different (a repeated key was read as its last value, silently)."""
    out = dict(pairs)
    if len(out) < len(pairs):
        seen = set()
        twice = next(k for k, _ in pairs if k in seen or seen.add(k))
        raise ValueError(f"the key {twice[:60]!r} appears twice in one object")
    return out


def read_json(path, what: str):
    """The parsed content of a user's JSON file; one clear error if unreadable, not UTF-8 or not JSON."""
    raw = read_input(path, what)
    if raw.startswith(b"\xef\xbb\xbf"):
        raise Mech2SpiceError(f"{what} {path} begins with a UTF-8 byte-order mark, which JSON does not allow: "
                              "save it without one")
    try:
        text = raw.decode("utf-8")
    except UnicodeDecodeError as err:
        raise Mech2SpiceError(f"{what} {path} is not UTF-8 text (bad byte at offset {err.start})") from None
    try:
        return json.loads(text, parse_constant=_no_constant, object_pairs_hook=_unique_keys)
    except json.JSONDecodeError as err:
        raise Mech2SpiceError(f"{what} {path} is not valid JSON: {err.msg} (line {err.lineno})") from None
    except (ValueError, RecursionError) as err:     # NaN/Infinity, >4300-digit integers, deep nesting
        why = str(err) or type(err).__name__
        if "Exceeds the limit" in why:               # Python's advice (sys.set_int_max_str_digits) is not ours
            why = "an integer of more than 4,300 digits, which no field takes"
        raise Mech2SpiceError(f"{what} {path} is not usable JSON: {why}") from None


def finite(o, default=None):
    """`o` as strict JSON data: a non-finite number becomes None (the writer states why beside it, e.g. a
    sample's 'reason'), numpy values Python's, tuples lists; anything else through `default` if given."""
    if isinstance(o, dict):
        return {k: finite(v, default) for k, v in o.items()}
    if isinstance(o, (list, tuple)):
        return [finite(v, default) for v in o]
    if o is None or isinstance(o, (str, bool, int)):
        return o
    if isinstance(o, float):
        return o if math.isfinite(o) else None
    if default is not None:
        return finite(default(o), default)
    return finite(o.tolist()) if hasattr(o, "tolist") else o      # numpy arrays and scalars


def strict_json(data, default=None, **dumps) -> str:
    """The one JSON writer of files and output: strict JSON (no NaN/Infinity, which `jq` and other strict
    readers refuse; `finite` writes null), through `finite`; `dumps`: json.dumps's layout arguments."""
    return json.dumps(finite(data, default), allow_nan=False, **dumps)


def _no_constant(name: str):
    raise ValueError(f"{name} is not a JSON number")


def type_name(value) -> str:
    """How JSON would call a Python value's type (for messages); a number that is not usable as itself."""
    if isinstance(value, (int, float)) and not isinstance(value, bool) and not is_number(value):
        return f"{value:.3g}" if isinstance(value, float) else "an integer beyond the float range"
    return {dict: "an object", list: "a list", str: "a string", bool: "true/false", int: "an integer",
            float: "a number", type(None): "null"}.get(type(value), type(value).__name__)


def is_int(value) -> bool:
    """A JSON integer (true/false are not numbers here)."""
    return isinstance(value, int) and not isinstance(value, bool)


MAX_NAME = 80          # a name a user's file gives (a design, a block): shown in reports and netlist comments


def is_name(value) -> bool:
    """Printable text of at most MAX_NAME characters (no newline or control character: names reach
    netlist comments and one-line messages)."""
    return isinstance(value, str) and 0 < len(value) <= MAX_NAME and value.isprintable()


def is_number(value) -> bool:
    """A finite JSON number (integer or float, not true/false) that fits a float."""
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        return False
    try:
        return math.isfinite(value)
    except OverflowError:                       # an integer beyond the float range
        return False


def stimulus_steps(path, base: dict[str, int], engine) -> list[dict]:
    """A --stimulus file checked: [{"set": {PORT: INT}, "cycles": N}, ...], the --set values under each step's;
    `engine` (a registry class) states the cycle cap."""
    return check_steps(read_json(path, "stimulus file"), base, engine, f"stimulus file {path}")


def check_steps(data, base: dict[str, int], engine, where: str = "stimulus") -> list[dict]:
    """A stimulus (a file's content, or the API's list) checked: shape, types, the cycle cap (`engine`'s)."""
    if not isinstance(data, list):
        raise Mech2SpiceError(f"{where} must hold a list of steps "
                              f"([{{\"set\": {{\"PORT\": INT}}, \"cycles\": N}}, ...]), not {type_name(data)}")
    steps = []
    for k, step in enumerate(data):
        if not isinstance(step, dict):
            raise Mech2SpiceError(f"{where}, step {k}: expected an object {{\"set\": ..., \"cycles\": N}}, "
                                  f"not {type_name(step)}")
        extra = sorted(set(step) - {"set", "cycles"}, key=str)
        if extra:
            raise Mech2SpiceError(f"{where}, step {k}: unknown field(s) {', '.join(map(repr, extra))} "
                                  "(a step has 'set' and 'cycles')")
        if "set" in step and not isinstance(step["set"], Mapping):     # null too: the API's None is its own
            raise Mech2SpiceError(f"{where}, step {k}: 'set' must map port names to integers, not "
                                  f"{type_name(step['set'])}")
        sets, cycles = port_values(step.get("set", {}), f"{where}, step {k}: 'set'"), step.get("cycles", 1)
        if not is_integral(cycles) or cycles < 0:
            raise Mech2SpiceError(f"{where}, step {k}: 'cycles' must be a whole number >= 0, not "
                                  f"{json_shown(cycles)}")
        steps.append({"set": {**base, **sets}, "cycles": int(cycles)})
    check_cycles(sum(s["cycles"] for s in steps), engine, f"{where} asks for")
    return steps


def check_cycles(total: int, engine, what: str = "--cycles asks for") -> None:
    """Refuse runs longer than the cap the engine (a class of the backends' registry) states in its
    `max_cycles` (memory and time grow with every cycle)."""
    cap = engine.max_cycles
    if total > cap:
        raise Mech2SpiceError(f"{what} {total:,} clock cycles; the {engine.name} backend is limited to {cap:,} "
                              "per run (memory grows with every cycle): split the stimulus into shorter runs")
    if total < 1:
        raise Mech2SpiceError(f"{what} no clock cycles")


# --------------------------------------------------------------------------- values given in Python (the API)
# The API's counterparts of the argparse types above: the same caps, a Mech2SpiceError for anything else.

def is_integral(value) -> bool:
    """A Python or numpy integer (true/false are not numbers here)."""
    return isinstance(value, numbers.Integral) and not isinstance(value, bool)


def json_shown(value) -> str:
    """A value read from a JSON file, spelled as JSON (true, null, 2.0), at most 40 characters."""
    try:
        text = json.dumps(value, allow_nan=False)
    except (TypeError, ValueError):
        text = repr(value)
    return text if len(text) <= 40 else text[:40] + "…"


def value_kind(value) -> str:
    """type_name for a value given in Python (None is None there, not null)."""
    return "None" if value is None else type_name(value)


def whole_number(value, what: str, lo: int, hi: int) -> int:
    """`value` as an int in [lo, hi] (`integer`'s caps for a value given in Python)."""
    if not is_integral(value):
        raise Mech2SpiceError(f"{what} must be a whole number from {lo} to {hi:,}, not {value_kind(value)}")
    if not lo <= value <= hi:
        raise Mech2SpiceError(f"{what} {_out_of_range(lo, hi, value)}")
    return int(value)


def path_value(value, what: str) -> Path:
    """A file path given as str or os.PathLike (not empty)."""
    text = os.fspath(value) if isinstance(value, (str, os.PathLike)) else None
    if not isinstance(text, str):
        raise Mech2SpiceError(f"{what} must be a file path (str or os.PathLike), not {value_kind(value)}")
    if not text:
        raise Mech2SpiceError(f"the {what} path is empty")
    return Path(text)


def port_values(values, what: str = "inputs") -> dict[str, int]:
    """{port: int} given in Python (the API's inputs, a stimulus step's 'set'): string names, integer values.
    Which ports exist and their widths are the design's to check (synthesis.ports.pack_inputs)."""
    if values is None:
        return {}
    if not isinstance(values, Mapping):
        raise Mech2SpiceError(f"{what} must map port names to integers, not {value_kind(values)}")
    for port, v in values.items():
        if not isinstance(port, str):
            raise Mech2SpiceError(f"{what} must map port names to integers: the name {port!r} is not a string")
        if not is_integral(v):
            raise Mech2SpiceError(f"{what} must map port names to integers: {port!r} -> {value_kind(v)}")
    return {port: int(v) for port, v in values.items()}


_KINDS = {"int": ("a whole number", is_integral), "bool": ("True or False", lambda v: isinstance(v, bool)),
          "float": ("a number", lambda v: isinstance(v, numbers.Real) and not isinstance(v, bool)),
          "str": ("a string", lambda v: isinstance(v, str)), "None": ("None", lambda v: v is None)}


def check_fields(options) -> None:
    """Each field of an engine's Options dataclass of the type its annotation names (int, float, bool, str,
    `| None`): a wrong type fails at construction, not deep inside a run or as a TypeError in validate.
    Ranges (NaN and inf included) are each validate's, with messages that say what the value means."""
    for f in dataclasses.fields(options):
        kinds = [k.strip() for k in (f.type if isinstance(f.type, str) else f.type.__name__).split("|")]
        if not all(k in _KINDS for k in kinds):
            continue                            # a type this check does not know: the Options' validate's
        value = getattr(options, f.name)
        if not any(_KINDS[k][1](value) for k in kinds):
            raise Mech2SpiceError(f"{type(options).__name__}.{f.name} = {value!r}: must be "
                                  f"{' or '.join(_KINDS[k][0] for k in kinds)}")


# --------------------------------------------------------------------------- files written
# One rule for every file a command writes, command line and API alike, checked before any work: never an
# input of the same command, never an existing file of another kind unless forced, in a folder we can write.

def check_output_file(path, inputs=(), what: str = "output file", *, kind=None, force: bool = False,
                      remedy: str = "give --force to replace it", parents: bool = False,
                      regular: bool = False) -> Path:
    """A file we may write.  `inputs`: {label: path} (or paths) the same command reads or also writes,
    compared through links, never written whatever `force`; `kind`: (name, test) telling a file this command
    writes (replaced or resumed): an existing non-empty file that fails it is refused unless `force` (`remedy`
    says how to give it); kind None: any file may be replaced (for the package's own files).  `parents`: the
    writer creates missing folders, so the nearest existing one must take files.  `regular`: a device or a
    pipe is refused (a checkpoint, replaced by a rename and read back), where others are written in place."""
    p = Path(path)
    if not str(path):
        raise Mech2SpiceError(f"the {what} name is empty")
    if p.is_dir():
        raise Mech2SpiceError(f"{what} {path} is a directory")
    for label, src in _labelled(inputs):
        if _same_file(p, Path(src)):
            raise Mech2SpiceError(f"{what} {path} is {label} {src}: refusing to overwrite it")
    if p.exists() and not p.is_file():            # a device or pipe (/dev/null, /dev/stdout): written in place
        if regular:
            raise Mech2SpiceError(f"{what} {path} is not a regular file (a device or a pipe): a {what} is "
                                  "replaced whole and read back, so give a file name")
        if not os.access(p, os.W_OK):
            raise Mech2SpiceError(f"{what} {path} is not writable")
        _check_reader(p, path, what)
        return p
    folder = p.parent
    while parents and not folder.exists() and folder != folder.parent:
        folder = folder.parent
    _check_folder(folder, path, what)
    if p.exists():
        if not os.access(p, os.W_OK):
            raise Mech2SpiceError(f"{what} {path} is not writable")
        if kind is not None and not force and p.stat().st_size and not kind[1](p):
            raise Mech2SpiceError(f"{what} {path} exists and is not {kind[0]}: refusing to overwrite it ({remedy})")
    return p


def _check_reader(p: Path, path, what: str) -> None:
    """A named pipe is written only when something reads it (else the write waits forever)."""
    if not stat.S_ISFIFO(p.stat().st_mode):
        return
    try:
        os.close(os.open(p, os.O_WRONLY | os.O_NONBLOCK))
    except OSError:
        raise Mech2SpiceError(f"{what} {path} is not a regular file but a named pipe that nothing reads: the "
                              "write would wait forever") from None


def check_inside(path, folder, what: str) -> Path:
    """`path` as written under `folder` (an --out folder): a name that leaves it (`..`, an absolute path, a link
    out) is refused, so a stem option cannot write elsewhere."""
    base, p = Path(folder).resolve(), (Path(folder) / path).resolve()
    if p == base or base not in p.parents:
        raise Mech2SpiceError(f"{what} {path} is not a file inside the output folder {folder}")
    return Path(folder) / path


INCLUDE = re.compile(r'`include\s+"([^"\n]+)"')       # anywhere (a commented one too: the check errs safe)
MAX_INCLUDES = 256


def design_inputs(design, label: str = "the design") -> list[tuple[str, Path]]:
    """(label, path) of a Verilog design and of every file it `include`s, transitively, wherever Yosys or
    Icarus may find it (beside the including file, beside the design, or as written): an output of a
    command that reads the design is none of them."""
    if not isinstance(design, (str, os.PathLike)) or not str(design):
        return []
    found, todo = [(label, Path(design))], [Path(design)]
    while todo and len(found) < MAX_INCLUDES:
        src = todo.pop()
        try:
            text = read_input(src, "Verilog file").decode("utf-8", errors="replace")
        except Mech2SpiceError:
            continue
        for name in INCLUDE.findall(text):
            for cand in (src.parent / name, Path(design).parent / name, Path(name)):
                if cand.is_file() and not any(_same_file(cand, f) for _, f in found):
                    found.append((f"`include \"{name}\" of {src},", cand))
                    todo.append(cand)
        for name in _readmem_names(text):            # a ROM's words (docs/rtl.md, "ROMs read from a file")
            cand = src.parent / name
            if cand.is_file() and not any(_same_file(cand, f) for _, f in found):
                found.append((f"the $readmem file \"{name}\" of {src},", cand))
    return found


_READMEM_NAME = re.compile(r'\$readmem[hb]\s*\(\s*"((?:\\.|[^"\\\n])*)"')


def _readmem_names(text: str) -> list[str]:
    """The file names `$readmemh`/`$readmemb` read (one in a comment counts too: kept safe all the same)."""
    return [name for name in _READMEM_NAME.findall(text) if name]


def force_arg(parser, option: str) -> None:
    """--force: what lets an output replace a file of another kind (never an input of the command)."""
    parser.add_argument("--force", action="store_true",
                        help=f"let {option} replace an existing file that is not this command's own output "
                             "(an input of the command is never replaced)")


def head(path, size: int = 4096) -> bytes:
    """The first bytes of a file (b"" if unreadable): enough to tell what wrote it."""
    try:
        with open(path, "rb") as f:
            return f.read(size)
    except OSError:
        return b""


def first_json_line(path, limit: int = 64 << 20):
    """The first line of a file parsed as JSON, or None (not UTF-8, not JSON, unreadable)."""
    try:
        with open(path, "rb") as f:
            return json.loads(f.readline(limit).decode("utf-8"))
    except (OSError, ValueError, RecursionError):
        return None


def _labelled(inputs):
    """(label, path) pairs of the file inputs ({label: path}, (label, path) pairs or bare paths; program
    bytes and None left out)."""
    pairs = inputs.items() if isinstance(inputs, dict) else \
        (src if isinstance(src, tuple) else ("the input", src) for src in inputs)
    return [(label, src) for label, src in pairs if isinstance(src, (str, os.PathLike)) and str(src)]


def check_output_dir(path, what: str = "output directory", parents: bool = False) -> Path:
    """A folder we may write into: existing, or created (its last component only; with `parents`, every
    missing one)."""
    p = Path(path)
    if not str(path):
        raise Mech2SpiceError(f"the {what} name is empty")
    if p.exists() and not p.is_dir():
        raise Mech2SpiceError(f"{what} {path} exists and is not a directory")
    base = p if p.exists() else p.parent
    while parents and not base.exists() and base != base.parent:
        base = base.parent
    _check_folder(base, path, what)
    return p


def write_text(path, text: str, encoding: str = "utf-8") -> None:
    """write_bytes of the encoded text."""
    write_bytes(path, text.encode(encoding))


def write_bytes(path, data: bytes) -> None:
    """Write an output file whole or not at all (`replace_file`; devices and pipes are written directly); an
    OS failure such as a full disk becomes one clear error."""
    p = Path(path)
    if p.exists() and not p.is_file():
        try:
            with open(p, "wb") as f:
                f.write(data)
        except OSError as err:
            raise Mech2SpiceError(f"cannot write {path}: {err.strerror or err}") from None
        return
    replace_file(p, data)


def replace_file(path, data: bytes, *, durable: bool = False) -> None:
    """Replace a regular file whole or not at all: a temporary file beside it, under a fresh name created
    exclusively (never an existing file, nor a link someone left under a predictable name), fsynced when
    `durable` (a checkpoint: on disk before the rename makes it the file), then renamed over it.  A device
    or a pipe at `path` is refused: a rename would put a file in its place (as root, /dev/null's)."""
    p = Path(path)
    if p.exists() and not p.is_file():
        raise Mech2SpiceError(f"cannot write {path}: not a regular file (a device or a pipe); this file is "
                              "replaced whole, so give a file name")
    try:
        fd, tmp = tempfile.mkstemp(dir=str(p.parent) or ".", prefix=f".{p.name}.", suffix=".tmp")
    except OSError as err:
        raise Mech2SpiceError(f"cannot write {path}: {err.strerror or err}") from None
    try:
        with os.fdopen(fd, "wb") as f:
            f.write(data)
            if durable:
                f.flush()
                os.fsync(f.fileno())
        os.chmod(tmp, 0o666 & ~_umask())         # mkstemp's 0600 would hide an output from its owner's group
        os.replace(tmp, p)
    except OSError as err:
        Path(tmp).unlink(missing_ok=True)
        raise Mech2SpiceError(f"cannot write {path}: {err.strerror or err}") from None


def _umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask


def _check_folder(folder: Path, path, what: str) -> None:
    folder = folder if str(folder) else Path(".")
    if not folder.exists():
        raise Mech2SpiceError(f"cannot write {what} {path}: directory {folder} does not exist")
    if not folder.is_dir():
        raise Mech2SpiceError(f"cannot write {what} {path}: {folder} is not a directory")
    try:                          # a real file, not os.access: root passes that on a read-only mount
        fd, probe = tempfile.mkstemp(dir=folder, prefix=".mech2spice-", suffix=".probe")
    except OSError as err:
        raise Mech2SpiceError(f"cannot write {what} {path}: directory {folder} is not writable "
                              f"({err.strerror or err})") from None
    os.close(fd)
    os.unlink(probe)


def _same_file(a: Path, b: Path) -> bool:
    try:
        return os.path.samefile(a, b)
    except OSError:                              # one of them does not exist (yet)
        return a.resolve() == b.resolve()
