"""The shape of the code: no function outside the numba kernels is over ~80 lines of body or
takes over ~12 parameters (issue 21).

Kernels (``@nb.njit`` / ``@numba.njit``) are exempt: they loop over flat arrays and take
them one by one (their state is grouped in named tuples where a family has many). The body
is counted from its first statement after the docstring to its last line (a docstring says
what a function computes; it is documentation, not length). Parameters are the positional
ones, ``*args`` and ``**kwargs``, and the keyword-only ones of private functions: the
keyword-only options of a public function are its interface and are not counted.
"""

from __future__ import annotations

import ast
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
PACKAGES = ("terrainvis", "simplifiers")
MAX_BODY_LINES = 80
MAX_PARAMETERS = 12

#: Functions allowed over the limits, as "path:qualified name" -> why. Empty: at this commit
#: no function of terrainvis/ or simplifiers/ is over them. A new entry needs its reason
#: (owned by a branch not merged yet, with the issue that will split it).
ALLOWED: dict[str, str] = {}

_KERNEL_DECORATORS = {"nb.njit", "numba.njit", "njit", "kernel_of"}


def _is_kernel(fn: ast.FunctionDef) -> bool:
    for dec in fn.decorator_list:
        target = dec.func if isinstance(dec, ast.Call) else dec
        if ast.unparse(target) in _KERNEL_DECORATORS:
            return True
    return False


def _body_lines(fn: ast.FunctionDef) -> int:
    body = fn.body
    if body and isinstance(body[0], ast.Expr) and isinstance(body[0].value, ast.Constant) \
            and isinstance(body[0].value.value, str):
        body = body[1:]
    return body[-1].end_lineno - body[0].lineno + 1 if body else 0


def _parameters(fn: ast.FunctionDef) -> int:
    a = fn.args
    n = len(a.posonlyargs) + len(a.args) + (a.vararg is not None) + (a.kwarg is not None)
    return n if not fn.name.startswith("_") else n + len(a.kwonlyargs)


def _functions(tree: ast.AST, prefix: str = ""):
    """(qualified name, node) of every function, methods and nested functions included."""
    for node in ast.iter_child_nodes(tree):
        if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
            name = prefix + node.name
            yield name, node
            yield from _functions(node, name + ".")
        elif isinstance(node, ast.ClassDef):
            yield from _functions(node, prefix + node.name + ".")
        else:
            yield from _functions(node, prefix)


def offenders(source: str, rel: str) -> dict[str, str]:
    """"rel:name" -> what is over the limits, for every non-kernel function of ``source``."""
    out = {}
    for name, fn in _functions(ast.parse(source)):
        if _is_kernel(fn):
            continue
        problems = []
        if _body_lines(fn) > MAX_BODY_LINES:
            problems.append(f"{_body_lines(fn)} lines of body")
        if _parameters(fn) > MAX_PARAMETERS:
            problems.append(f"{_parameters(fn)} parameters")
        if problems:
            out[f"{rel}:{name}"] = ", ".join(problems)
    return out


def _all_offenders() -> dict[str, str]:
    found = {}
    for package in PACKAGES:
        for path in sorted((ROOT / package).rglob("*.py")):
            found.update(offenders(path.read_text(encoding="utf-8"), path.relative_to(ROOT).as_posix()))
    return found


def test_checker_on_a_hand_made_module():
    long_body = "\n".join(f"    x{i} = {i}" for i in range(MAX_BODY_LINES + 1))
    just_fits = "\n".join(f"    x{i} = {i}" for i in range(MAX_BODY_LINES))
    many = ", ".join(f"a{i}" for i in range(MAX_PARAMETERS + 1))
    doc = '    """' + "\n".join(["doc"] * 30) + '"""\n'
    source = (
        f"def long():\n{long_body}\n\n"
        f"def fits():\n{doc}{just_fits}\n\n"                     # the docstring is not counted
        f"def _wide({many}):\n    pass\n\n"
        f"def public_options(a, *, {many}):\n    pass\n\n"       # keyword-only options of a public function
        f"def _private_options(a, *, {many}):\n    pass\n\n"     # ... of a private one count
        f"class C:\n    def method(self, {many}):\n        pass\n\n"
        f"@nb.njit(cache=True, nogil=True)\ndef kernel({many}):\n{long_body}\n\n"
        f"@numba.njit\ndef kernel2({many}):\n    pass\n"
    )
    assert offenders(source, "m.py") == {
        "m.py:long": f"{MAX_BODY_LINES + 1} lines of body",
        "m.py:_wide": f"{MAX_PARAMETERS + 1} parameters",
        "m.py:_private_options": f"{MAX_PARAMETERS + 2} parameters",
        "m.py:C.method": f"{MAX_PARAMETERS + 2} parameters",
    }


def test_no_long_or_wide_function():
    found = _all_offenders()
    unexpected = {k: v for k, v in found.items() if k not in ALLOWED}
    assert not unexpected, (
        f"functions over {MAX_BODY_LINES} lines of body or {MAX_PARAMETERS} parameters (split them: "
        "well-named helpers, named records for state):\n" + "\n".join(f"{k}: {v}" for k, v in unexpected.items())
    )


def test_allow_list_only_shrinks():
    found = _all_offenders()
    stale = [k for k in ALLOWED if k not in found]
    assert not stale, f"allow-list entries no longer needed (remove them): {stale}"
