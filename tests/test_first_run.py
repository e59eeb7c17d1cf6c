"""First-run frictions (issue #26): --version, the preset list, a changed parameter set's name, a Monte-Carlo
sweep where every sample fails, progress on a redirected stderr, and `make setup` waiting for apt's lock."""
import json
import os
import re
import subprocess
import warnings
from dataclasses import replace
from pathlib import Path

import pytest

import mech2spice as m2s
from mech2spice.cli import main
from mech2spice.experiments import montecarlo as mc

REPO = Path(__file__).resolve().parent.parent


def test_version_prints_and_exits_0(capsys):
    assert main(["--version"]) == 0
    out = capsys.readouterr().out
    assert re.fullmatch(r"mech2spice \d+\.\d+\.\d+\S*\n", out)


def test_the_package_version_is_the_distribution_version():
    """`--version` falls back to __version__ in a source tree: both must name the same release."""
    text = (REPO / "pyproject.toml").read_text()
    assert re.search(r'^version = "([^"]+)"', text, re.M).group(1) == m2s.__version__


def test_presets_list_every_name_params_takes():
    assert list(m2s.PRESETS) == ["default", "printed", "robust", "classic", "centered", "centered_fc", "centered2",
                                 "centered_fc2"]
    for name in m2s.PRESETS:
        p = m2s.load_params(name)
        assert p.name == name and m2s.PRESETS[name] == p
    assert "robust" in m2s.PRESETS and "nope" not in m2s.PRESETS and len(m2s.PRESETS) == 8
    with pytest.raises(KeyError):
        m2s.PRESETS["nope"]


def test_a_changed_parameter_set_does_not_call_itself_default():
    assert m2s.GateParams().name == "default" == m2s.DEFAULT.name
    assert m2s.GateParams(q_g=150.0).name == "custom"
    assert replace(m2s.DEFAULT, omega=50.0).name == "custom"
    assert m2s.GateParams(q_g=150.0, name="mine").name == "mine"
    assert m2s.GateParams(q_g=200.0).name == "default"          # the default value is the default set
    assert m2s.PRINTED.name == "printed"
    assert m2s.GateParams(**m2s.DEFAULT.to_dict()) == m2s.DEFAULT


# --- montecarlo: every sample fails -----------------------------------------------------------------
def _rec(i, margin, ok=False, reason=None):
    return {"i": i, "pass": ok, "margin": margin, **({"reason": reason} if reason else {})}


def test_summary_quantiles_skip_diverged_samples_without_warnings():
    recs = [_rec(0, -float("inf"), reason="diverged"), _rec(1, -0.4), _rec(2, 0.2, ok=True), _rec(3, -0.1)]
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        res = mc.summary(recs, 3)
        none = mc.summary([_rec(i, -float("inf"), reason="diverged") for i in range(3)], 3)
    assert res["margin_samples"] == 3 and res["margin_quantiles"]["1%"] == pytest.approx(-0.394)
    assert res["margin_quantiles"]["99%"] == pytest.approx(0.194)
    assert none["margin_samples"] == 0 and none["margin_quantiles"] == {} and none["reasons"] == {"diverged": 3}
    judged = [{**r, "failing_gates": ["g1"] * (r["i"] == 1)} for r in recs if "reason" not in r]
    res = mc.summary([recs[0], *judged], 3)
    assert res["gate_samples"] == 3 and res["gate_failure_rate"] == pytest.approx(1 / 9)
    assert none["gate_failure_rate"] is None and none["gate_samples"] == 0


def test_montecarlo_where_every_sample_diverges(tmp_path, capfd):
    """Damping so low that every sample's channel goes negative: every sample fails before it has a margin.
    The quantiles were null (NaN from -inf) with numpy's RuntimeWarning on stderr."""
    params = tmp_path / "unstable.json"
    params.write_text(json.dumps({"q_c": 1e6, "gamma_ic": 1e6}))
    argv = ["montecarlo", str(REPO / "verilog/adder2.v"), "--samples", "2", "--spread", "0.01", "--set", "a=1",
            "--scheduler", "inline", "--params", str(params)]
    assert main(argv + ["--json"]) == 1
    out, err = capfd.readouterr()
    res = json.loads(out)
    assert res["failures"] == 2 and res["margin_quantiles"] == {} and res["margin_samples"] == 0
    # no gate was judged: the rate is unknown, not 0 (it read 0.0 beside a yield of 0; hostile-input pass)
    assert res["gate_failure_rate"] is None and res["gate_samples"] == 0
    assert "Warning" not in err and err == ""
    assert main(argv) == 1
    out, err = capfd.readouterr()
    assert "margin quantiles: none (every sample diverged or did not run)" in out
    assert "2 samples stopped early: 1 x DOF 'g0.C': total damping" in out
    assert "Warning" not in err


