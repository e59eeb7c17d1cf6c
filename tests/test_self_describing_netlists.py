"""Emitted netlists read their own result: `ngspice -b FILE` alone (no Python in the loop) prints each output
bit's amplitude and value and each port's integer, and the header maps probed nodes to port bits."""
import json
import re
import shutil
import subprocess
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import pytest

from mech2spice import cli
from mech2spice.physics.params import band_of

ROOT = Path(__file__).resolve().parents[1]
ADDER = str(ROOT / "verilog" / "adder2.v")
CARRIER_PERIODS = 1200        # every adder input settles by then (carrier: ~8 s of ngspice per run)
BIT = re.compile(r"^(\w+)\[(\d+)\] = (\S+) u_R -> (0|1|invalid)$", re.M)
PORT = re.compile(r"^(\w+) = (?:(-?\d+) \(valid\)|(invalid))$", re.M)

pytestmark = pytest.mark.skipif(shutil.which("ngspice") is None, reason="ngspice not installed")


def emit(tmp_path, design, values, *extra) -> Path:
    """Write the netlist through the command line, in-process."""
    out = tmp_path / f"{Path(design).stem}_{'_'.join(f'{k}{v}' for k, v in values.items())}.cir"
    sets = [a for k, v in values.items() for a in ("--set", f"{k}={v}")]
    assert cli.main(["emit", str(design), *sets, "-o", str(out), "--force", *extra]) == 0
    return out


def ngspice(path: Path, valid: bool = True) -> str:
    """`ngspice -b FILE`, nothing else; its stdout (its exit status: 0 valid, 1 some bit in no band)."""
    proc = subprocess.run(["ngspice", "-b", path.name], cwd=path.parent, capture_output=True, text=True,
                          timeout=300, stdin=subprocess.DEVNULL)
    assert proc.returncode == (0 if valid else 1), proc.stdout[-2000:] + proc.stderr[-2000:]
    return proc.stdout


def reading(stdout: str) -> tuple[dict, dict]:
    """{bit: (amplitude, '0'|'1'|'invalid')}, {port: int or None} from what ngspice printed."""
    bits = {f"{p}[{i}]": (float(a), v) for p, i, a, v in BIT.findall(stdout)}
    ports = {p: None if bad else int(v) for p, v, bad in PORT.findall(stdout)}
    return bits, ports


def check_bands(bits: dict) -> None:
    """Every printed verdict is the band its printed amplitude falls in (params.band_of)."""
    for bit, (amp, verdict) in bits.items():
        b = band_of(amp)
        assert verdict == ("invalid" if b is None else str(b)), (bit, amp, verdict)


def adder_sum(tmp_path, a: int, b: int, *extra) -> tuple[dict, dict]:
    bits, ports = reading(ngspice(emit(tmp_path, ADDER, {"a": a, "b": b}, *extra)))
    check_bands(bits)
    assert set(bits) == {"s[0]", "s[1]", "s[2]"}
    assert ports == {"s": a + b}, (a, b, bits)
    return bits, ports


def all_pairs(tmp_path, pairs, *extra) -> None:
    """Each pair in its own ngspice process, two at a time (the machine's cores)."""
    with ThreadPoolExecutor(2) as pool:
        list(pool.map(lambda ab: adder_sum(tmp_path, *ab, *extra), pairs))


@pytest.mark.parametrize("a,b", [(0, 0), (3, 2), (2, 3)])
def test_carrier_adder_prints_its_sum(tmp_path, a, b):
    adder_sum(tmp_path, a, b, "--periods", str(CARRIER_PERIODS))


@pytest.mark.slow          # 163 s measured (two ngspice at a time, loaded 2-core machine); the envelope form below
def test_carrier_adder_all_16_inputs(tmp_path):     # runs all 16 in the normal tier (10 s)
    all_pairs(tmp_path, [(a, b) for a in range(4) for b in range(4)], "--periods", str(CARRIER_PERIODS))


def test_envelope_adder_all_16_inputs(tmp_path):
    all_pairs(tmp_path, [(a, b) for a in range(4) for b in range(4)], "--format", "ngspice-envelope")


