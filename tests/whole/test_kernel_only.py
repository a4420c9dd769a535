"""Kernels that only kernels call (``**KERNEL_ONLY``) are never named by Python code.

numba builds no entry from Python for such a kernel (:data:`terrainvis.core.compiling.KERNEL_ONLY`:
no CPython or C wrapper, which saves their compilation on a first run), so a call from
Python would jump to no code and crash the interpreter. This test reads every Python file of
terrainvis, simplifiers, the tests, the benchmarks and the examples, and fails when code that
runs in Python (a module's statements, a plain function's body; not a kernel's body, not an
import, not the argument of :func:`terrainvis.core.compiling.from_python`) names one, through
the names its imports bind: such a kernel must lose ``**KERNEL_ONLY`` or the caller must go
through ``from_python``. A second test checks that what the modules compile agrees with what
the files say.
"""

from __future__ import annotations

import ast
import importlib
from pathlib import Path

import pytest

from terrainvis.core.compiling import KERNEL_ONLY

ROOT = Path(__file__).resolve().parents[2]
SOURCES = ("terrainvis", "simplifiers")
READERS = SOURCES + ("tests", "benchmarks", "examples", "docs")


def _is_kernel(fn: ast.FunctionDef) -> bool:
    for dec in fn.decorator_list:
        target = dec.func if isinstance(dec, ast.Call) else dec
        if ast.unparse(target).split(".")[-1] in ("njit", "jit", "register_jitable", "kernel_of"):
            return True
    return False


def _kernel_only(fn: ast.FunctionDef) -> bool:
    return any(isinstance(dec, ast.Call) and any(k.arg is None and ast.unparse(k.value) == "KERNEL_ONLY"
                                                   for k in dec.keywords)
               for dec in fn.decorator_list)


def _made_names(fn: ast.FunctionDef) -> list[str] | None:
    """The names a kernel written once for several kinds takes (the strings its
    ``@kernel_of(kind, "grid_x", "tin_x", ...)`` names), or None for a kernel of its own name."""
    for dec in fn.decorator_list:
        if isinstance(dec, ast.Call) and ast.unparse(dec.func).split(".")[-1] == "kernel_of":
            return [a.value for a in dec.args[1:] if isinstance(a, ast.Constant)]
    return None


def declared(source: str) -> set[str]:
    """The names of the kernels declared ``**KERNEL_ONLY`` in a module's source (a kernel made
    per kind by :func:`terrainvis.core.compiling.kernel_of`: every name it takes)."""
    out = set()
    for n in ast.walk(ast.parse(source)):
        if isinstance(n, ast.FunctionDef) and _kernel_only(n):
            made = _made_names(n)
            out.update([n.name] if made is None else made)
    return out


def _module_of(path: Path) -> str:
    rel = path.relative_to(ROOT).with_suffix("")
    parts = rel.parts[:-1] if rel.name == "__init__" else rel.parts
    return ".".join(parts)


def _absolute(node: ast.ImportFrom, module: str, is_package: bool) -> str:
    """The absolute name of what an ``from ... import`` reads (its relative dots resolved)."""
    if not node.level:
        return node.module or ""
    base = module.split(".")
    base = base[: len(base) - node.level + (1 if is_package else 0)]
    return ".".join(base + ([node.module] if node.module else []))


def kernel_names(source: str, module: str, kernels: dict[str, set[str]], is_package: bool = False):
    """What names a kernel-only kernel in a module: ``(names, modules)``, the names bound to
    one (its own kernels, those it imports; a name the module assigns again at its top level,
    as ``k = from_python(k)``, no longer does) and the names bound to a kernel module
    (``import a.b as m``, ``from a import b``), whose attributes of those names do."""
    tree = ast.parse(source)
    names = set(kernels.get(module, ()))
    modules = {}
    for node in ast.walk(tree):
        if isinstance(node, ast.ImportFrom):
            src = _absolute(node, module, is_package)
            for a in node.names:
                if a.name in kernels.get(src, ()):
                    names.add(a.asname or a.name)
                elif f"{src}.{a.name}" in kernels:
                    modules[a.asname or a.name] = f"{src}.{a.name}"
        elif isinstance(node, ast.Import):
            for a in node.names:
                if a.name in kernels and a.asname:
                    modules[a.asname] = a.name
    own = set(kernels.get(module, ()))  # bound at its top level where made per kind (kernel_of)
    for node in tree.body:  # a name assigned again at the top level is no longer the kernel
        targets = node.targets if isinstance(node, ast.Assign) else []
        for t in targets:
            for n in ast.walk(t):
                if isinstance(n, ast.Name) and n.id not in own:
                    names.discard(n.id)
    return names, modules


