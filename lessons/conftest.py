"""pytest settings for the lesson notebooks (nbval); not needed to run the lessons in JupyterLab.

Outside CI, a lesson whose CMU clips can be had neither from the mirror
(``MOCAPLAB_DATA_DIR``) nor by download is skipped with one line saying
why (``tests/lesson_data.py``), instead of failing in every cell
with download tracebacks; in CI it runs, and fails.

A cell that shows a warning its lesson does not teach fails
(``tests/lesson_warnings.py``).
"""

from __future__ import annotations

import sys
from pathlib import Path

import pytest

_TESTS = str(Path(__file__).resolve().parent.parent / "tests")
if _TESTS not in sys.path:
    sys.path.insert(0, _TESTS)

from lesson_data import missing_data  # noqa: E402
from lesson_warnings import check_cell  # noqa: E402


class LessonWithoutData(pytest.File):
    """A lesson notebook whose clips cannot be had, collected as one item that skips."""

    reason = ""

    def collect(self):  # type: ignore[no-untyped-def]
        yield SkippedLesson.from_parent(self, name="no data")


class SkippedLesson(pytest.Item):
    def runtest(self) -> None:
        pytest.skip(self.parent.reason)  # type: ignore[union-attr]

    def reportinfo(self):  # type: ignore[no-untyped-def]
        return self.path, 0, "no data"


@pytest.hookimpl(wrapper=True)
def pytest_collect_file(file_path: Path, parent: pytest.Collector):  # type: ignore[no-untyped-def]
    collectors = yield
    if file_path.suffix != ".ipynb" or not collectors:
        return collectors
    reason = missing_data(file_path)
    if reason is None:
        return collectors
    skip = LessonWithoutData.from_parent(parent, path=file_path)
    skip.reason = f"{file_path.name}: {reason}"
    return [skip]


@pytest.hookimpl(wrapper=True)
def pytest_runtest_call(item: pytest.Item):  # type: ignore[no-untyped-def]
    """After nbval runs a cell: fail it when it showed a warning its lesson does not teach."""
    result = yield
    outputs = getattr(item, "test_outputs", None)
    if outputs and item.path.suffix == ".ipynb":
        check_cell(item.path.name, item.name, outputs)
    return result
