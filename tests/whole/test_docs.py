"""The Markdown documentation holds together: README.md and docs/*.md.

* Every relative link and image (``[text](path)``, ``[text](path#anchor)``,
  ``[text](#anchor)``, reference definitions, ``<a href>`` / ``<img src>``) points to a
  file or folder of this repository, and every ``#anchor`` matches a heading of the
  target file under GitHub's slug rules (lowercase; characters other than letters, marks,
  digits, ``_``, ``-`` and spaces dropped; spaces to ``-``; a repeated slug gets ``-1``,
  ``-2``, ...). Links inside code (fenced blocks, inline spans) are not links.
* The README stays navigable: a table of contents, at most 200 lines, a link to every
  document in docs/, every figure in docs/figures/ shown somewhere.
* The README's quick start is the install and test command that ``.ci/run`` runs.
* The docs say what the code is: docs/architecture.md names every module of
  ``terrainvis/`` and ``simplifiers/``; the user guide's options table of ``compare``
  lists exactly the flags of ``terrainvis compare --help``; the default relocations the
  user guide and paper.md name are ``terrainvis.relocation.default_relocations()``; the
  output of ``terrainvis info hills`` the user guide shows is what the command prints.
  The expected values are read from the code, never written here.

The checker itself is tested on hand-worked cases (slugs, a broken file, a broken
anchor, a link inside code) so that a checker that finds nothing cannot pass unnoticed.
"""

from __future__ import annotations

import argparse
import re
import unicodedata
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[2]
README = REPO / "README.md"
DOCS = REPO / "docs"

_FENCE = re.compile(r"^\s{0,3}(```|~~~)")
_HEADING = re.compile(r"^\s{0,3}(#{1,6})\s+(.*?)(?:\s+#+)?\s*$")
_INLINE_CODE = re.compile(r"(`+)(?:(?!\1).)+?\1")
_LINK = re.compile(r"!?\[(?:[^\[\]]|\[[^\[\]]*\])*\]\(\s*<?([^)\s>]*)>?(?:\s+\"[^\"]*\")?\s*\)")
_REFDEF = re.compile(r"^\s{0,3}\[[^\]]+\]:\s*<?(\S+?)>?(?:\s+\"[^\"]*\")?\s*$")
_HTML = re.compile(r"<(?:a|img)\b[^>]*?\b(?:href|src)\s*=\s*\"([^\"]*)\"", re.IGNORECASE)
_SCHEME = re.compile(r"^[A-Za-z][A-Za-z0-9+.-]*:")


def _prose_lines(text: str):
    """(line number, line) of the lines outside fenced code blocks."""
    fence = None
    for i, line in enumerate(text.splitlines(), 1):
        m = _FENCE.match(line)
        if m:
            if fence is None:
                fence = m.group(1)
            elif m.group(1) == fence:
                fence = None
            continue
        if fence is None:
            yield i, line


def slug(heading: str) -> str:
    """GitHub's anchor for a heading's text (before de-duplication)."""
    text = re.sub(r"!?\[([^\]]*)\]\([^)]*\)", r"\1", heading)  # a link counts by its text
    text = re.sub(r"<[^>]+>", "", text)  # inline HTML tags
    out = []
    for ch in text.lower():
        cat = unicodedata.category(ch)
        if ch in "- " or cat[0] in "LM" or cat in ("Nd", "Pc"):
            out.append("-" if ch == " " else ch)
    return "".join(out)


def anchors(text: str) -> set[str]:
    """Every heading anchor of a Markdown text, with GitHub's -1, -2 suffixes for repeats."""
    seen: dict[str, int] = {}
    out = set()
    for _, line in _prose_lines(text):
        m = _HEADING.match(line)
        if not m:
            continue
        base = slug(m.group(2))
        n = seen.get(base, 0)
        seen[base] = n + 1
        out.add(base if n == 0 else f"{base}-{n}")
    return out


def links(text: str):
    """(line number, target) of every link, image and reference definition outside code."""
    for i, line in _prose_lines(text):
        line = _INLINE_CODE.sub("", line)
        for pattern in (_LINK, _HTML):
            for m in pattern.finditer(line):
                yield i, m.group(1)
        m = _REFDEF.match(line)
        if m:
            yield i, m.group(1)


