"""The package's imports go one way (docs/architecture.md, "Import order"): no circles, lazy imports included,
and the lower layers import nothing above them (issue #28)."""
import ast
from pathlib import Path

import networkx as nx

ROOT = Path(__file__).resolve().parents[1]

# circles other parts of #28 are breaking (the CLI package, measurement out of reports/, inputs vs params);
# a circle may shrink or vanish, never grow or appear elsewhere
KNOWN = [{"mech2spice.inputs", "mech2spice.physics.blocks", "mech2spice.physics.params"},
         {"mech2spice.cli", "mech2spice.cpu.cli", "mech2spice.design.cli", "mech2spice.experiments.mc_cli",
          "mech2spice.verify"},
         {"mech2spice.reports.carrier", "mech2spice.reports.speed_accuracy", "mech2spice.reports.vacask"}]


def module_name(path: Path) -> str:
    parts = list(path.relative_to(ROOT).with_suffix("").parts)
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def imported(node, name: str, is_package: bool, modules: set[str]) -> list[str]:
    """The package modules one import statement loads (`from pkg import mod` names the module, not pkg)."""
    if isinstance(node, ast.Import):
        return [a.name for a in node.names]
    if node.level:
        base = name.split(".") if is_package else name.split(".")[:-1]
        base = base[:len(base) - node.level + 1]
        source = ".".join(base + ([node.module] if node.module else []))
    else:
        source = node.module or ""
    subs = [f"{source}.{a.name}" for a in node.names if f"{source}.{a.name}" in modules]
    return subs if len(subs) == len(node.names) else [source, *subs]


def import_graph() -> nx.DiGraph:
    paths = {module_name(p): p for p in (ROOT / "mech2spice").rglob("*.py")}
    graph = nx.DiGraph()
    for name, path in paths.items():
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, (ast.Import, ast.ImportFrom)):
                for target in imported(node, name, path.name == "__init__.py", set(paths)):
                    if target in paths and target != name:
                        graph.add_edge(name, target)
    return graph


def test_no_new_import_circles():
    graph = import_graph()
    # the graph sees relative, lazy and `from pkg import module` imports
    assert {("mech2spice.simulation", "mech2spice.experiments.clocking"),
            ("mech2spice.experiments.clocking", "mech2spice.experiments.characterise"),
            ("mech2spice.spice.memory", "mech2spice.spice.openvaf")} <= set(graph.edges)
    circles = [c for c in nx.strongly_connected_components(graph) if len(c) > 1]
    for circle in circles:
        assert any(circle <= known for known in KNOWN), sorted(circle)


def test_lower_layers_import_nothing_above_them():
    graph = import_graph()
    above = ("mech2spice.backends", "mech2spice.experiments", "mech2spice.simulation", "mech2spice.spice")
    for name, target in graph.edges:
        if name.startswith("mech2spice.physics."):
            assert not target.startswith(above), (name, target)
        if name.startswith("mech2spice.spice."):
            assert not target.startswith("mech2spice.backends"), (name, target)
        if name == "mech2spice.simulation" and target.startswith("mech2spice.experiments."):
            assert target == "mech2spice.experiments.clocking", target
