"""Mutations of the Coleman et al. 2008 lessons (11-13), run by ``test_lessons_falsifiable.py``.

Each case is ``(lesson, switch, message)``: ``switch(monkeypatch)`` breaks one
piece of the method, and the lesson must then fail an ``assert`` whose
message contains ``message`` (None: any assert).
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
import pytest

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

    monkeypatch.setattr(
        contacts,
        "_gait_windows",
        lambda motion, travel, cap=0.25: np.full(motion.n_frames, max(2, int(round(cap * motion.fps)))),
    )


def no_constraint_layer(monkeypatch: pytest.MonkeyPatch) -> None:
    """The contact constraint layer leaves the motion as it is."""
    from mocaplab.staggered.constraints import ConstraintLayer

    monkeypatch.setattr(ConstraintLayer, "apply", lambda self, sm, motion, t, staggered=True: motion)


CASES: list[tuple[str, Callable[[pytest.MonkeyPatch], None], str | None]] = [
    (L11, identity_tangents, "the fitted splines carry the motion"),
    (L12, identity_tangents, "the fitted splines carry the motion"),
    (L13, identity_tangents, "the fitted splines carry the motion (lesson 11)"),
    (L12, every_maximum, "no two poses closer than 50 ms"),
    (L12, fixed_stillness, "the run gets its stances"),
    (L13, no_filter, "filtering before timing edits keeps the noise from coming apart"),
    (L13, no_constraint_layer, "the constraint layer keeps planted feet planted"),
]
