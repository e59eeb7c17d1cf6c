"""No import circles among mech2spice's modules, and the lower layers import nothing above them (issue #28;
docs/architecture.md, "Import order").

Every `import` counts, at module level or inside a function: a function-level import that closes a circle
still ties the two modules together (each needs the other to work) and hides the dependency.  The graph is
built from the source with `ast`, so no module is imported to check it."""
from __future__ import annotations

import ast
from pathlib import Path

import networkx as nx

PACKAGE = Path(__file__).resolve().parent.parent / "mech2spice"

ALLOWED: list[set[str]] = []     # every circle of #28 is gone: none may come back


def module_names(root: Path) -> dict[str, Path]:
    """Every module of the package under `root`, by dotted name relative to it ('' for the top __init__)."""
    out = {}
    for path in root.rglob("*.py"):
        parts = list(path.relative_to(root).with_suffix("").parts)
        if parts[-1] == "__init__":
            parts.pop()
        out[".".join(parts)] = path
    return out


def _package_of(name: str, path: Path) -> list[str]:
    """The package a module's relative imports start from."""
    parts = name.split(".") if name else []
    return parts if path.name == "__init__.py" else parts[:-1]


def _targets(node, name: str, path: Path, top: str, modules) -> list[str]:
    """The package's modules (dotted, relative to it) one import statement imports: `from P import x` names
    the submodule P.x where there is one, else P itself."""
    if isinstance(node, ast.Import):
        return [a.name[len(top) + 1:] if a.name != top else "" for a in node.names
                if a.name == top or a.name.startswith(top + ".")]
    if node.level:
        base = _package_of(name, path)[:len(_package_of(name, path)) - node.level + 1]
    elif node.module == top or (node.module or "").startswith(top + "."):
        base = []
    else:
        return []
    mod_parts = (node.module or "").split(".") if node.module else []
    if not node.level:
        mod_parts = mod_parts[1:]             # drop the package's own name
    mod = ".".join(base + mod_parts)
    subs = [f"{mod}.{a.name}" if mod else a.name for a in node.names]
    return [s if s in modules else mod for s in subs]


def import_graph(root: Path) -> nx.DiGraph:
    """Module -> the package's modules it imports (anywhere in its source)."""
    modules = module_names(root)
    g = nx.DiGraph()
    g.add_nodes_from(modules)
    for name, path in modules.items():
        for node in ast.walk(ast.parse(path.read_text(), str(path))):
            if isinstance(node, (ast.Import, ast.ImportFrom)):
                for target in _targets(node, name, path, root.name, modules):
                    if target in modules and target != name:
                        g.add_edge(name, target)
    return g


def circles(g: nx.DiGraph) -> list[set[str]]:
    """The groups of modules that import each other, directly or through others."""
    return [set(c) for c in nx.strongly_connected_components(g) if len(c) > 1]


def _describe(g: nx.DiGraph, group: set[str]) -> str:
    cycle = next(nx.simple_cycles(g.subgraph(group)))
    return " -> ".join(cycle + cycle[:1])


def test_no_import_circles_beyond_the_allowed_ones():
    g = import_graph(PACKAGE)
    # the graph sees the package's relative, lazy and `from pkg import module` imports
    assert {("simulation", "experiments.clocking"), ("experiments.clocking", "experiments.characterise"),
            ("spice.memory", "spice.openvaf")} <= set(g.edges)
    new = [c for c in circles(g) if not any(c <= allowed for allowed in ALLOWED)]
    assert not new, "import circles: " + "; ".join(_describe(g, c) for c in new)


def unresolved(root: Path) -> list[str]:
    """Relative imports whose module is not in the package (a module moved without its importers)."""
    modules, bad = module_names(root), []
    for name, path in modules.items():
        for node in ast.walk(ast.parse(path.read_text(), str(path))):
            if isinstance(node, ast.ImportFrom) and node.level:
                package = _package_of(name, path)
                base = package[:len(package) - node.level + 1]
                mod = ".".join(base + (node.module.split(".") if node.module else []))
                if mod not in modules:
                    bad.append(f"{path.relative_to(root.parent)}:{node.lineno}: {'.' * node.level}{node.module or ''}")
    return bad


def test_every_relative_import_names_a_module_of_the_package():
    assert unresolved(PACKAGE) == []


def _write(root: Path, files: dict[str, str]) -> None:
    for rel, text in files.items():
        (root / rel).parent.mkdir(parents=True, exist_ok=True)
        (root / rel).write_text(text)


def test_the_graph_sees_function_level_and_relative_circles(tmp_path):
    pkg = tmp_path / "pkg"
    _write(pkg, {"__init__.py": "", "a.py": "from .sub import b\n", "sub/__init__.py": "",
                 "sub/b.py": "def f():\n    from ..a import g\n", "c.py": "import pkg.sub.b\nimport os\n",
                 "d.py": "from . import c\nfrom .sub import f\n"})
    g = import_graph(pkg)
    assert circles(g) == [{"a", "sub.b"}]
    assert unresolved(pkg) == []
    (pkg / "sub" / "e.py").write_text("def f():\n    from .._gone import x\n")
    assert unresolved(pkg) == ["pkg/sub/e.py:2: .._gone"]
    assert set(g.edges) == {("a", "sub.b"), ("sub.b", "a"), ("c", "sub.b"), ("d", "c"), ("d", "sub")}


def test_lower_layers_import_nothing_above_them():
    above = ("backends", "experiments", "simulation", "spice")
    for name, target in import_graph(PACKAGE).edges:
        if name.startswith("physics."):
            assert not target.startswith(above), (name, target)
        if name.startswith("spice."):
            assert not target.startswith("backends"), (name, target)
        if name == "simulation" and target.startswith("experiments."):
            assert target == "experiments.clocking", target


# A private module (name starting with _) is its package's own: another package reaches it only through the
# package's public names.  The exceptions measure an engine's insides, which no public name exposes: two
# studies time the compiled kernels themselves, and the noise check compares the noisy envelope's own
# integrator (its step and batch) with linear response.
PRIVATE_ALLOWED = {("studies.speed_accuracy", "backends._envelope_kernel"),
                   ("studies.speed_accuracy", "backends._rk4_kernel"),
                   ("studies.performance", "backends._rk4_kernel"),
                   ("experiments.noise_agreement", "backends._noise_envelope")}


def _private_imports(g: nx.DiGraph) -> set[tuple[str, str]]:
    def package(m: str) -> str:
        return m.rsplit(".", 1)[0] if "." in m else ""
    return {(a, b) for a, b in g.edges
            if b.rsplit(".", 1)[-1].startswith("_") and package(b) and not (a + ".").startswith(package(b) + ".")}


def test_no_module_imports_another_packages_private_module():
    found = _private_imports(import_graph(PACKAGE)) - PRIVATE_ALLOWED
    assert not found, sorted(found)
