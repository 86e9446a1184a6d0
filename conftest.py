"""Test-run settings shared by tests/ and the lessons executed by nbval.

* ``MOCAPLAB_FAST=1``: lessons shrink iteration counts and clip lengths.
* pyvista renders off-screen with its static backend in executed lessons.
* ``MOCAPLAB_DATA_DIR`` defaults to the data folder beside the checkout.
* Each lesson's run time is reported; a lesson over its budget fails the run.
* nbval (and the notebook stack it imports, about 3 s) is loaded only when
  the run collects lessons: the whole run, or a path to a notebook or to
  ``lessons/``; ``pytest tests/test_quat.py`` starts without it.  The
  lessons run in nbval's lax mode (``--nbval-lax``, set here).
"""

from __future__ import annotations

import os
import sys
import time
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent
LESSON_BUDGET_S = 60.0
LESSONS = ROOT / "lessons"


def _collects_lessons(args: list[str]) -> bool:
    """Whether a pytest command line collects notebooks: no path given (the whole run), or a lesson path."""
    paths = [Path(a.split("::")[0]) for a in args if a and not a.startswith("-")]
    paths = [p.resolve() for p in paths if p.exists()]
    if not paths:
        return True
    return any(p.suffix == ".ipynb" or p == LESSONS or p in LESSONS.parents for p in paths)


# pyproject's addopts keep nbval's entry point out (-p no:nbval); loaded here by its module name when needed
if _collects_lessons(sys.argv[1:]):
    pytest_plugins = ["nbval.plugin"]


@pytest.hookimpl(tryfirst=True)
def pytest_configure(config: pytest.Config) -> None:
    if config.pluginmanager.has_plugin("nbval.plugin") and not config.option.nbval:
        config.option.nbval_lax = True

os.environ.setdefault("MOCAPLAB_FAST", "1")
os.environ.setdefault("PYVISTA_OFF_SCREEN", "true")
os.environ.setdefault("MOCAPLAB_JUPYTER_BACKEND", "static")
os.environ.setdefault("MPLBACKEND", "Agg")
_default_mirror = ROOT.parent / "shared" / "mocap"
if "MOCAPLAB_DATA_DIR" not in os.environ and _default_mirror.is_dir():
    os.environ["MOCAPLAB_DATA_DIR"] = str(_default_mirror)

_lesson_times: dict[str, float] = {}
_lesson_start: dict[str, float] = {}


def pytest_runtest_setup(item: pytest.Item) -> None:
    path = str(item.path)
    if path.endswith(".ipynb"):
        _lesson_start.setdefault(path, time.perf_counter())


def pytest_runtest_teardown(item: pytest.Item) -> None:
    path = str(item.path)
    if path.endswith(".ipynb"):
        _lesson_times[path] = time.perf_counter() - _lesson_start[path]


def pytest_terminal_summary(terminalreporter, exitstatus, config) -> None:  # type: ignore[no-untyped-def]
    if not _lesson_times:
        return
    terminalreporter.section(f"lesson run times (budget {LESSON_BUDGET_S:.0f} s each)")
    over = []
    for path, seconds in sorted(_lesson_times.items()):
        flag = "  OVER BUDGET" if seconds > LESSON_BUDGET_S else ""
        terminalreporter.write_line(f"{Path(path).name:45s} {seconds:6.1f} s{flag}")
        if seconds > LESSON_BUDGET_S:
            over.append(path)
    if over:
        terminalreporter.write_line(f"{len(over)} lesson(s) over the {LESSON_BUDGET_S:.0f} s budget", red=True)


def pytest_sessionfinish(session: pytest.Session, exitstatus: int) -> None:
    if any(t > LESSON_BUDGET_S for t in _lesson_times.values()) and exitstatus == 0:
        session.exitstatus = 1
