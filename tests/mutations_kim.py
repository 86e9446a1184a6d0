"""Mutations of the Kim et al. 2009 lessons (01-07), run by ``test_lessons_falsifiable.py``.

Each case is ``(lesson, switch, message)``: ``switch(monkeypatch)`` breaks one
piece of the method, and the lesson must then fail an ``assert`` whose
message contains ``message`` (None: any assert).
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
import pytest

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


CASES: list[tuple[str, Callable[[pytest.MonkeyPatch], None], str | None]] = [
    (L03, no_flip_repair, "30 degrees per frame"),
    (L03, linear_relative, "in metres"),
    (L03, no_end_effectors, "hold the object"),
    (L05, linear_relative, "in metres"),
    (L05, no_discrete_transformations, "added frames"),
    (L07, no_discrete_transformations, "steps are added"),
]
