"""The floor plan: the parts are folders, the imports run one way, nothing cycles, and no
numba kernel takes more than :data:`MAX_KERNEL_PARAMETERS` parameters.

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


#: The most parameters a numba kernel may take (issue 41): arrays that travel together go as
#: one record (a named tuple or a tuple, grouped by meaning: the mesh, the front, the heap).
MAX_KERNEL_PARAMETERS = 12
#: Kernels allowed over it, as "path:name" -> why; it can only shrink. Empty: at this commit
#: no kernel of terrainvis/ or simplifiers/ is over it.
KERNELS_ALLOWED_WIDE: dict[str, str] = {}
_JIT = {"njit", "jit", "nb.njit", "nb.jit", "numba.njit", "numba.jit", "kernel_of"}


def _is_jit(node: ast.expr) -> bool:
    """True for ``njit``, ``nb.njit(...)``, ``numba.jit`` and the like."""
    target = node.func if isinstance(node, ast.Call) else node
    return ast.unparse(target) in _JIT


def _kernel_parameters(source: str) -> dict[str, int]:
    """Name -> parameters of every function compiled by numba in ``source``: decorated
    (``@nb.njit(...)``) or wrapped (``nb.njit(**options)(fn)``)."""
    tree = ast.parse(source)
    defs = {n.name: n for n in ast.walk(tree) if isinstance(n, (ast.FunctionDef, ast.AsyncFunctionDef))}
    kernels = {name for name, fn in defs.items() if any(_is_jit(d) for d in fn.decorator_list)}
    for node in ast.walk(tree):
        if isinstance(node, ast.Call) and isinstance(node.func, ast.Call) and _is_jit(node.func):
            kernels |= {a.id for a in node.args if isinstance(a, ast.Name) and a.id in defs}
    out = {}
    for name in kernels:
        a = defs[name].args
        out[name] = (len(a.posonlyargs) + len(a.args) + len(a.kwonlyargs) + (a.vararg is not None)
                     + (a.kwarg is not None))
    return out


def test_kernel_parameter_count_on_a_hand_made_module():
    many = ", ".join(f"a{i}" for i in range(MAX_KERNEL_PARAMETERS + 1))
    source = (
        f"@nb.njit(cache=True, nogil=True)\ndef k1({many}):\n    pass\n\n"
        f"@numba.jit\ndef k2(a, *, b):\n    pass\n\n"
        f"def _k3({many}, *rest):\n    pass\n\n"
        f"k3 = nb.njit(**_OPTIONS)(_k3)\n\n"
        f"def plain({many}):\n    pass\n"
    )
    assert _kernel_parameters(source) == {
        "k1": MAX_KERNEL_PARAMETERS + 1, "k2": 2, "_k3": MAX_KERNEL_PARAMETERS + 2,
    }


def _wide_kernels() -> dict[str, int]:
    wide = {}
    for path in MODULES.values():
        for name, n in _kernel_parameters(path.read_text(encoding="utf-8")).items():
            if n > MAX_KERNEL_PARAMETERS:
                wide[f"{path.relative_to(REPO).as_posix()}:{name}"] = n
    return wide


def test_no_kernel_takes_more_than_twelve_parameters():
    wide = [f"{k} takes {n}" for k, n in _wide_kernels().items() if k not in KERNELS_ALLOWED_WIDE]
    assert not wide, (f"numba kernels over {MAX_KERNEL_PARAMETERS} parameters (pass the arrays that travel "
                      "together as one record):\n" + "\n".join(sorted(wide)))


def test_wide_kernel_allow_list_only_shrinks():
    stale = sorted(set(KERNELS_ALLOWED_WIDE) - set(_wide_kernels()))
    assert not stale, f"allow-list entries no longer needed (remove them): {stale}"
