"""Every lesson asserts what it teaches: break the method and the lesson fails (STYLE 18).

The mutations live beside this runner, one module per paper
(``mutations_kim.py`` for lessons 01-07, ``mutations_shin.py`` for 08-10,
``mutations_coleman.py`` for 11-13, ``mutations_pipeline.py`` for the lessons
that combine them).  Each case runs a lesson's code cells in this process
(fast mode, Agg), in order, with one piece of the method replaced by a broken
or do-nothing stand-in, and expects an ``assert`` of the lesson to fail with
the case's message; any other exception is a broken lesson and fails the
test.  Cells after the first failing assert are not run, so a case costs
only the lesson's prefix.  nbval runs the unmodified lessons (they pass).
"""

from __future__ import annotations

import importlib
import os
from collections.abc import Callable

import pytest
from lesson_support import LESSONS, first_failing_assert

Switch = Callable[[pytest.MonkeyPatch], None]


def _cases() -> list[tuple[str, Switch, str | None]]:
    cases: list[tuple[str, Switch, str | None]] = []
    for name in ("mutations_kim", "mutations_shin", "mutations_coleman", "mutations_pipeline"):
        try:
            module = importlib.import_module(name)
        except ModuleNotFoundError as exc:
            if exc.name != name:
                raise
            continue
        cases += module.CASES
    return cases


CASES = _cases()


def test_every_lesson_has_a_mutation() -> None:
    lessons = sorted(p.name for p in LESSONS.glob("[0-9][0-9]_*.ipynb"))
    covered = {lesson for lesson, _, _ in CASES}
    assert not set(lessons) - covered, f"lessons without a mutation: {sorted(set(lessons) - covered)}"
    assert covered <= set(lessons), f"mutations name lessons that do not exist: {sorted(covered - set(lessons))}"


@pytest.mark.parametrize(
    ("lesson", "switch", "message"), CASES, ids=[f"{lesson[:2]}-{switch.__name__}" for lesson, switch, _ in CASES]
)
def test_lesson_fails_with_the_method_broken(lesson: str, switch: Switch, message: str | None, monkeypatch, mocap_dir):
    monkeypatch.setenv("MOCAPLAB_FAST", "1")
    monkeypatch.setenv("MPLBACKEND", "Agg")
    switch(monkeypatch)
    assert os.environ["MOCAPLAB_FAST"] == "1"
    failed = first_failing_assert(lesson)
    assert failed is not None, f"{lesson} passes with {switch.__name__}: its asserts do not test the method"
    cell, exc = failed
    if message is not None:
        assert message in str(exc), f"{lesson} cell {cell} failed on another assert: {exc}"
