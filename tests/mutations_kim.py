"""Mutations of the Kim et al. 2009 lessons (01-07), run by ``test_lessons_falsifiable.py``.

Each case is ``(lesson, switch, message)``: ``switch(monkeypatch)`` breaks one
piece of the method, and the lesson must then fail an ``assert`` whose
message contains ``message`` (None: any assert).
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
import pytest

L01 = "01_motion_data.ipynb"
L02 = "02_motion_paths.ipynb"
L03 = "03_laplacian_path_editing.ipynb"
L04 = "04_time_warping.ipynb"
L05 = "05_synchronized_characters.ipynb"
L06 = "06_full_body_refinement.ipynb"
L07 = "07_discrete_editing.ipynb"


# ------------------------------------------------------------------ the switches
def wrong_rotation_order(monkeypatch: pytest.MonkeyPatch) -> None:
    """Forward kinematics composes rotations child-first, ``Q_j = q_j Q_parent`` instead of ``Q_parent q_j``."""
    from mocaplab import kinematics, quat

    def fk(rotations, root_positions, offsets, parents, *, translations=None):  # noqa: ANN001, ANN202
        rotations = np.asarray(rotations, dtype=float)
        n_frames, n_joints = rotations.shape[:2]
        gq = np.empty_like(rotations)
        gp = np.empty((n_frames, n_joints, 3))
        gq[:, 0], gp[:, 0] = rotations[:, 0], root_positions
        for j in range(1, n_joints):
            p = parents[j]
            t = offsets[j] if translations is None else np.asarray(translations)[:, j]
            gp[:, j] = gp[:, p] + quat.rotate(gq[:, p], t)
            gq[:, j] = quat.mul(rotations[:, j], gq[:, p])
        return gq, gp

    monkeypatch.setattr(kinematics, "fk", fk)


def no_contacts(monkeypatch: pytest.MonkeyPatch) -> None:
    """Foot-contact detection finds no contact at all."""
    from mocaplab import contacts

    real = contacts.foot_contacts

    def none_found(motion, **kw):  # noqa: ANN001, ANN202
        found = real(motion, **kw)
        return contacts.Contacts(found.joints, np.zeros_like(found.mask), found.fps)

    monkeypatch.setattr(contacts, "foot_contacts", none_found)


def forward_difference_tangents(monkeypatch: pytest.MonkeyPatch) -> None:
    """Path tangents from the forward difference ``p[i+1] - p[i]`` instead of the central one."""
    from mocaplab.editing import paths

    def forward(positions):  # noqa: ANN001, ANN202
        p = np.asarray(positions, dtype=float)
        t = np.zeros_like(p)
        t[:-1] = p[1:] - p[:-1]
        t[-1] = t[-2] if len(p) > 1 else 0.0
        return t

    monkeypatch.setattr(paths, "central_tangents", forward)


def no_scale_compensation(monkeypatch: pytest.MonkeyPatch) -> None:
    """Phase 2 rescales no segment to its original length (equation 7 on the phase-1 segments)."""
    from mocaplab.editing import spatial

    def unscaled(self, pbar):  # noqa: ANN001, ANN202
        P = pbar.reshape(-1, 2)
        v = P[1:] - P[:-1]
        i = self._interior
        return (v[i] - v[i - 1]).reshape(-1), v

    monkeypatch.setattr(spatial.SpatialSolver, "_scale_terms", unscaled)


def no_flip_repair(monkeypatch: pytest.MonkeyPatch) -> None:
    """Section 4.2's tangent-flip detection finds nothing: the heading follows every flipped tangent."""
    from mocaplab.editing import flips

    monkeypatch.setattr(flips, "detect_tangent_flips", lambda t0, t1, **_: np.zeros(len(t0), bool))


def linear_relative(monkeypatch: pytest.MonkeyPatch) -> None:
    """Relative offsets in units of the tangent (equations 1-2 alone): no metric correction."""
    from mocaplab.editing import spatial

    monkeypatch.setattr(spatial, "metric_targets", lambda *args, **kw: None)