# --- progress on a redirected stderr -----------------------------------------------------------------
def test_redirected_stderr_gets_timestamped_progress_lines(capsys, monkeypatch):
    """Without a terminal there is no bar (it was simply off): a line every PROGRESS_EVERY_S instead, so a long
    step in a log file shows it moves.  The interval is 0 here, so every cycle gives one."""
    from mech2spice.backends import _base
    monkeypatch.setattr(_base, "PROGRESS_EVERY_S", 0.0)
    sieve = str(REPO / "programs/sieve.asm")
    assert main(["cpu", "run", sieve, "--backend", "logic", "--max-cycles", "30"]) == 1
    lines = capsys.readouterr().err.splitlines()
    assert len(lines) == 30 and lines[-1].endswith("] 30/30 cycles (100%), at most 0 s to go")
    assert all(re.fullmatch(r"\[ *\d+\.\ds\] \d+/30 cycles \(\d+%\)(, at most \d+ s to go)?", x) for x in lines)
    assert main(["cpu", "run", sieve, "--backend", "logic", "--max-cycles", "30", "--json"]) == 1
    assert capsys.readouterr().err == ""


def test_progress_lines_count_from_a_resumed_start(monkeypatch):
    from mech2spice.backends import _base
    monkeypatch.setattr(_base, "PROGRESS_EVERY_S", 0.0)
    got = []
    bar = _base.progress_bar(10, got.append, unit="sample", initial=6)
    bar.update(2)
    bar.close()
    assert got == [got[0]] and got[0].startswith("8/10 samples (80%)")


# --- make setup: apt waits for another apt --------------------------------------------------------------
FAKE_APT = """#!/bin/sh
# apt-get as another apt leaves it: `update` finds the lists' lock held until the third try
echo "$*" >> "$CALLS"
case "$*" in *" update")
    n=$(grep -c " update" "$CALLS")
    if [ "$n" -lt 3 ]; then
        echo "E: Could not get lock $FAIL. It is held by process 99 (apt-get)" >&2
        echo "E: Unable to lock directory /var/lib/apt/lists/" >&2
        exit 100
    fi;;
esac
"""


def _fake_apt(tmp_path, fail: str) -> dict:
    bin_ = tmp_path / "bin"
    bin_.mkdir()
    for name, text in (("apt-get", FAKE_APT), ("sleep", "#!/bin/sh\n")):
        (bin_ / name).write_text(text)
        (bin_ / name).chmod(0o755)
    return {**os.environ, "PATH": f"{bin_}:{os.environ['PATH']}", "CALLS": str(tmp_path / "calls"), "FAIL": fail}


def test_setup_apt_waits_for_the_package_lists_lock(tmp_path):
    """`apt-get update` failed at once when another apt held /var/lib/apt/lists/lock (DPkg::Lock::Timeout does
    not cover it): it is retried; install waits for the dpkg lock itself (DPkg::Lock::Timeout)."""
    env = _fake_apt(tmp_path, "/var/lib/apt/lists/lock")
    r = subprocess.run(["sh", str(REPO / "scripts/apt_install.sh"), "ngspice", "libngspice0"], env=env,
                       capture_output=True, text=True, timeout=60)
    assert r.returncode == 0, r.stderr
    calls = (tmp_path / "calls").read_text().splitlines()
    assert calls == ["-q -o DPkg::Lock::Timeout=600 update"] * 3 + \
        ["-q -o DPkg::Lock::Timeout=600 install -y ngspice libngspice0"]
    assert r.stdout.count("Could not get lock /var/lib/apt/lists/lock. It is held by process 99 (apt-get); waiting") == 2


def test_setup_apt_gives_up_at_once_on_other_failures(tmp_path):
    env = _fake_apt(tmp_path, "unused")
    (tmp_path / "bin" / "apt-get").write_text("#!/bin/sh\necho \"$*\" >> \"$CALLS\"\n"
                                             "echo 'E: Failed to fetch http://deb.debian.org' >&2\nexit 100\n")
    r = subprocess.run(["sh", str(REPO / "scripts/apt_install.sh"), "ngspice"], env=env, capture_output=True,
                       text=True, timeout=60)
    assert r.returncode == 1 and "Failed to fetch" in r.stderr
    assert len((tmp_path / "calls").read_text().splitlines()) == 1


def test_make_setup_uses_the_waiting_install():
    text = (REPO / "Makefile").read_text()
    assert "|| sh scripts/apt_install.sh ngspice libngspice0" in text and "apt-get update -qq" not in text