def test_carrier_reading_is_the_python_decode(tmp_path):
    """The printed amplitudes are the ones `simulate --backend ngspice` decodes (same run length)."""
    import mech2spice as m2s
    bits, _ = adder_sum(tmp_path, 1, 1, "--periods", str(CARRIER_PERIODS))
    res = m2s.simulate(ADDER, {"a": 1, "b": 1}, backend="ngspice", periods=CARRIER_PERIODS)
    for bit, amp in res["amplitudes"].items():
        assert abs(bits[bit][0] - amp) < 2e-5, (bit, bits[bit][0], amp)     # echo prints 6 digits


def test_unsettled_run_prints_invalid(tmp_path):
    """Five periods from rest: the outputs are nowhere near a band, and the port says so."""
    bits, ports = reading(ngspice(emit(tmp_path, ADDER, {"a": 1, "b": 2}, "--periods", "5"), valid=False))
    check_bands(bits)
    assert any(v == "invalid" for _, v in bits.values()) and ports == {"s": None}


def test_signed_and_multidigit_ports(tmp_path):
    """Two's complement for a signed port; a two-digit value printed digit by digit."""
    src = tmp_path / "sw.v"
    src.write_text("module sw(input [1:0] a, output signed [1:0] n, output [4:0] w);\n"
                   "  assign n = -a;\n  assign w = {a, 3'b101};\nendmodule\n")
    for a in (1, 3):
        _, ports = reading(ngspice(emit(tmp_path, src, {"a": a}, "--format", "ngspice-envelope")))
        assert ports == {"n": (-a + 2) % 4 - 2, "w": a * 8 + 5}


def test_header_maps_nodes_to_port_bits(tmp_path):
    text = emit(tmp_path, ADDER, {"a": 2, "b": 1}, "--periods", "5").read_text()
    head = text.split("* DOF -> displacement node:")[0]
    assert "inputs a=2, b=1" in head and "u_R = 0.0182" in head and "'1' 0.92..1.025 u_R" in head
    mapped = dict(re.findall(r"^\*   v\((\w+)\) -> (s\[\d\])$", head, re.M))
    assert sorted(mapped.values()) == ["s[0]", "s[1]", "s[2]"]
    saved = re.search(r"^\.save (.*)$", text, re.M).group(1)
    assert all(f"v({n})" in saved for n in mapped)
    assert "\n.four" not in text        # a .four line would make batch mode run the circuit a second time


def test_emit_json_keeps_its_fields(tmp_path, capsys):
    out = tmp_path / "j.cir"
    assert cli.main(["emit", ADDER, "--set", "a=1", "-o", str(out), "--periods", "5", "--json"]) == 0
    info = json.loads(capsys.readouterr().out)
    assert set(info) == {"netlist", "format", "periods", "oscillators", "probes", "options"}
    assert info["probes"] == ["s[0]", "s[1]", "s[2]"] and info["periods"] == 5


@pytest.mark.parametrize("form", ["vacask", "vacask-envelope"])
def test_vacask_header_maps_nodes_and_says_what_it_cannot(tmp_path, form):
    text = emit(tmp_path, ADDER, {"a": 1, "b": 1}, "--format", form, "--periods", "5").read_text()
    head = text.split("// DOF -> nodes:")[0]
    nodes = r"v\((\w+)\) v\((\w+)\)" if form.endswith("envelope") else r"v\((\w+)\)"
    mapped = re.findall(rf"^//   {nodes} -> (s\[\d\])$", head, re.M)
    assert [m[-1] for m in mapped] == ["s[0]", "s[1]", "s[2]"]
    assert "VACASK cannot decode by itself" in head and "u_R = 0.0182" in head


def test_cpu_emit_header_maps_port_bits():
    from mech2spice.cpu.circuit import emit_cpu
    text = emit_cpu([0] * 4, 1).text
    head = text.split("// DOF -> nodes:")[0]
    assert re.search(r"^//   v\(ar_\w+\) v\(ai_\w+\) -> raddr\[0\]$", head, re.M) and "bands: '0' 0.365" in head
