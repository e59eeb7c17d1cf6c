"""Property-based tests (hypothesis): random Verilog against Python, random command lines and JSON files.

Bounded for CI: few examples, no deadline; Yosys (~0.3 s a run) is cached per (file, options) in the
command-line tests, and the gate's minute-long characterisation is replaced by a canned result there
(what is tested is the handling of the input, not the physics).
"""
import contextlib
import copy
import functools
import io
import json
import shutil
import string
from pathlib import Path

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from mech2spice import cli
from mech2spice.backends.logic import evaluate
from mech2spice.synthesis import synth

ROOT = Path(__file__).resolve().parents[1]
ADDER, COUNTER, SIEVE = (str(ROOT / p) for p in ("verilog/adder2.v", "verilog/counter4.v", "programs/sieve.asm"))
FAST = settings(max_examples=20, deadline=None, derandomize=True, database=None,
                suppress_health_check=[HealthCheck.function_scoped_fixture, HealthCheck.too_slow])

# ------------------------------------------------------------------ random expressions vs Python
# Every node is 2 bits wide (booleans are widened with {1'b0, ...}), so Verilog's width rules reduce
# to "each operation modulo 4" and Python can evaluate the same tree exactly.

MASK = 3
BINARY = {"&": lambda x, y: x & y, "|": lambda x, y: x | y, "^": lambda x, y: x ^ y,
          "+": lambda x, y: x + y, "-": lambda x, y: x - y, "*": lambda x, y: x * y}
BOOLEAN = {"<": lambda x, y: x < y, "==": lambda x, y: x == y, "!=": lambda x, y: x != y,
           ">=": lambda x, y: x >= y}
UNARY = {"~": lambda x: ~x, "-": lambda x: -x, "<< 1": lambda x: x << 1, ">> 1": lambda x: x >> 1}
REDUCE = {"&": lambda x: x == MASK, "|": lambda x: x != 0, "^": lambda x: bin(x).count("1") % 2, "!": lambda x: x == 0}

leaves = st.one_of(st.sampled_from(["a", "b", "c"]), st.integers(0, MASK))


def _extend(children):
    return st.one_of(
        st.tuples(st.sampled_from(sorted(BINARY)), children, children).map(lambda t: ("bin", *t)),
        st.tuples(st.sampled_from(sorted(BOOLEAN)), children, children).map(lambda t: ("bool", *t)),
        st.tuples(st.sampled_from(sorted(UNARY)), children).map(lambda t: ("un", *t)),
        st.tuples(st.sampled_from(sorted(REDUCE)), children).map(lambda t: ("red", *t)),
        st.tuples(children, children, children).map(lambda t: ("mux", *t)))


expressions = st.recursive(leaves, _extend, max_leaves=8)


def to_verilog(e) -> str:
    if isinstance(e, str):
        return e
    if isinstance(e, int):
        return f"2'd{e}"
    kind, *args = e
    if kind == "bin":
        return f"({to_verilog(args[1])} {args[0]} {to_verilog(args[2])})"
    if kind == "bool":
        return f"{{1'b0, ({to_verilog(args[1])} {args[0]} {to_verilog(args[2])})}}"
    if kind == "un":
        op, x = args
        return f"({to_verilog(x)} {op})" if op.startswith(("<<", ">>")) else f"({op}{to_verilog(x)})"
    if kind == "red":
        return f"{{1'b0, ({args[0]}{to_verilog(args[1])})}}"
    return f"({to_verilog(args[0])} ? {to_verilog(args[1])} : {to_verilog(args[2])})"


def py_eval(e, env: dict) -> int:
    if isinstance(e, str):
        return env[e]
    if isinstance(e, int):
        return e
    kind, *args = e
    if kind in ("bin", "bool"):
        table = BINARY if kind == "bin" else BOOLEAN
        return int(table[args[0]](py_eval(args[1], env), py_eval(args[2], env))) & MASK
    if kind == "un":
        op, x = args
        return int(UNARY[op](py_eval(x, env))) & MASK
    if kind == "red":
        return int(REDUCE[args[0]](py_eval(args[1], env)))
    return py_eval(args[1] if py_eval(args[0], env) else args[2], env)


