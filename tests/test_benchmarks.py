"""The benchmarks (benchmarks/README.md) stay runnable without running them (they take
minutes): every module imports and has a docstring and a ``main(argv)`` entry point, the
README has a row for each, and ``python -m benchmarks`` lists them all and refuses an unknown
name with exit code 2. Also ``crazyflie_evaluation``'s refusal of a mocap of another
recording, on synthetic timestamps (the shared logs are not needed)."""

from __future__ import annotations

import importlib
import inspect
import os
import subprocess
import sys
from pathlib import Path
from unittest import mock

import numpy as np
import pytest

import benchmarks
from benchmarks.__main__ import main as run
from benchmarks.crazyflie_evaluation import aligned_errors, check_alignment, check_clock_rate
from lhgraph.errors import InputError
from lhgraph.importers.crazyflie.mocap import align_mocap

REPO = Path(__file__).resolve().parents[1]
NAMES = benchmarks.names()


def test_every_script_is_a_benchmark():
    scripts = {p.stem for p in (REPO / "benchmarks").glob("*.py")}
    assert set(NAMES) == {s for s in scripts if not s.startswith("_")}
    assert len(NAMES) >= 27


@pytest.mark.parametrize("name", NAMES)
def test_benchmark_module(name):
    with mock.patch.dict(os.environ):  # benchmarks._single_thread sets thread variables
        module = importlib.import_module(f"benchmarks.{name}")
    assert module.__doc__ and benchmarks.summary(name)
    parameters = inspect.signature(module.main).parameters
    assert list(parameters) == ["argv"] and parameters["argv"].default is None
    assert f"| `{name}` |" in (REPO / "benchmarks" / "README.md").read_text(encoding="utf-8")


def runner(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "benchmarks", *args], cwd=REPO,
                          capture_output=True, text=True, timeout=60)


def test_runner_lists_every_benchmark():
    for args in ((), ("--list",)):
        proc = runner(*args)
        assert proc.returncode == 0, proc.stderr
        listed = [line.split()[0] for line in proc.stdout.splitlines()[1:]]
        assert listed == NAMES
        assert benchmarks.summary("crlb") in proc.stdout


def test_runner_refuses_an_unknown_name():
    proc = runner("no_such_benchmark", "--seeds", "1")
    assert proc.returncode == 2
    assert proc.stdout == "" and len(proc.stderr.splitlines()) == 1
    assert "unknown benchmark 'no_such_benchmark'" in proc.stderr


def test_runner_refuses_to_replace_a_results_file_in_one_line(tmp_path):
    """An existing output without --force is bad input: one line naming it, exit 2, the file
    untouched (checked before any work)."""
    out = tmp_path / "results.md"
    out.write_text("earlier results\n")
    proc = runner("anchored_stations", "--output", str(out))
    assert proc.returncode == 2
    assert proc.stdout == "" and len(proc.stderr.splitlines()) == 1
    assert str(out) in proc.stderr and "--force" in proc.stderr
    assert out.read_text() == "earlier results\n"


def test_runner_passes_the_arguments_on(capsys):
    with pytest.raises(SystemExit) as exit_:
        run(["crlb", "--help"])
    assert exit_.value.code == 0
    assert capsys.readouterr().out.startswith("usage: python -m benchmarks crlb ")
    assert benchmarks.command("benchmarks/crlb.py", ["--seeds", "2"]) == \
        "python -m benchmarks crlb --seeds 2"


def test_clock_rate_of_another_recording_refused():
    """A 60.95 s mocap (300 Hz) put onto a log whose markers are 121.9 s apart (the flight
    log's mocap on the moving deck's log): clock rate 2, refused naming the file; the
    recording's own mocap (the shared logs' 1.1 % clock difference) passes."""
    t_ms = np.arange(0.0, 60950.0, 1000 / 300)
    rows = np.column_stack([t_ms, np.zeros((len(t_ms), 3))])
    span = (t_ms[-1] - t_ms[0]) * 1e-3
    check_clock_rate(align_mocap(rows, 3.0, 3.0 + span * 0.98907).rate, "mocap02.npy")
    wrong = align_mocap(rows, 3.0, 124.9)
    assert wrong.rate == pytest.approx(2.0, abs=0.01)
    with pytest.raises(InputError, match=r"^mocap00\.npy: clock rate 2\.0\d+ .*outside 1 \+- "):
        check_clock_rate(wrong.rate, "mocap00.npy")


def lissajous(t: np.ndarray) -> np.ndarray:
    """A deck path (m) over a 2 x 1.6 x 0.6 m volume."""
    return np.stack([np.sin(2 * np.pi * 0.21 * t), 0.8 * np.cos(2 * np.pi * 0.33 * t),
                     1 + 0.3 * np.sin(2 * np.pi * 0.17 * t)], axis=1)


def test_alignment_with_another_recording_refused():
    """Positions at 50 Hz against a 300 Hz mocap in another frame: the recording's own mocap,
    30 ms late, is aligned (offsets found, rms ~0) and accepted; the same path on a clock
    running at 0.47 (another recording's timing) leaves over a metre and is refused."""
    t = np.arange(0.0, 20.0, 0.02)
    t_m = np.arange(-0.5, 20.5, 1 / 300)
    R = np.array([[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]])
    e, d0, d1 = aligned_errors(t, lissajous(t), t_m, lissajous(t_m - 0.03) @ R.T + [0.5, 0, 0])
    assert (d0, d1) == (pytest.approx(-0.03), pytest.approx(-0.03))
    check_alignment([float(np.sqrt(np.mean(e**2)))], "mocap.csv")
    e, _, _ = aligned_errors(t, lissajous(t), 0.47 * t_m, lissajous(t_m) @ R.T)
    rms = float(np.sqrt(np.mean(e**2)))
    assert rms > 1.0
    with pytest.raises(InputError, match=r"^out/mocap\.csv: the positions do not follow"):
        check_alignment([rms, 2 * rms], "out/mocap.csv")
    check_alignment([rms, 0.02], "out/mocap.csv")  # one geometry that fits: the mocap is right
