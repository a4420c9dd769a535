"""The user guide's commands run as they stand and print what the guide shows.

Every ``$ terrainvis ...`` line of a console block in docs/user-guide.md is run in a fresh
folder (with the files the guide names from the repository: the observers' CSV), and
its standard output is compared with the lines the guide shows under it, seconds and
rates masked. ``$ cat FILE`` lines create FILE with the lines shown. The commands that are
not run are listed in NOT_RUN with the reason, and a test checks that list against the
guide, so that a new command cannot be left out silently.
"""

from __future__ import annotations

import re
import shlex
import shutil
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[2]
USER_GUIDE = REPO / "docs" / "user-guide.md"

#: Files of the repository the guide's commands read, copied into the folder they run in.
INPUTS = ("docs/figures/cumberland_observers.csv",)

#: Commands of the guide that this test does not run, each with why.
NOT_RUN = {
    "terrainvis viewshed dem.tif --observer 515375 4010255 -o viewshed.tif":
        "the first-run notice on a user's own DEM with an empty numba cache (stderr)",
    "terrainvis compare --terrain cumberland --out results":
        "the whole experiment on a 337 x 321 DEM takes minutes (compare is tested in tests/experiment)",
}

_FENCE = re.compile(r"^\s*```")


def guide_sessions(text: str) -> list[tuple[str, list[str]]]:
    """``(command, shown output lines)`` for every ``$ `` line of the guide's console blocks."""
    sessions: list[tuple[str, list[str]]] = []
    inside, current = False, None
    for line in text.splitlines():
        if _FENCE.match(line):
            inside, current = line.strip().startswith("```console") and not inside, None
            continue
        if not inside:
            continue
        if line.startswith("$ "):
            current = []
            sessions.append((line[2:].split("  #")[0].rstrip(), current))
        elif current is not None:  # lines before a block's first command are shown output of nothing run
            current.append(line)
    return sessions


#: What differs between runs: seconds ("0.21 s", "4.5 s in all") and rates ("175.6 observers/s").
_TIMES = re.compile(r"\d[\d,]*(?:\.\d+)? (?:s\b|observers/s\b)")


def masked(lines: list[str]) -> list[str]:
    return [_TIMES.sub("<time>", line.rstrip()) for line in lines]


def test_masking_on_hand_worked_lines():
    assert masked(["  visible 14,273 of 108,177 samples (13.19 %), 0.02 s"]) == \
        ["  visible 14,273 of 108,177 samples (13.19 %), <time>"]
    assert masked(["0.1 s in this process (175.6 observers/s)", "viewsheds 4.3 s, greedy 0.11 s; 4.5 s in all"]) == \
        ["<time> in this process (<time>)", "viewsheds <time>, greedy <time>; <time> in all"]
    assert masked(["12 samples", "3 sets", "level 2 s"]) == ["12 samples", "3 sets", "level <time>"]


def test_sessions_are_read_from_console_blocks_only():
    text = "\n".join(["```console", "$ cat a.csv", "x,y", "1,2", "$ terrainvis info hills", "hills: ...",
                      "```", "$ terrainvis not-in-a-block", "```python", "$ x = 1", "```",
                      "```console", "  earth: flat", "```"])
    assert guide_sessions(text) == [("cat a.csv", ["x,y", "1,2"]), ("terrainvis info hills", ["hills: ..."])]


def _sessions():
    return guide_sessions(USER_GUIDE.read_text(encoding="utf-8"))


def test_every_command_not_run_is_in_the_guide():
    commands = {command for command, _ in _sessions()}
    assert set(NOT_RUN) <= commands, f"NOT_RUN names commands the guide no longer has: {set(NOT_RUN) - commands}"


def test_the_guides_commands_print_what_it_shows(tmp_path, monkeypatch, capsys):
    pytest.importorskip("rasterio", reason="the guide's GIS examples read the bundled GeoTIFF (the geo extra)")
    from terrainvis.cli import main

    for name in INPUTS:
        (tmp_path / name).parent.mkdir(parents=True, exist_ok=True)
        shutil.copyfile(REPO / name, tmp_path / name)
    monkeypatch.chdir(tmp_path)
    ran = 0
    for command, shown in _sessions():
        argv = shlex.split(command)
        if argv[0] == "cat":
            Path(argv[1]).write_text("\n".join(shown) + "\n", encoding="utf-8")
            continue
        if argv[0] != "terrainvis" or command in NOT_RUN:  # others: benchmark runs, measurements of their day
            continue
        capsys.readouterr()
        assert main(argv[1:]) == 0, command
        printed = capsys.readouterr().out.rstrip("\n").splitlines()
        if shown:
            assert masked(printed) == masked(shown), f"$ {command}"
        ran += 1
    assert ran >= 12, f"ran {ran} of the guide's commands"
