"""The VCD writer (mech2spice/waveform.py): what it writes is read back equal, by its own reader and by an
independent one (vcdvcd), in the standard form viewers read ($timescale, a scope per module, vectors)."""
from __future__ import annotations

import pytest

from mech2spice.errors import Mech2SpiceError
from mech2spice.waveform import Waveform, bits_string, is_vcd, read_vcd, vcd_text, wire_value, write_vcd

vcdvcd = pytest.importorskip("vcdvcd")

TIMES = [0, 1, 2, 3]
Q_BITS = [[0, 1, 0, 0], [0, 1, 0, 0], [None, 1, 1, 0], [1, 1, 1, 1]]     # least significant first
AMPS = [0.1, 0.1, 0.9, 1.25]


def _wave() -> Waveform:
    w = Waveform(list(TIMES), comment="one timestep per clock cycle")
    w.add_bits(["top", "outputs"], "q", Q_BITS)
    w.add_wire(["top", "inputs"], "en", 1, [1, 1, 0, 0])
    w.add_wire(["top", "inputs"], "d", 8, [5, None, -1, "0000x001"])
    w.add_real(["top", "amplitudes"], "q[0]", AMPS)
    return w


def test_bits_and_values_are_written_msb_first_with_x_for_invalid():
    assert bits_string([1, 0, None, 1]) == "1x01"
    assert wire_value(5, 4) == "0101" and wire_value(-1, 3) == "111" and wire_value(None, 2) == "xx"
    assert wire_value("01z", 3) == "01z"             # Icarus's undriven bits (verify --vcd's source side)
    with pytest.raises(Mech2SpiceError):
        wire_value("01q", 3)


def test_round_trip_through_its_own_reader(tmp_path):
    path = tmp_path / "w.vcd"
    write_vcd(path, _wave())
    back = read_vcd(path, TIMES)
    want = _wave()
    assert {s.path(): (s.width, s.values) for s in back.signals} == \
           {s.path(): (s.width, s.values) for s in want.signals}
    assert back.signal("top.outputs.q").values == ("0010", "0010", "011x", "1111")


def test_an_independent_reader_sees_the_same_values(tmp_path):
    path = tmp_path / "w.vcd"
    write_vcd(path, _wave())
    v = vcdvcd.VCDVCD(str(path))
    assert set(v.signals) == {"top.outputs.q[3:0]", "top.inputs.en", "top.inputs.d[7:0]", "top.amplitudes.q[0]"}
    q, amp = v["top.outputs.q[3:0]"], v["top.amplitudes.q[0]"]
    assert [q[t] for t in TIMES] == ["0010", "0010", "011x", "1111"]
    assert [float(amp[t]) for t in TIMES] == AMPS
    assert [v["top.inputs.d[7:0]"][t] for t in TIMES] == ["00000101", "xxxxxxxx", "11111111", "0000x001"]


def test_the_file_is_standard_vcd(tmp_path):
    text = vcd_text(_wave())
    assert "$timescale 1 ns $end" in text and "$scope module top $end" in text
    assert "$var wire 4 " in text and " q[3:0] $end" in text and "$var real 64 " in text
    assert "$comment one timestep per clock cycle $end" in text
    path = tmp_path / "w.vcd"
    write_vcd(path, _wave())
    assert is_vcd(path)
    (tmp_path / "x.json").write_text("{}")
    assert not is_vcd(tmp_path / "x.json")


@pytest.mark.parametrize("name", ["has space", "a.b", "", "tab\there", "nl\n"])
def test_names_that_would_break_the_format_are_refused(name):
    w = Waveform([0])
    w.add_wire(["top"], name, 1, [0])
    with pytest.raises(Mech2SpiceError):
        vcd_text(w)


def test_inconsistent_waveforms_are_refused():
    w = Waveform([0, 1])
    w.add_wire(["top"], "a", 1, [0])
    with pytest.raises(Mech2SpiceError, match="1 values for 2 timesteps"):
        vcd_text(w)
    with pytest.raises(Mech2SpiceError, match="increasing"):
        vcd_text(Waveform([1, 1]))
    with pytest.raises(Mech2SpiceError, match="not finite"):
        Waveform([0]).add_real(["top"], "a", [float("nan")])