def problems(files, root: Path) -> list[str]:
    """What is broken in the relative links of ``files`` (paths inside ``root``)."""
    root = root.resolve()
    cache: dict[Path, set[str]] = {}

    def anchors_of(path: Path) -> set[str]:
        if path not in cache:
            cache[path] = anchors(path.read_text(encoding="utf-8"))
        return cache[path]

    out = []
    for f in files:
        f = Path(f).resolve()
        where = f.relative_to(root)
        for line, target in links(f.read_text(encoding="utf-8")):
            if not target:
                out.append(f"{where}:{line}: empty link target")
                continue
            if _SCHEME.match(target) or target.startswith("//"):
                continue  # a URL, not a file of the repository
            path_part, _, anchor = target.partition("#")
            dest = f if not path_part else (f.parent / path_part).resolve()
            if dest != root and root not in dest.parents:
                out.append(f"{where}:{line}: {target!r} points outside the repository")
                continue
            if not dest.exists():
                out.append(f"{where}:{line}: {target!r}: no file {dest.relative_to(root)}")
                continue
            if anchor:
                if dest.suffix.lower() != ".md" or dest.is_dir():
                    out.append(f"{where}:{line}: {target!r}: an anchor into a file that is not Markdown")
                elif anchor not in anchors_of(dest):
                    out.append(f"{where}:{line}: {target!r}: no heading with anchor #{anchor} in "
                               f"{dest.relative_to(root)}")
    return out


def _documents() -> list[Path]:
    return [README] + sorted(DOCS.glob("*.md"))


# ------------------------------------------------------------------ the checker itself
@pytest.mark.parametrize(("heading", "expected"), [
    ("Quick start", "quick-start"),
    ("The main job: `terrainvis compare`", "the-main-job-terrainvis-compare"),
    ("Why our relocation finding differs from the paper's", "why-our-relocation-finding-differs-from-the-papers"),
    ("Exact line of sight (`terrainvis.visibility`)", "exact-line-of-sight-terrainvisvisibility"),
    ("What simplification buys at SRTM scale (`benchmarks/bench_srtm.py`)",
     "what-simplification-buys-at-srtm-scale-benchmarksbench_srtmpy"),
    ("Reverse Faber on 3601² — one level", "reverse-faber-on-3601--one-level"),
    ("See [the guide](docs/user-guide.md) *now*", "see-the-guide-now"),
    ("Greedy cuts, QEC & friends", "greedy-cuts-qec--friends"),
])
def test_slug_follows_github(heading, expected):
    assert slug(heading) == expected


def test_repeated_headings_get_numbered_anchors_and_code_is_not_a_heading():
    text = "# Tests\n\n## Tests\n\n```\n# Tests\n```\n\n### Tests\n"
    assert anchors(text) == {"tests", "tests-1", "tests-2"}


def test_checker_finds_broken_files_and_anchors(tmp_path):
    (tmp_path / "docs").mkdir()
    (tmp_path / "docs" / "guide.md").write_text("# Guide\n\n## Resume a run\n", encoding="utf-8")
    (tmp_path / "fig.png").write_bytes(b"")
    readme = tmp_path / "README.md"
    readme.write_text(
        "# Title\n\n## Contents\n\n"
        "- [ok](docs/guide.md#resume-a-run) and [ok too](#contents) ![ok](fig.png)\n"
        "- [missing file](docs/nope.md)\n"
        "- [missing anchor](docs/guide.md#resume)\n"
        "- [own missing anchor](#nowhere)\n"
        "- [outside](../elsewhere.md) [web](https://example.org/x.md#y)\n"
        "- `[in code](docs/nope.md)`\n\n"
        "```\n[in a block](docs/nope.md)\n```\n\n"
        "[ref]: docs/gone.md\n",
        encoding="utf-8",
    )
    found = problems([readme], tmp_path)
    assert len(found) == 5, found
    assert any("docs/nope.md" in p and ":6:" in p for p in found)
    assert any("#resume" in p and ":7:" in p for p in found)
    assert any("#nowhere" in p for p in found)
    assert any("outside the repository" in p for p in found)
    assert any("docs/gone.md" in p for p in found)


