"""The test run itself: nbval loads only where lessons run, and the whole run still collects every lesson."""

from __future__ import annotations

import importlib.util
import os
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
_spec = importlib.util.spec_from_file_location("mocaplab_root_conftest", ROOT / "conftest.py")
assert _spec is not None and _spec.loader is not None
_root_conftest = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(_root_conftest)  # the root conftest: its rule is under test
_collects_lessons = _root_conftest._collects_lessons


@pytest.mark.parametrize(
    "args, expected",
    [
        ([], True),  # the whole run (testpaths include lessons/)
        (["-q", "-k", "touch"], True),
        (["tests/test_quat.py"], False),
        (["tests/test_quat.py::test_mul", "-q"], False),
        (["tests"], False),
        (["lessons"], True),
        (["lessons/01_motion_data.ipynb"], True),
        (["."], True),
    ],
)
def test_nbval_is_loaded_only_where_lessons_are_collected(args, expected, monkeypatch):
    monkeypatch.chdir(ROOT)
    assert _collects_lessons(args) is expected


def _collect(*args: str) -> str:
    out = subprocess.run(
        [sys.executable, "-m", "pytest", "--collect-only", "-q", *args], cwd=ROOT, capture_output=True, text=True,
        timeout=600,
    )
    assert out.returncode == 0, out.stdout[-2000:] + out.stderr[-2000:]
    return out.stdout


def test_a_lesson_is_collected_and_a_test_file_alone_is_not_slowed_by_nbval():
    lesson = _collect("lessons/01_motion_data.ipynb")
    assert "01_motion_data.ipynb::Cell 0" in lesson
    plain = _collect("tests/test_quat.py")
    assert ".ipynb" not in plain and "test_quat.py::" in plain
    # a probe plugin reports whether nbval was imported by the end of collection
    env = {**os.environ, "PYTHONPATH": os.pathsep.join(filter(None, [str(ROOT / "tests"), os.environ.get("PYTHONPATH")]))}
    probes = {
        target: subprocess.run(
            [sys.executable, "-m", "pytest", "-p", "nbval_probe", "--collect-only", "-q", target],
            cwd=ROOT, capture_output=True, text=True, timeout=600, env=env,
        ).stdout
        for target in ("tests/test_quat.py", "lessons/01_motion_data.ipynb")
    }
    assert "nbval imported: False" in probes["tests/test_quat.py"], probes["tests/test_quat.py"][-1000:]
    assert "nbval imported: True" in probes["lessons/01_motion_data.ipynb"], probes["lessons/01_motion_data.ipynb"][-1000:]
