"""The in-process command line as the bad-input tests drive it: one command's (exit code, stdout, stderr),
and the refusal every bad input must get (exit 2, one line on stderr, no traceback)."""
from mech2spice.cli import main


def run(capsys, *argv):
    """(exit code, stdout, stderr) of one in-process command."""
    rc = main([str(a) for a in argv])
    out, err = capsys.readouterr()
    return rc, out, err


def refused(capsys, *argv, needle: str) -> str:
    """Assert the command exits 2 with one line on stderr containing `needle`; returns that line."""
    rc, out, err = run(capsys, *argv)
    assert rc == 2, (rc, out, err[-3000:])
    assert err.count("\n") == 1 and "Traceback" not in err, err
    assert needle in err, err
    return err


def verilog(tmp_path, text: str, name: str = "d.v") -> str:
    """A Verilog file with `text` in tmp_path; its path."""
    path = tmp_path / name
    path.write_text(text)
    return str(path)