# ------------------------------------------------------------------ the documentation
def test_every_relative_link_and_anchor_resolves():
    docs = _documents()
    assert len(docs) >= 2, "README.md and the docs/ folder"
    found = problems(docs, REPO)
    assert not found, "broken links:\n" + "\n".join(found)


def test_readme_is_navigable():
    text = README.read_text(encoding="utf-8")
    lines = text.splitlines()
    assert len(lines) <= 200, f"README.md has {len(lines)} lines; move details into docs/ (at most 200)"
    assert "contents" in anchors(text), "README.md needs a 'Contents' heading (its table of contents)"
    targets = {target.partition("#")[0] for _, target in links(text)}
    for doc in sorted(DOCS.glob("*.md")):
        assert f"docs/{doc.name}" in targets, f"README.md does not link to docs/{doc.name}"


def test_every_figure_in_docs_is_shown():
    shown = set()
    for doc in _documents():
        for _, target in links(doc.read_text(encoding="utf-8")):
            if not _SCHEME.match(target):
                shown.add((doc.parent / target.partition("#")[0]).resolve())
    figures = sorted((DOCS / "figures").glob("*.png"))
    assert figures
    unused = [f.name for f in figures if f.resolve() not in shown]
    assert not unused, f"figures in docs/figures/ that no document shows: {unused}"


def test_quick_start_is_what_ci_runs():
    readme = README.read_text(encoding="utf-8")
    ci = (REPO / ".ci" / "run").read_text(encoding="utf-8")
    install = '.venv/bin/pip install -e ".[test,dask,geo,xarray,peers,tiles]"'
    assert (f"python3.11 -m venv .venv && {install} && .venv/bin/terrainvis compare --out results") in readme
    assert ".venv/bin/python -m pytest" in readme
    assert "python3.11 -m venv .venv" in ci
    assert install in ci
    assert ".venv/bin/python -m pytest" in ci


# ------------------------------------------------------------------ the docs say what the code is
ARCHITECTURE = DOCS / "architecture.md"
USER_GUIDE = DOCS / "user-guide.md"
PAPER = DOCS / "paper.md"


def code_modules(root: Path = REPO) -> list[str]:
    """Every module of terrainvis/ and simplifiers/ by its path from the repository
    (``terrainvis/core/mesh.py``), leaving out terrainvis/data/ and the ``__init__.py``
    and ``__main__.py`` files."""
    out = []
    for pkg in ("terrainvis", "simplifiers"):
        for p in sorted((root / pkg).rglob("*.py")):
            rel = p.relative_to(root)
            if rel.parts[:2] == ("terrainvis", "data") or p.name in ("__init__.py", "__main__.py"):
                continue
            out.append(rel.as_posix())
    return out


def unnamed(text: str, modules) -> list[str]:
    """The modules whose path (``terrainvis/core/mesh.py``) ``text`` never writes out."""
    return [m for m in modules if not re.search(rf"(?<![\w/.-]){re.escape(m)}(?![\w/])", text)]


def section(text: str, title: str) -> list[str]:
    """The lines of the section under the heading ``title`` (to the next heading of its level or above)."""
    lines = text.splitlines()
    for i, line in enumerate(lines):
        m = _HEADING.match(line)
        if m and m.group(2) == title:
            level = len(m.group(1))
            out = []
            for nxt in lines[i + 1:]:
                h = _HEADING.match(nxt)
                if h and len(h.group(1)) <= level:
                    break
                out.append(nxt)
            return out
    raise AssertionError(f"no heading {title!r}")


def table(lines, first: str) -> list[list[str]]:
    """The body rows (cells stripped) of the first Markdown table in ``lines`` whose first header cell is ``first``."""
    rows, found = [], False
    for line in lines:
        if not line.lstrip().startswith("|"):
            if found:
                break
            continue
        cells = [c.strip() for c in re.split(r"(?<!\\)\|", line.strip())[1:-1]]
        if not found:
            found = cells[0] == first
            continue
        if not all(set(c) <= set("-: ") for c in cells):
            rows.append(cells)
    assert found, f"no table with the header {first!r}"
    return rows


def flags_in(cell: str) -> set[str]:
    """The long flags written in a cell's code spans (```--points N```, ```--cascade` / `--no-cascade```)."""
    spans = re.findall(r"`([^`]+)`", cell)
    return {f for span in spans for f in re.findall(r"(?<![\w-])--[a-z][a-z-]*", span)}


