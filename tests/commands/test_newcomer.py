"""Frictions a newcomer met (issue 42), each reproduced first.

8. ``cumulative`` and ``site`` redrew their progress bars into log files (carriage
   returns and cursor escapes), where ``compare`` writes plain lines; and the first
   observer's compilation counted in the bar's rate ("22:42 left", "0.4 observers/s").
"""

from __future__ import annotations

import subprocess
import sys

import numpy as np

from terrainvis import bundled_terrain, save_terrain


def _observers(path, n=12):
    rng = np.random.default_rng(0)
    xy = rng.uniform(200.0, 3300.0, (n, 2))
    path.write_text("x,y\n" + "".join(f"{x:.1f},{y:.1f}\n" for x, y in xy))
    return path


def test_progress_into_a_log_is_plain_lines(tmp_path):
    dem = tmp_path / "hills.npz"
    save_terrain(bundled_terrain("hills"), dem)
    obs = _observers(tmp_path / "obs.csv")
    runs = {
        "cumulative viewshed": ["cumulative", str(dem), "--observers", str(obs), "--frame", "local", "-o",
                                str(tmp_path / "c.npz")],
        "candidate viewsheds": ["site", str(dem), "--grid", "20", "-k", "2", "--frame", "local"],
    }
    for desc, argv in runs.items():
        with open(tmp_path / "log.txt", "w") as log:  # stderr is a file, as under nohup or a CI log
            out = subprocess.run([sys.executable, "-m", "terrainvis.cli", *argv], stderr=log, stdout=subprocess.PIPE,
                                 text=True, timeout=600)
        err = (tmp_path / "log.txt").read_text()
        assert out.returncode == 0, err
        assert "\r" not in err and "\x1b[" not in err, repr(err)
        lines = [ln for ln in err.splitlines() if ln.startswith(desc + ": ")]
        assert lines and lines[-1].split(": ")[1].split(" ")[0].split("/")[0] == lines[-1].split("/")[1].split(" ")[0]
