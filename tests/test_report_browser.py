"""report.html of a multi-method run without a truth file, rendered by a real headless
browser (Debian's chromium; skipped when it is absent): not blank, and the page a browser
builds holds the verdicts, the stations with their 1-sigma, residuals in µrad, coverage."""

from __future__ import annotations

import dataclasses
import re
import shutil
import subprocess
from pathlib import Path

import numpy as np
import pytest

from lhgraph.sim.simulate import default_simulation_config, simulate, write_simulation
from lhgraph.workflow.rundir import run_to_directory
from lhgraph.workflow.solve_config import load_solve_config

CHROMIUM = shutil.which("chromium") or shutil.which("chromium-browser")
pytestmark = pytest.mark.skipif(CHROMIUM is None, reason="chromium not installed")


def chromium(args: list[str], tmp: Path) -> subprocess.CompletedProcess[str]:
    """Headless chromium, offline and with a throw-away profile."""
    return subprocess.run(
        [str(CHROMIUM), "--headless", "--no-sandbox", "--disable-gpu", "--disable-quic",
         "--no-first-run", "--disable-background-networking", "--disable-component-update",
         "--disable-sync", f"--user-data-dir={tmp / 'profile'}", *args],
        capture_output=True, text=True, timeout=120, check=True)


@pytest.fixture(scope="module")
def run_dir(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """Both methods on a 1.5 s simulated capture, no truth file (as with a real capture)."""
    tmp = tmp_path_factory.mktemp("browser")
    sim = simulate(dataclasses.replace(default_simulation_config(), duration_s=1.5), seed=5)
    write_simulation(sim, tmp)
    (tmp / "run.toml").write_text('board = "board.toml"\nangles = "angles.csv"\n'
                                  'methods = ["graph", "paper"]\n')
    run_to_directory(load_solve_config(tmp / "run.toml"), tmp / "out")
    return tmp / "out"


def test_report_renders_with_stations_sigma_verdict(run_dir: Path, tmp_path: Path) -> None:
    from matplotlib.image import imread

    report = run_dir / "report.html"
    shot = tmp_path / "report.png"
    chromium([f"--screenshot={shot}", "--window-size=1200,3000", report.as_uri()], tmp_path)
    pixels = imread(shot)[..., :3]
    assert pixels.shape[:2] == (3000, 1200)
    assert pixels.std() > 0.05  # not a blank page: text, tables and figures drawn
    dom = chromium(["--dump-dom", report.as_uri()], tmp_path).stdout
    text = re.sub(r'src="data:image/png;base64,[^"]*"', "", dom)
    assert "verdict" in text and ("OK" in text or "check:" in text)
    assert text.count("<h2>Stations: ") == 2 and text.count("(reference)") == 2
    sigmas = re.findall(r"<td>-?\d+\.\d+ ± (\d+\.\d+)</td>", text)
    assert len(sigmas) >= 6 and all(np.isfinite(float(v)) for v in sigmas)
    assert "µrad" in text and "urad" not in text.replace("µrad", "")
    assert "Coverage" in text and "No truth file given" in text
    assert dom.count("data:image/png;base64,") >= 4  # histograms, coverage, scene, convergence
    for method in ("graph", "paper"):
        sub = chromium(["--dump-dom", (run_dir / method / "report.html").as_uri()], tmp_path)
        assert "verdict" in sub.stdout and "Coverage" in sub.stdout