def compare_flags() -> set[str]:
    """The long flags of ``terrainvis compare`` as its parser declares them (``--help`` aside)."""
    from terrainvis.cli import _parser

    sub = next(a for a in _parser()._actions if isinstance(a, argparse._SubParsersAction))
    return {s for a in sub.choices["compare"]._actions for s in a.option_strings
            if s.startswith("--") and s != "--help"}


def test_the_module_checker_on_hand_worked_cases(tmp_path):
    for rel in ("terrainvis/__init__.py", "terrainvis/core/__init__.py", "terrainvis/core/mesh.py",
                "terrainvis/core/_kernels.py", "terrainvis/cli/__main__.py", "terrainvis/data/make_bundled.py",
                "simplifiers/registry.py"):
        (tmp_path / rel).parent.mkdir(parents=True, exist_ok=True)
        (tmp_path / rel).write_text("", encoding="utf-8")
    found = code_modules(tmp_path)
    assert found == ["terrainvis/core/_kernels.py", "terrainvis/core/mesh.py", "simplifiers/registry.py"]
    text = "| `terrainvis/core/mesh.py` | meshes |\nsee my_terrainvis/core/_kernels.py and simplifiers/registry.pyc"
    assert unnamed(text, found) == ["terrainvis/core/_kernels.py", "simplifiers/registry.py"]
    assert flags_in("`--cascade` / `--no-cascade`, `--fill`, `--crop-valid` and not --workers") == {
        "--cascade", "--no-cascade", "--fill", "--crop-valid"}
    rows = table(["| option | default |", "|---|---|", "| `--a\\|b` | 1 |", "", "| other |"], "option")
    assert rows == [["`--a\\|b`", "1"]]


def test_architecture_names_every_module():
    modules = code_modules()
    assert "terrainvis/core/mesh.py" in modules and "simplifiers/registry.py" in modules
    missing = unnamed(ARCHITECTURE.read_text(encoding="utf-8"), modules)
    assert not missing, ("docs/architecture.md does not name these modules (write each path, e.g. "
                         "`terrainvis/core/mesh.py`, with one line on what it is for): " + ", ".join(missing))


def test_the_user_guides_options_table_is_compares_help():
    rows = table(section(USER_GUIDE.read_text(encoding="utf-8"), "`compare`: the paper's experiment"), "option")
    documented = set().union(*(flags_in(r[0]) for r in rows))
    flags = compare_flags()
    assert "--points" in flags and "--overwrite" in flags
    assert documented == flags, (f"the user guide's options table of compare lacks {sorted(flags - documented)} "
                                 f"and lists {sorted(documented - flags)}, which terrainvis compare does not take")


def test_the_default_relocations_the_docs_name_are_the_codes():
    from terrainvis.relocation import RELOCATIONS, default_relocations

    expected = list(default_relocations())
    rows = table(section(USER_GUIDE.read_text(encoding="utf-8"), "`compare`: the paper's experiment"), "option")
    default = [r[1] for r in rows if "--relocations" in flags_in(r[0])]
    assert len(default) == 1, "one row of the options table for --relocations"
    assert re.findall(r"[\w-]+", default[0]) == expected, f"user guide: default relocations {default[0]!r}"
    protocol = "\n".join(section(PAPER.read_text(encoding="utf-8"), "The protocol"))
    bullet = re.findall(r"^- \*\*Relocations:\*\*.*(?:\n  .*)*", protocol, re.MULTILINE)
    assert len(bullet) == 1, "paper.md: one '- **Relocations:**' bullet in the protocol"
    named = [s for s in re.findall(r"`([^`]+)`", bullet[0]) if s in RELOCATIONS]
    assert named == expected, f"paper.md's protocol names the relocations {named}, the code's defaults are {expected}"


def test_info_as_the_user_guide_shows_it(capsys):
    from terrainvis.cli import main

    text = USER_GUIDE.read_text(encoding="utf-8").splitlines()
    start = text.index("$ terrainvis info hills")
    shown = []
    for line in text[start + 1:]:
        if line.startswith("$ ") or _FENCE.match(line):
            break
        shown.append(line)
    assert main(["info", "hills"]) == 0
    assert shown == capsys.readouterr().out.rstrip("\n").splitlines()
