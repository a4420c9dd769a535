"""The floor plan: the parts are folders, the imports run one way, and nothing cycles.

Read from the source (``ast``), every import counted, those inside functions too: a lazy
import that ran back up a layer would still tie a lower part to a higher one.
"""

from __future__ import annotations

import ast
from pathlib import Path

REPO = Path(__file__).resolve().parents[2]

#: The layers, lowest first: a module may import from its own layer and the ones below it.
LAYERS = (
    ("terrainvis.errors", "terrainvis.tolerances"),
    ("terrainvis.core",),
    ("terrainvis.io",),
    ("terrainvis.visibility",),
    ("terrainvis.relocation",),
    ("simplifiers",),
    ("terrainvis.tiles",),
    ("terrainvis.experiment",),
    ("terrainvis.cli", "terrainvis.__main__", "terrainvis.testing"),
)
#: The folders the parts live in (and the top-level modules beside them).
PARTS = {"core", "io", "visibility", "relocation", "tiles", "experiment", "cli", "data"}
TOP_LEVEL = {"__init__.py", "__main__.py", "errors.py", "tolerances.py", "testing.py"}


def _files():
    for pkg in ("terrainvis", "simplifiers"):
        for p in sorted((REPO / pkg).rglob("*.py")):
            if "data" not in p.relative_to(REPO).parts:
                yield p


def _module(path: Path) -> tuple[str, str]:
    """The module's dotted name and the package its relative imports start from."""
    parts = list(path.relative_to(REPO).with_suffix("").parts)
    if parts[-1] == "__init__":
        name = ".".join(parts[:-1])
        return name, name
    name = ".".join(parts)
    return name, name.rpartition(".")[0]


MODULES = {_module(p)[0]: p for p in _files()}


def _imports(path: Path) -> list[tuple[str, int]]:
    """Every terrainvis or simplifiers module (or name's module) ``path`` imports, with the line."""
    _, base = _module(path)
    out = []
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
        if isinstance(node, ast.ImportFrom):
            if node.level:
                parts = base.split(".")
                parts = parts[: len(parts) - (node.level - 1)]
                full = ".".join(parts + ([node.module] if node.module else []))
            else:
                full = node.module or ""
            for a in node.names:
                sub = f"{full}.{a.name}"
                out.append((sub if sub in MODULES else full, node.lineno))
        elif isinstance(node, ast.Import):
            out += [(a.name, node.lineno) for a in node.names]
    return [(m, line) for m, line in out if m.split(".")[0] in ("terrainvis", "simplifiers")]


def _layer(module: str) -> int:
    found = [i for i, prefixes in enumerate(LAYERS) for p in prefixes if module == p or module.startswith(p + ".")]
    if module == "terrainvis":
        return -1  # the package's own __init__: the lazy API, importing nothing at import time
    assert found, f"{module} belongs to no layer of tests/whole/test_layout.py: add it there and to docs/architecture.md"
    return max(found)


def test_the_parts_are_folders():
    """terrainvis holds its parts as folders and only the shared leaf modules beside them."""
    top = REPO / "terrainvis"
    files = {p.name for p in top.iterdir() if p.suffix == ".py"}
    folders = {p.name for p in top.iterdir() if p.is_dir() and not p.name.startswith((".", "__"))}
    assert files == TOP_LEVEL
    assert folders == PARTS


def test_no_import_runs_back_up_a_layer():
    upward = []
    for name, path in MODULES.items():
        mine = _layer(name)
        for target, line in _imports(path):
            if _layer(target) > mine:
                upward.append(f"{path.relative_to(REPO)}:{line} imports {target}")
    assert not upward, "imports that run back up a layer:\n" + "\n".join(upward)


def test_no_import_cycle():
    graph = {name: {t for t, _ in _imports(path) if t in MODULES and t != name} for name, path in MODULES.items()}
    state: dict[str, str] = {}

    def visit(m, trail):
        if state.get(m) == "done":
            return
        assert state.get(m) != "open", "import cycle: " + " -> ".join(trail + [m])
        state[m] = "open"
        for dep in sorted(graph[m]):
            visit(dep, trail + [m])
        state[m] = "done"

    for m in sorted(graph):
        visit(m, [])
