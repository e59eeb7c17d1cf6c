"""The README's Python API example runs as written (from the repository root, where its paths point)."""
import re
from pathlib import Path

REPO = Path(__file__).resolve().parent.parent


def test_readme_api_example_runs(monkeypatch, capsys):
    text = (REPO / "README.md").read_text()
    code = re.search(r"## The Python API\n\n```python\n(.*?)```", text, re.S).group(1)
    monkeypatch.chdir(REPO)
    scope = {}
    exec(compile(code, "README.md", "exec"), scope)
    assert scope["res"]["outputs"] == {"s": 5} and scope["res"]["valid"]
    assert "{'s': 5} True" in capsys.readouterr().out
    assert ".tran" in scope["netlist_text"] and "mech2spice: adder2 with a=3, b=2" in scope["netlist_text"]
