"""Lessons without data skip in one line outside CI, and fail in CI (``lessons/conftest.py``, ``lesson_data.py``).

Each case runs ``pytest`` on one lesson in a subprocess, with the mirror
pointing at an empty folder or unset and downloads sent to a closed local
port, so no network is needed.
"""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest
from lesson_data import in_ci, lesson_trials

ROOT = Path(__file__).resolve().parent.parent
LESSON = "lessons/15_capstone.ipynb"
CLOSED = "http://127.0.0.1:9/subjects"  # the discard port: nothing listens, the connection is refused at once


def _pytest(env_changes: dict[str, str], *args: str) -> subprocess.CompletedProcess[str]:
    env = {k: v for k, v in os.environ.items() if k not in ("CI", "PYTEST_ADDOPTS", "PYTEST_CURRENT_TEST")}
    env.update(env_changes)
    return subprocess.run(
        [sys.executable, "-m", "pytest", "-q", "-rs", "-p", "no:randomly", *args, LESSON],
        cwd=ROOT,
        env=env,
        capture_output=True,
        text=True,
        timeout=300,
    )


def _skip_lines(out: str) -> list[str]:
    return [line for line in out.splitlines() if line.startswith("SKIPPED")]


@pytest.mark.parametrize(("value", "ci"), [("", False), ("0", False), ("false", False), ("1", True), ("true", True)])
def test_in_ci(monkeypatch, value, ci):
    monkeypatch.setenv("CI", value)
    assert in_ci() is ci


def test_lesson_trials_reads_the_clip_ids():
    assert lesson_trials(ROOT / LESSON) == ["16_15", "16_11"]


def test_empty_mirror_skips_the_lesson_in_one_line(tmp_path):
    run = _pytest({"MOCAPLAB_DATA_DIR": str(tmp_path), "MOCAPLAB_CMU_URL": CLOSED})
    out = run.stdout + run.stderr
    assert run.returncode == 0, out
    lines = _skip_lines(run.stdout)
    assert len(lines) == 1, out
    assert (
        "15_capstone.ipynb: no CMU data" in lines[0]
        and f"MOCAPLAB_DATA_DIR={tmp_path} has no bvh/16_15.bvh" in lines[0]
    )
    assert "1 skipped" in run.stdout and "Traceback" not in out and "DataError" not in out


def test_no_mirror_and_no_download_skips_the_lesson_in_one_line(tmp_path):
    # an empty MOCAPLAB_DATA_DIR is "no mirror" (and keeps conftest.py from pointing it at ../shared/mocap)
    env = {"MOCAPLAB_DATA_DIR": "", "MOCAPLAB_CMU_URL": CLOSED, "MOCAPLAB_CACHE_DIR": str(tmp_path)}
    run = _pytest(env)
    out = run.stdout + run.stderr
    assert run.returncode == 0, out
    lines = _skip_lines(run.stdout)
    assert len(lines) == 1 and "could not be downloaded from " + CLOSED in lines[0], out
    assert "Traceback" not in out


def test_in_ci_a_missing_mirror_fails(tmp_path):
    run = _pytest({"CI": "1", "MOCAPLAB_DATA_DIR": str(tmp_path), "MOCAPLAB_CMU_URL": CLOSED}, "-x")
    assert run.returncode != 0 and not _skip_lines(run.stdout), run.stdout[-2000:]
    assert "DataError" in run.stdout, run.stdout[-2000:]
