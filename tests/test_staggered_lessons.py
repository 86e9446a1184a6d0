"""Lessons 11-13 assert what they teach: switch the method off and they fail (STYLE 18).

Each case runs a lesson's code cells in this process (fast mode, Agg), in
order, with one piece of the method replaced by a do-nothing stand-in, and
expects an ``assert`` of the lesson to fail; any other exception is a broken
lesson and fails the test.  nbval runs the unmodified lessons (they pass).
Cells after the first failing assert are not run, so a case costs only the
lesson's prefix.
"""

from __future__ import annotations

import os
from collections.abc import Callable

import numpy as np
import pytest
from lesson_support import first_failing_assert

L11 = "11_staggered_pose_representation.ipynb"
L12 = "12_extracting_staggered_poses.ipynb"
L13 = "13_editing_staggered_poses.ipynb"


# ------------------------------------------------------------------ the switches
def identity_tangents(monkeypatch: pytest.MonkeyPatch) -> None:
    """Every fitted rotation tangent replaced by the identity (an ease-in/out spline through the knots)."""
    from mocaplab.staggered import fit

    real = fit.fit_rotation_tangents

    def identity(seg, tn, q, q1, q4, **options):
        _, _, info = real(seg, tn, q, q1, q4, **options)
        ident = np.tile([0.0, 0.0, 0.0, 1.0], (q1.shape[0], 1))
        return ident, ident.copy(), info

    monkeypatch.setattr(fit, "fit_rotation_tangents", identity)


def every_maximum(monkeypatch: pytest.MonkeyPatch) -> None:
    """Candidate poses at every local maximum of P (no merging, no prominence)."""
    from mocaplab.staggered import features

    real = features.candidate_poses
    monkeypatch.setattr(features, "candidate_poses", lambda p, **_: real(p))


def no_filter(monkeypatch: pytest.MonkeyPatch) -> None:
    """No rotation filter before fitting (section 6 switched off)."""
    from mocaplab.staggered import fit

    monkeypatch.setattr(fit, "orientation_filter", lambda q, sigma, fps: np.array(q, copy=True))


def fixed_stillness(monkeypatch: pytest.MonkeyPatch) -> None:
    """Appendix B with the paper's fixed 0.25 s, whatever the gait."""
    from mocaplab import contacts

    monkeypatch.setattr(contacts, "_gait_windows", lambda motion, travel, cap=0.25: np.full(
        motion.n_frames, max(2, int(round(cap * motion.fps)))
    ))


def no_constraint_layer(monkeypatch: pytest.MonkeyPatch) -> None:
    """The contact constraint layer leaves the motion as it is."""
    from mocaplab.staggered.edit import ConstraintLayer

    monkeypatch.setattr(ConstraintLayer, "apply", lambda self, sm, motion, t, staggered=True: motion)


CASES: list[tuple[str, Callable[[pytest.MonkeyPatch], None]]] = [
    (L11, identity_tangents),
    (L12, identity_tangents),
    (L13, identity_tangents),
    (L12, every_maximum),
    (L12, fixed_stillness),
    (L13, no_filter),
    (L13, no_constraint_layer),
]


@pytest.mark.parametrize(("lesson", "switch"), CASES, ids=[f"{n[:2]}-{s.__name__}" for n, s in CASES])
def test_lesson_fails_without_its_method(lesson: str, switch, monkeypatch, mocap_dir) -> None:
    monkeypatch.setenv("MOCAPLAB_FAST", "1")
    monkeypatch.setenv("MPLBACKEND", "Agg")
    switch(monkeypatch)
    failed = first_failing_assert(lesson)
    assert failed is not None, f"{lesson} passes with {switch.__name__}: its asserts do not test the method"
    assert os.environ["MOCAPLAB_FAST"] == "1"