def no_relative_rows(monkeypatch: pytest.MonkeyPatch) -> None:
    """Relative constraints (equations 1-2) give no row: the characters are no longer tied in space."""
    from mocaplab.editing import scene
    from mocaplab.editing.constraints import Relative
    from mocaplab.editing.lsq import Rows

    real = scene.spatial_rows

    def dropped(c, *args, **kw):  # noqa: ANN001, ANN202
        return Rows([], [], np.zeros(0)) if isinstance(c, Relative) else real(c, *args, **kw)

    monkeypatch.setattr(scene, "spatial_rows", dropped)


def no_end_effectors(monkeypatch: pytest.MonkeyPatch) -> None:
    """End-effector constraints dropped before full-body refinement."""
    from mocaplab.editing import scene

    monkeypatch.setattr(scene, "_effectors", lambda constraints, K: tuple(() for _ in range(K)))


def no_monotonicity_rounds(monkeypatch: pytest.MonkeyPatch) -> None:
    """The time warp is solved once: no round turns a violated step into ``h_min`` (or ``h_max``)."""
    from mocaplab.editing import timewarp

    def one_round(self, f, bw, h):  # noqa: ANN001, ANN202
        r = self.Tth + (f.BwT @ bw if len(bw) else 0.0)
        kkt, hard = self._kkt(f, ())
        t = kkt.solve(r, np.concatenate([h[hard.keep], f.g]))
        hard.check(t, h, scale=self.extent)
        return t, ()

    monkeypatch.setattr(timewarp.TimeSolver, "solve", one_round)


def no_ik(monkeypatch: pytest.MonkeyPatch) -> None:
    """Two-bone IK returns the rotations it was given."""
    from mocaplab import goals, ik

    def unchanged(rotations, *args, **kw):  # noqa: ANN001, ANN202
        return np.array(rotations, dtype=float)

    monkeypatch.setattr(ik, "two_bone_ik", unchanged)
    monkeypatch.setattr(goals, "two_bone_ik", unchanged)


def no_goal_solver(monkeypatch: pytest.MonkeyPatch) -> None:
    """The IK layer of refinement (``solve_goals``) meets no goal: it returns the motion unchanged."""
    from mocaplab import goals

    monkeypatch.setattr(goals, "solve_goals", lambda motion, goals, **kw: motion)


def no_discrete_transformations(monkeypatch: pytest.MonkeyPatch) -> None:
    """Discrete editing finds no candidate: Algorithm 1 never changes a motion's structure."""
    from mocaplab.editing.discrete import editor

    monkeypatch.setattr(editor, "enumerate_transformations", lambda track, **kw: [])


def prune_keeps_nothing(monkeypatch: pytest.MonkeyPatch) -> None:
    """``discrete.prune`` as the lesson calls it keeps no candidate (the editor's own pruning still runs)."""
    from mocaplab.editing import discrete

    monkeypatch.setattr(discrete, "prune", lambda candidates, **kw: [])


CASES: list[tuple[str, Callable[[pytest.MonkeyPatch], None], str | None]] = [
    (L01, wrong_rotation_order, "forward kinematics by hand"),
    (L01, no_contacts, "the feet alternate"),
    (L02, forward_difference_tangents, "central difference"),
    (L03, no_scale_compensation, "scale compensation keeps the length"),
    (L03, no_flip_repair, "30 degrees per frame"),
    (L03, linear_relative, "in metres"),
    (L03, no_end_effectors, "hold the object"),
    (L04, no_monotonicity_rounds, "strictly increasing"),
    (L05, no_relative_rows, "in A's moving frame"),
    (L05, linear_relative, "in metres"),
    (L05, no_discrete_transformations, "added frames"),
    (L06, no_ik, "IK on targets from FK"),
    (L06, no_goal_solver, "skate per planted frame"),
    (L07, no_discrete_transformations, "steps are added"),
    (L07, prune_keeps_nothing, "chosen among the pruned candidates"),
]