def python_uses(source: str, names: set[str], modules: dict[str, str] | None = None,
                kernels: dict[str, set[str]] | None = None) -> list[tuple[int, str]]:
    """(line, what) of every place where code that runs in Python names a kernel-only kernel:
    one of ``names``, or an attribute of a module of ``modules`` that is one of its ``kernels``."""
    modules = modules or {}
    found = []

    def visit(node, in_kernel: bool):
        if isinstance(node, (ast.Import, ast.ImportFrom)):
            return
        if isinstance(node, ast.Call) and ast.unparse(node.func).split(".")[-1] == "from_python":
            return  # the Python entry made for a kernel-only kernel
        if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
            for dec in node.decorator_list:
                visit(dec, in_kernel)
            for stmt in node.body:
                visit(stmt, in_kernel or _is_kernel(node))
            return
        if not in_kernel:
            if isinstance(node, ast.Name) and isinstance(node.ctx, ast.Load) and node.id in names:
                found.append((node.lineno, node.id))
            elif isinstance(node, ast.Attribute) and isinstance(node.value, ast.Name) \
                    and node.value.id in modules and node.attr in kernels[modules[node.value.id]]:
                found.append((node.lineno, f"{node.value.id}.{node.attr}"))
        for child in ast.iter_child_nodes(node):
            visit(child, in_kernel)

    visit(ast.parse(source), False)
    return found


def _files(folders):
    for folder in folders:
        yield from sorted((ROOT / folder).rglob("*.py"))


def _all_declared() -> dict[str, set[str]]:
    """Kernel module (dotted) -> the names of the kernel-only kernels it defines."""
    out = {}
    for path in _files(SOURCES):
        names = declared(path.read_text(encoding="utf-8"))
        if names:
            out[_module_of(path)] = names
    return out


def _all_reachable() -> dict[str, set[str]]:
    """Module (dotted) -> the names of kernel-only kernels reachable as its attributes: those it
    defines and those it imports from another module (``ck.new_stack`` is ``_kernels.new_stack``)."""
    out = {k: set(v) for k, v in _all_declared().items()}
    sources = [(p, p.read_text(encoding="utf-8")) for p in _files(SOURCES)]
    for _ in range(3):  # imports of imports
        for path, source in sources:
            names, _modules = kernel_names(source, _module_of(path), out, path.name == "__init__.py")
            if names:
                out.setdefault(_module_of(path), set()).update(names)
    return out


def test_checker_on_a_hand_made_module():
    kernels = {"pkg.kern": {"inner"}}
    own = '''
import numba as nb
from terrainvis.core.compiling import KERNEL_ONLY

@nb.njit(cache=True, **KERNEL_ONLY)
def inner(a):
    return a + 1

@nb.njit(cache=True)
def outer(a):
    return inner(a)

def plain(a):
    return outer(a) + inner(a)
'''
    assert declared(own) == {"inner"}
    assert python_uses(own, *kernel_names(own, "pkg.kern", kernels), kernels) == [(14, "inner")]
    other = '''
from pkg.kern import inner
from pkg import kern as k
import pkg.kern as kk
from .kern import inner as inner2
from terrainvis.core.compiling import from_python

def inner3(a):  # a Python function of the same name as another module's kernel
    return a

TABLE = {"f": k.inner, "g": kk.inner, "h": inner2, "i": inner3, "j": k.outer}
CALL = from_python(k.inner)
USE = inner(1)
'''
    assert python_uses(other, *kernel_names(other, "pkg.user", kernels), kernels) == [
        (11, "k.inner"), (11, "kk.inner"), (11, "inner2"), (13, "inner")]
    again = "from pkg.kern import inner\ninner = from_python(inner)\nUSE = inner(1)\n"
    assert python_uses(again, *kernel_names(again, "pkg.user", kernels), kernels) == []
    made = '''
from terrainvis.core.compiling import KERNEL_ONLY, kernel_of

def _make(kind):
    @kernel_of(kind, "grid_leaf", "tin_leaf", **KERNEL_ONLY)
    def leaf(a):
        return a

    return leaf

grid_leaf, tin_leaf = _make(0), _make(1)
USE = tin_leaf(1)
'''
    assert declared(made) == {"grid_leaf", "tin_leaf"}  # the names it takes, not the function's
    made_kernels = {"pkg.made": declared(made)}
    assert python_uses(made, *kernel_names(made, "pkg.made", made_kernels), made_kernels) == [(12, "tin_leaf")]


def test_no_python_code_names_a_kernel_only_kernel():
    assert sum(len(v) for v in _all_declared().values()) >= 100
    kernels = _all_reachable()  # the sweep's, the walks', the simplifiers' helpers
    uses = []
    for path in _files(READERS):
        source = path.read_text(encoding="utf-8")
        bound = kernel_names(source, _module_of(path), kernels, path.name == "__init__.py")
        for line, what in python_uses(source, *bound, kernels):
            uses.append(f"{path.relative_to(ROOT).as_posix()}:{line} names {what}, a kernel-only kernel "
                        "(call it through terrainvis.core.compiling.from_python)")
    assert not uses, "\n".join(uses)


@pytest.mark.parametrize("module", sorted(_all_declared()))
def test_the_files_say_what_numba_gets(module):
    """Every dispatcher a module makes without a Python entry is one its source declares, and back."""
    mod = importlib.import_module(module)
    compiled = {name for name, obj in vars(mod).items()
                if getattr(obj, "targetoptions", None) is not None and getattr(obj, "py_func", None) is not None
                and obj.py_func.__module__ == mod.__name__
                and all(obj.targetoptions.get(k) == v for k, v in KERNEL_ONLY.items())}
    assert compiled == _all_declared()[module]