@FAST
@given(st.lists(expressions, min_size=1, max_size=6))
def test_logic_backend_equals_python_on_random_expressions(tmp_path, exprs):
    """Several random expressions (one output each) in one module: every input combination through
    Yosys -> NOR netlist -> logic backend equals Python's evaluation of the same tree."""
    outs = "".join(f", output [1:0] y{k}" for k in range(len(exprs)))
    body = "".join(f"  assign y{k} = {to_verilog(e)};\n" for k, e in enumerate(exprs))
    src = tmp_path / "rand.v"
    src.write_text(f"module rand(input [1:0] a, input [1:0] b, input [1:0] c{outs});\n{body}endmodule\n")
    nl = synth.synthesize(src)
    for a in range(4):
        for b in range(4):
            for c in range(4):
                env = {"a": a, "b": b, "c": c}
                got = evaluate(nl, env)
                want = {f"y{k}": py_eval(e, env) for k, e in enumerate(exprs)}
                assert got == want, (src.read_text(), env)


def test_expression_model_knows_verilog_widths(tmp_path):
    """The Python model itself, on cases where a width slip would show (a test that can fail)."""
    e = ("bool", "<", ("bin", "+", "a", "b"), "c")         # a + b wraps at 2 bits before the compare
    assert py_eval(e, {"a": 3, "b": 2, "c": 2}) == 1
    src = tmp_path / "w.v"
    src.write_text(f"module w(input [1:0] a, input [1:0] b, input [1:0] c, output [1:0] y);\n"
                   f"  assign y = {to_verilog(e)};\nendmodule\n")
    assert evaluate(synth.synthesize(src), {"a": 3, "b": 2, "c": 2}) == {"y": 1}


# ------------------------------------------------------------------ random command lines and files

def _json_values():
    scalars = st.one_of(st.none(), st.booleans(), st.integers(-10, 10 ** 7), st.floats(allow_nan=False),
                        st.text(max_size=6))
    return st.recursive(scalars, lambda c: st.one_of(st.lists(c, max_size=4),
                                                     st.dictionaries(st.text(max_size=6), c, max_size=4)),
                        max_leaves=10)


# A JSON file: random values, shapes close to the real ones, or broken bytes.
json_files = st.one_of(
    _json_values().map(lambda v: json.dumps(v).encode()),
    st.dictionaries(st.sampled_from(["q_c", "k_g", "omega", "name", "f_r", "bogus"]),
                    st.one_of(st.floats(), st.integers(-5, 10 ** 400), st.text(max_size=4)), max_size=3)
    .map(lambda d: json.dumps(d).encode()),
    st.lists(st.fixed_dictionaries({}, optional={
        "set": st.dictionaries(st.sampled_from(["rst", "clk", "q", "x"]), st.integers(-2, 20), max_size=2),
        "cycles": st.one_of(st.integers(-2, 10 ** 9), st.floats(), st.text(max_size=3))}), max_size=3)
    .map(lambda v: json.dumps(v).encode()),
    st.binary(max_size=40))

numbers = st.one_of(st.integers(1, 3000).map(str), st.integers(-3, 10 ** 12).map(str), st.floats().map(str),
                    st.sampled_from(["nan", "inf", "-inf", "", "0x10", "1e3", "abc", "--json"]))
ports = st.sampled_from(["a", "b", "s", "rst", "clk", "q", "nope", "", "a[0]"])
sets = st.lists(st.tuples(ports, numbers).map(lambda t: f"{t[0]}={t[1]}"), max_size=3)


@pytest.fixture
def cheap(monkeypatch):
    """Yosys runs cached per (file, top, max_fanout); the gate's characterisation canned."""
    real = synth.synthesize

    @functools.lru_cache(maxsize=64)
    def cached(path, top=None, max_fanout=None):
        return real(path, top, max_fanout=max_fanout)
    monkeypatch.setattr(synth, "synthesize",
                        lambda path, top=None, *, max_fanout=None: copy.deepcopy(cached(str(path), top, max_fanout)))
    from mech2spice.experiments import characterise
    canned = {"params": {"name": "x", "omega": 1.0}, "truth_table": [], "switches": False, "min_margin": -1,
              "requirements": {}, "rk4_vs_steady": 0.0, "step_halving_change": 0.0, "min_margin_detail": {}}
    monkeypatch.setattr(characterise, "characterise", lambda p, quick=False, log=None: copy.deepcopy(canned))


