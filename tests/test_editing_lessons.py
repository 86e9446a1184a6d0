"""Lessons 03, 05 and 07 assert what they teach: switch the method off and they fail (STYLE 18).

Each case runs a lesson's code cells in this process (fast mode, Agg), in
order, with one piece of the method replaced by a do-nothing stand-in, and
expects an ``assert`` of the lesson to fail; any other exception is a broken
lesson and fails the test.  nbval runs the unmodified lessons (they pass).
"""

from __future__ import annotations

import os
from collections.abc import Callable

import numpy as np
import pytest
from lesson_support import first_failing_assert

L03 = "03_laplacian_path_editing.ipynb"
L05 = "05_synchronized_characters.ipynb"
L07 = "07_discrete_editing.ipynb"


# ------------------------------------------------------------------ the switches
def no_flip_repair(monkeypatch: pytest.MonkeyPatch) -> None:
    """Section 4.2's tangent-flip detection finds nothing: the heading follows every flipped tangent."""
    from mocaplab.editing import laplacian

    monkeypatch.setattr(laplacian, "detect_tangent_flips", lambda t0, t1, **_: np.zeros(len(t0), bool))


def linear_relative(monkeypatch: pytest.MonkeyPatch) -> None:
    """Relative offsets in units of the tangent (equations 1-2 alone): no metric correction."""
    from mocaplab.editing import laplacian

    monkeypatch.setattr(laplacian, "metric_targets", lambda *args, **kw: None)


def no_end_effectors(monkeypatch: pytest.MonkeyPatch) -> None:
    """End-effector constraints dropped before full-body refinement."""
    from mocaplab.editing import scene

    monkeypatch.setattr(scene, "_effectors", lambda constraints, K: tuple(() for _ in range(K)))


def no_discrete_transformations(monkeypatch: pytest.MonkeyPatch) -> None:
    """Discrete editing finds no candidate: Algorithm 1 never changes a motion's structure."""
    from mocaplab.editing.discrete import editor

    monkeypatch.setattr(editor, "enumerate_transformations", lambda track, **kw: [])


CASES: list[tuple[str, Callable[[pytest.MonkeyPatch], None], str]] = [
    (L03, no_flip_repair, "30 degrees per frame"),
    (L03, linear_relative, "in metres"),
    (L03, no_end_effectors, "hold the object"),
    (L05, linear_relative, "in metres"),
    (L05, no_discrete_transformations, "added frames"),
    (L07, no_discrete_transformations, "steps are added"),
]


@pytest.mark.parametrize(
    "lesson, switch, message", CASES, ids=[f"{lesson[:2]}-{switch.__name__}" for lesson, switch, _ in CASES]
)
def test_lesson_fails_with_the_method_switched_off(lesson, switch, message, monkeypatch, mocap_dir):
    monkeypatch.setenv("MOCAPLAB_FAST", "1")
    monkeypatch.setenv("MPLBACKEND", "Agg")
    assert os.environ["MOCAPLAB_FAST"] == "1"
    switch(monkeypatch)
    failed = first_failing_assert(lesson)
    assert failed is not None, f"{lesson} passes with {switch.__name__}: its asserts do not test the method"
    cell, exc = failed
    assert message in str(exc), f"{lesson} cell {cell} failed on another assert: {exc}"
