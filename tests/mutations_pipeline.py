"""Mutations of the lessons that combine the papers (14, 15), run by ``test_lessons_falsifiable.py``.

Each case is ``(lesson, switch, message)``: ``switch(monkeypatch)`` breaks one
piece of the method, and the lesson must then fail an ``assert`` whose
message contains ``message`` (None: any assert).

* Lesson 14 (your own motion capture) teaches what ``mocaplab.load`` and the
  joint roles do for a file in another convention: each switch removes one
  of them (the unit estimate, the frame-rate snap, the up axis found from
  the body, the travelling path joint, the names in role inference), or the
  refinement whose output the quality report judges; one makes lesson 12's pose
  probability depend on the root layout, which the comparison with the CMU clip
  catches.
* Lesson 15 (the capstone) teaches that the touch-up balances and the
  staggered-pose exaggeration stylises: each switch turns one of them off.
"""

from __future__ import annotations

import importlib
from collections.abc import Callable

import pytest
from mutations_shin import no_ground_adjustment

L14 = "14_your_own_motion_capture.ipynb"
L15 = "15_capstone.ipynb"


# ------------------------------------------------------------------ lesson 14
def no_unit_estimate(monkeypatch: pytest.MonkeyPatch) -> None:
    """A BVH file without ``scale=`` is read as metres: no unit is estimated from the figure's size."""
    from mocaplab.io import bvh

    monkeypatch.setattr(bvh, "estimate_scale", lambda skeleton: (1.0, "metres"))


def no_fps_snap(monkeypatch: pytest.MonkeyPatch) -> None:
    """``Frame Time: 0.0333333`` stays 30.0000003 fps: the loader does not snap rates."""
    load = importlib.import_module("mocaplab.io.load")  # the module, not the function mocaplab.io.load

    monkeypatch.setattr(load, "_snap_fps", lambda fps: fps)


def path_joint_is_joint_0(monkeypatch: pytest.MonkeyPatch) -> None:
    """The motion path follows joint 0 whatever the skeleton: a static root above the pelvis is not seen."""
    from mocaplab.motion import Motion

    monkeypatch.setattr(Motion, "path_joint", property(lambda self: 0))


def no_up_axis_detection(monkeypatch: pytest.MonkeyPatch) -> None:
    """The loader never looks at the body for the up axis: a Z-up file is read in its own axes."""
    load = importlib.import_module("mocaplab.io.load")

    monkeypatch.setattr(load, "find_up_axis", lambda motion, roles=None: None)


def refinement_off(monkeypatch: pytest.MonkeyPatch) -> None:
    """Refinement returns its input: an edited walk keeps the feet the path edit slid."""
    import mocaplab
    from mocaplab.editing import refinement

    def unchanged(motion, *args, **kwargs):
        return motion

    # mocaplab.refine first: resolving it lazily after the module's refine is patched would cache the stand-in
    # as the value to restore
    monkeypatch.setattr(mocaplab, "refine", unchanged, raising=False)
    monkeypatch.setattr(refinement, "refine", unchanged)


def role_names_ignored(monkeypatch: pytest.MonkeyPatch) -> None:
    """Role inference ignores the joint names, sides included (hierarchy and geometry only)."""
    from mocaplab import roles

    monkeypatch.setattr(roles, "_parse", lambda name: (None, "", None))


def pelvis_travel_unweighted(monkeypatch: pytest.MonkeyPatch) -> None:
    """The pose probability weighs only the root's travel: a pelvis travelling below a static root counts for nothing.

    On a CMU clip nothing changes (its only position variable is the root's); on the studio file the path's
    own position variable (``Hips.position``) loses the weight the root has on the CMU clip, so lesson 12's
    P(t) differs between the two layouts.
    """
    from mocaplab.staggered import features

    weights = features.signal_weights

    def root_only(trails, n_variables, *, root_weight=1.0):  # type: ignore[no-untyped-def]
        w = weights(trails, n_variables, root_weight=root_weight)
        w[trails.variable[(trails.kind == 0) & (trails.variable != 0)]] = 0.0
        return w

    monkeypatch.setattr(features, "signal_weights", root_only)


# ------------------------------------------------------------------ lesson 15
def no_exaggeration(monkeypatch: pytest.MonkeyPatch) -> None:
    """Exaggerating staggered poses changes nothing (the stylisation stage is the identity)."""
    from mocaplab import staggered

    monkeypatch.setattr(staggered, "exaggerate", lambda sm, *args, **kwargs: sm)


CASES: list[tuple[str, Callable[[pytest.MonkeyPatch], None], str | None]] = [
    (L14, no_unit_estimate, "the unit was found"),
    (L14, no_fps_snap, "exactly 30 fps"),
    (L14, path_joint_is_joint_0, "travelling pelvis"),
    (L14, role_names_ignored, "swapped"),
    (L14, no_up_axis_detection, "stands along Z"),
    (L14, refinement_off, "refinement plants them"),
    (L14, pelvis_travel_unweighted, "the same pose probability"),
    (L15, no_ground_adjustment, "lowers the mean ZMP distance"),
    (L15, no_exaggeration, "doubles the upper body"),
]
