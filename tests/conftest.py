"""Fixtures: real CMU clips from the local mirror, small synthetic skeletons.

Tests that run a whole lesson (``test_lessons_full_mode.py``,
``test_lessons_falsifiable.py``) are skipped with one line, outside CI, when
the lesson's clips can be had neither from the mirror nor by download, as the
lessons themselves are (``lessons/conftest.py``, ``tests/lesson_data.py``).
"""

from __future__ import annotations

import os
import tempfile
from pathlib import Path

import numpy as np
import pytest
from hypothesis import settings
from hypothesis.configuration import set_hypothesis_home_dir
from hypothesis.database import DirectoryBasedExampleDatabase

# Hypothesis keeps its examples and caches outside the checkout (the test run writes nothing into it).
_HYPOTHESIS_HOME = Path(tempfile.gettempdir()) / "mocaplab-hypothesis"
set_hypothesis_home_dir(str(_HYPOTHESIS_HOME))
settings.register_profile("mocaplab", database=DirectoryBasedExampleDatabase(str(_HYPOTHESIS_HOME / "examples")))
settings.load_profile("mocaplab")

DATA = Path(__file__).parent / "data"
LESSON_DIR = Path(__file__).resolve().parent.parent / "lessons"


def pytest_collection_modifyitems(config: pytest.Config, items: list[pytest.Item]) -> None:
    """Skip the tests that run a lesson whose clips cannot be had (outside CI; see ``lesson_data.py``)."""
    from lesson_data import missing_data

    reasons: dict[str, str | None] = {}
    for item in items:
        params = getattr(getattr(item, "callspec", None), "params", {})
        lesson = params.get("lesson", params.get("path"))
        if not isinstance(lesson, str | Path) or not str(lesson).endswith(".ipynb"):
            continue
        name = Path(lesson).name
        if name not in reasons:
            reasons[name] = missing_data(LESSON_DIR / name)
        if reasons[name] is not None:
            item.add_marker(pytest.mark.skip(reason=f"{name}: {reasons[name]}"))


def _mirror() -> Path | None:
    value = os.environ.get("MOCAPLAB_DATA_DIR")
    return Path(value) if value and Path(value).is_dir() else None


@pytest.fixture(scope="session")
def mocap_dir() -> Path:
    """The CMU mirror; a missing mirror skips locally but fails in CI."""
    root = _mirror()
    if root is None:
        if os.environ.get("CI"):
            pytest.fail("MOCAPLAB_DATA_DIR must name the CMU mirror in CI (see .ci/run)")
        pytest.skip("no CMU mirror: set MOCAPLAB_DATA_DIR")
    return root


@pytest.fixture(scope="session")
def cmu(mocap_dir: Path):
    """``cmu("16_15")`` loads a clip from the mirror (cached per session)."""
    from mocaplab import data

    cache: dict[str, object] = {}

    def load(trial: str):
        if trial not in cache:
            cache[trial] = data.cmu(trial)
        return cache[trial]

    return load


@pytest.fixture
def rng() -> np.random.Generator:
    return np.random.default_rng(12345)


@pytest.fixture(scope="session")
def converted(cmu, tmp_path_factory):
    """``converted(clip, convention, frames)``: a CMU clip slice written in another
    convention (``tests/conventions.py``) and loaded back, with its name map (cached)."""
    from conventions import load_converted

    cache: dict = {}

    def get(clip: str, convention: str, frames: slice = slice(0, 360)):
        key = (clip, convention, frames.start, frames.stop, frames.step)
        if key not in cache:
            folder = tmp_path_factory.mktemp(f"{clip}_{convention}")
            cache[key] = load_converted(cmu(clip)[frames], convention, folder)
        return cache[key]

    return get
