"""What a program computes is shown (`.result`), and every machine runs in lockstep with the ISS (`iss_check`)."""
import json

import pytest

from mech2spice.cpu import asm
from mech2spice.cpu.run import run_program
from mech2spice.errors import Mech2SpiceError

from cli_helpers import run

PRIMES_BELOW_32 = [2, 3, 5, 7, 11, 13, 17, 19, 23, 29, 31]


def test_the_sieve_shows_its_primes_on_the_logic_netlist(capsys):
    code, out, _ = run(capsys, "cpu", "run", "programs/sieve.asm", "--backend", "logic", "--json")
    res = json.loads(out)
    assert code == 0 and res["results"]["primes"] == PRIMES_BELOW_32
    assert res["iss_check"] == {"from_cycle": 0, "cycles_checked": 457, "mismatches": 0, "first_mismatch": None}
    code, text, _ = run(capsys, "cpu", "run", "programs/sieve.asm", "--backend", "logic")
    assert "primes: 2 3 5 7 11 13 17 19 23 29 31" in text and "every cycle equal" in text


def test_a_machine_that_departs_from_the_iss_is_caught(monkeypatch):
    from mech2spice.cpu import machines
    real = machines.make_cpu

    corrupted = []

    def faulty(*a, **k):                      # the logic netlist, with one memory read corrupted
        cpu = real(*a, **k)
        read = cpu.mem.read

        def bad_read(addr):
            if cpu.cycle == 20:
                corrupted.append(len(corrupted))
            return read(addr) ^ (1 if cpu.cycle == 20 else 0)
        cpu.mem.read = bad_read
        return cpu
    monkeypatch.setattr("mech2spice.cpu.run.make_cpu", faulty)
    res = run_program("programs/sieve.asm", "logic", max_cycles=40)
    chk = res["iss_check"]
    assert corrupted and chk["mismatches"] >= 1
    first = chk["first_mismatch"]
    assert first["machine"]["rdata"] == first["iss"]["rdata"] ^ 1     # the corrupted read, named as such


@pytest.mark.parametrize("line", [".result primes", ".result 1x zeros 0 4", ".result p odd 0 4",
                                  ".result p bytes 0 4 2"])
def test_bad_result_directives_are_refused(line):
    with pytest.raises(Mech2SpiceError, match=r"\.result"):
        asm.assemble_program(line + "\n")


def test_result_kinds():
    prog = asm.assemble_program(".result z zeros 4 4 10\n.result b bytes 4 2\n")
    mem = [0] * 256
    mem[5] = 7
    assert prog.read_results(mem) == {"z": [10, 12, 13], "b": [0, 7]}
