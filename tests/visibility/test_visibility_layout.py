"""The visibility package's shape: what it exports, no import cycle, no long argument lists."""

from __future__ import annotations

import ast
import inspect
from pathlib import Path

import pytest

import terrainvis
import terrainvis.visibility as vis

PACKAGE = Path(vis.__file__).parent
PUBLIC = ("min_clearance", "line_of_sight", "visibility_matrix", "viewshed", "lowest_point", "clearance_profile",
          "trim_length", "clearance_tolerance", "terrain_scale", "embree_tolerance", "ENGINES", "TRIM_REL", "TOL_REL")


def test_public_names_are_handed_on():
    for name in PUBLIC:
        assert hasattr(vis, name), name
    for name in ("min_clearance", "line_of_sight", "visibility_matrix", "viewshed"):
        assert getattr(terrainvis, name) is getattr(vis, name)
    # ``viewshed`` is the function, not a module
    assert callable(vis.viewshed) and not inspect.ismodule(vis.viewshed)


def test_the_package_init_only_hands_names_on():
    """No logic in the package's ``__init__``: its names, imported on first use by PEP 562's
    ``__getattr__`` (and listed by ``__dir__``), each the object its submodule defines."""
    import importlib

    tree = ast.parse((PACKAGE / "__init__.py").read_text())
    defined = [n.name for n in tree.body if isinstance(n, (ast.FunctionDef, ast.ClassDef))]
    assert sorted(defined) == ["__dir__", "__getattr__"]
    assert sorted(vis._API) == sorted(vis.__all__)
    for name, spec in vis._API.items():
        module, attr = spec if isinstance(spec, tuple) else (spec, name)
        assert getattr(vis, name) is getattr(importlib.import_module(f"terrainvis.visibility.{module}"), attr), name
    assert set(vis.__all__) <= set(dir(vis))
    with pytest.raises(AttributeError, match="no attribute 'nothing'"):
        vis.nothing
    # the function, though its module (in the viewsheds subpackage) has the same name
    assert callable(vis.field_of_view) and not inspect.ismodule(vis.field_of_view)


def _name(path: Path) -> str:
    """The dotted name of a module of the package (or of its subpackages), from the package:
    ``los``, ``viewsheds.sweep``, ``viewsheds`` for a subpackage's ``__init__``."""
    parts = list(path.relative_to(PACKAGE).with_suffix("").parts)
    if parts[-1] == "__init__":
        parts = parts[:-1] or ["__init__"]
    return ".".join(parts)


def _resolved(parts: list[str]) -> str:
    """``parts`` (from the package) as :func:`_name` names them when they are a module or a
    subpackage; otherwise a name its parent defines, which imports the parent's ``__init__``."""
    if PACKAGE.joinpath(*parts).with_suffix(".py").exists() or PACKAGE.joinpath(*parts).is_dir():
        return ".".join(parts)
    return ".".join(parts[:-1]) or "__init__"


def _module_imports(path: Path) -> set[str]:
    """Modules of the visibility package (and its subpackages) imported at module level by
    ``path``, by :func:`_name` (``from . import name`` of a name that is no module imports the
    package's ``__init__``)."""
    here = list(path.relative_to(PACKAGE).parent.parts)
    out = set()
    for node in ast.parse(path.read_text()).body:
        if not isinstance(node, ast.ImportFrom) or node.level == 0 or node.level > len(here) + 1:
            continue
        base = here[: len(here) - (node.level - 1)]
        if node.module:
            out.add(_resolved(base + node.module.split(".")))
        else:
            out.update(_resolved(base + [a.name]) for a in node.names)
    return out


def test_no_import_cycle_inside_the_package():
    mods = {_name(p): _module_imports(p) for p in PACKAGE.rglob("*.py")}
    assert "viewsheds.sweep" in mods and "viewsheds._sector_kernels" in mods["viewsheds.sweep"]
    state = {}

    def visit(m, path):
        if state.get(m) == "done":
            return
        assert state.get(m) != "open", f"import cycle: {' -> '.join(path + [m])}"
        state[m] = "open"
        for dep in sorted(mods.get(m, ())):
            if dep in mods:
                visit(dep, path + [m])
        state[m] = "done"

    for m in sorted(mods):
        visit(m, [])


def _functions():
    import importlib

    for p in sorted(PACKAGE.rglob("*.py")):
        name = _name(p)
        mod = importlib.import_module(f"terrainvis.visibility.{name}") if name != "__init__" else vis
        for name, obj in vars(mod).items():
            fn = getattr(obj, "py_func", obj)
            if inspect.isfunction(fn) and fn.__module__ == mod.__name__:
                yield f"{mod.__name__}.{name}", fn


@pytest.mark.parametrize("limit", [12])
def test_no_function_takes_more_than_a_dozen_positional_arguments(limit):
    long = []
    for name, fn in _functions():
        params = [p for p in inspect.signature(fn).parameters.values() if p.kind != p.KEYWORD_ONLY]
        if len(params) > limit:
            long.append(f"{name} ({len(params)})")
    assert not long, f"more than {limit} parameters (keyword-only options aside): {long}"