def check_outcome(argv: list[str]) -> None:
    """Valid JSON (with --json and exit 0/1), or exactly one line on stderr with exit 2; never a traceback."""
    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        rc = cli.main(argv)
    out, err = out.getvalue(), err.getvalue()
    assert "Traceback" not in err and rc != cli.BUG_EXIT, (argv, err)
    if rc == 2:
        assert err.count("\n") == 1 and "error:" in err, (argv, err)
    else:
        assert rc in (0, 1), (argv, rc, err)
        if "--json" in argv:
            json.loads(out)


def _options(draw, table: dict) -> list[str]:
    """Some of the options in `table` (name -> strategy of its value, None for a flag), in random order."""
    argv = []
    for name in draw(st.lists(st.sampled_from(sorted(table)), max_size=4, unique=True)):
        argv += [name] if table[name] is None else [name, draw(table[name])]
    return argv


@st.composite
def json_file(draw, tmp: Path) -> str:
    """A path to a file with random JSON-ish content."""
    path = tmp / draw(st.sampled_from(["params.json", "stim.json"]))
    if path.is_dir():                            # an earlier `subckts -o params.json` made it a folder
        shutil.rmtree(path)
    path.write_bytes(draw(json_files))
    return str(path)


@st.composite
def command_lines(draw, tmp: Path):
    """A random command line for any command, with random JSON files where a file is expected."""
    files = json_file(tmp)
    params = st.one_of(st.sampled_from(["default", "printed", "nope"]), files)
    design = draw(st.sampled_from([ADDER, COUNTER, str(tmp / "missing.v")]))
    common = {"--params": params, "--top": st.sampled_from(["adder2", "counter4", "x y"]),
              "--max-fanout": numbers, "--observe": ports}
    command = draw(st.sampled_from(["synth", "simulate", "emit", "subckts", "gate", "cpu asm", "cpu run"]))
    if command == "synth":
        return ["synth", design, "--json", *_options(draw, common)]
    if command == "simulate":
        argv = ["simulate", design, "--backend", "logic", "--json", *_options(draw, {
            **common, "--cycles": numbers, "--stimulus": files, "--periods": numbers, "--pulse": numbers,
            "--pause": numbers, "--clock": ports, "--steps": numbers})]
        return argv + [x for s in draw(sets) for x in ("--set", s)]
    if command == "emit":
        return ["emit", design, "-o", str(tmp / "out.cir"), "--json", *_options(draw, {
            **common, "--periods": numbers, "--max-step": numbers, "--method": st.sampled_from(["trap", "x"])})]
    if command == "subckts":
        return ["subckts", "-o", str(tmp / draw(st.sampled_from(["lib", "params.json", "no/such"]))), "--json",
                *_options(draw, {"--params": params})]
    if command == "gate":
        return ["gate", "--json", *_options(draw, {"--params": params, "--quick": None})]
    if command == "cpu asm":
        return ["cpu", "asm", draw(st.sampled_from([SIEVE, str(tmp / "stim.json")])), "-o", str(tmp / "p.bin")]
    checkpoint = draw(st.one_of(st.just(str(tmp / "ck.json")), files))
    return ["cpu", "run", SIEVE, "--json", *_options(draw, {
        "--backend": st.sampled_from(["iss", "logic", "spice"]), "--max-cycles": numbers,
        "--checkpoint": st.just(checkpoint), "--resume": None, "--checkpoint-every": numbers,
        "--step": numbers, "--settle": numbers})]


@settings(max_examples=150, deadline=None, derandomize=True, database=None,
          suppress_health_check=[HealthCheck.function_scoped_fixture, HealthCheck.too_slow])
@given(data=st.data())
def test_random_command_lines_and_files_never_give_a_traceback(tmp_path, cheap, data):
    argv = data.draw(command_lines(tmp_path))
    if "logic" in argv and argv[0] == "cpu":            # keep each example short: the sieve halts at 457
        for option, value in (("--max-cycles", "600"), ("--checkpoint-every", "100")):
            if option in argv:
                argv[argv.index(option) + 1] = value
    check_outcome(argv)


@FAST
@given(st.text(alphabet=string.printable, max_size=60))
def test_random_verilog_text_never_gives_a_traceback(tmp_path, text):
    src = tmp_path / "r.v"
    src.write_text(f"module r(input a, output y);\n{text}\nendmodule\n")
    check_outcome(["synth", str(src), "--json"])
