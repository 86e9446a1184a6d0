"""Path edits on real captures add no one-frame pop, or say where the constraints force one (issue 23).

A user's bend (``tests/pipeline.py``: first frame hard, the middle dragged
sideways, the last soft) of 8-second trims of the shared real files and of
CMU clips, judged by :func:`mocaplab.quality.compare`: no joint may move more
in one frame than 1.5x the input's largest one-frame move + 2 mm.  Where a
rigid stationary segment is dragged away from a hard pin beside it, the jump
is the constraints' and :class:`~mocaplab.editing.PathJumpWarning` names it.
"""

from __future__ import annotations

import os
import warnings
from pathlib import Path

import numpy as np
import pytest
from pipeline import _pins, trimmed

import mocaplab as ml
from mocaplab import quality
from mocaplab.editing import PathJumpWarning

#: clip -> the frames of the jump the constraints force (None: no jump allowed)
CLIPS = {
    "optitrack_mda/test_optitrack": None,  # standing: the heading turned -110 degrees in one frame
    "pybvh/bvh_test1": None,  # LeftFoot 22.6 -> 146 mm/frame at a segment boundary
    "bvhtoolbox/test_mocapbank": (120, 121),  # two rigid segments pulled apart across a 9-frame gap
    "perfume/A_test": (0, 1),  # a rigid segment from frame 2 dragged away from the hard pin at frame 0
    "16_15": None,
    "05_02": None,
}


def _load(label: str):
    path = Path(os.environ["MOCAPLAB_DATA_DIR"]) / "realworld" / f"{label}.bvh"
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        motion = ml.load(path) if path.is_file() else ml.cmu(label)
    return trimmed(motion, 8.0)


@pytest.mark.parametrize("label", list(CLIPS))
def test_a_bend_adds_no_pop_or_names_the_forced_jump(label, mocap_dir):
    motion = _load(label)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        out = ml.edit([motion], _pins(motion, bend=0.25, squeeze=0.0)).motions[0]
    jumps = [str(w.message) for w in caught if issubclass(w.category, PathJumpWarning)]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        row = quality.compare(motion, out)["displacement"]
    forced = CLIPS[label]
    if forced is None:
        assert not jumps, jumps
        assert not quality.Limit(1.5, 2.0).exceeded(row.before, row.after), (
            f"{label}: one-frame move {row.before:.1f} -> {row.after:.1f} mm at {row.where}"
        )
    else:
        assert len(jumps) == 1 and f"between frames {forced[0]} and {forced[1]}" in jumps[0], jumps
        assert "rigid stationary segment" in jumps[0] and "hard=False" in jumps[0]


def test_a_standing_clip_keeps_its_heading_smooth(mocap_dir):
    # optitrack stands still for most of its 8 s: its rigid segments' rotations are set by millimetres of sway,
    # and the heading once followed them (-110.6 degrees in one frame at 6 -> 7)
    motion = _load("optitrack_mda/test_optitrack")
    res = ml.edit([motion], _pins(motion, bend=0.25, squeeze=0.0))
    turn = np.degrees(np.abs(np.diff(res.heading_change[0])))
    assert turn.max() <= ml.editing.flips.TURN_RATE / motion.fps + 1e-9
    # the long standing segment turns as one (planted feet stay planted) away from its blended ends
    a, b = res.stationary[0][-1]
    middle = res.heading_change[0][a + motion.n_frames // 8 : b - motion.n_frames // 8]
    assert np.ptp(middle) < 1e-9


def test_a_hard_pin_built_from_a_static_root_is_named():
    # a studio layout: a static reference root above a travelling pelvis; a pin taken from root_positions
    # lands on the reference joint, metres from the walk: the edit says which joint the pins must come from
    from mocaplab.editing import PinPosition, edit
    from mocaplab.editing.scene import PinPlacementWarning

    sk = ml.Skeleton(
        ["Root", "Hips"], [-1, 0], [[0, 0, 0], [0, 1, 0]],
        channels=(("Xposition", "Yposition", "Zposition"), ("Xposition", "Yposition", "Zposition")),
    )
    walk = np.column_stack([np.linspace(0, 3, 60), np.zeros(60), np.zeros(60)])
    trans = np.zeros((60, 2, 3))
    trans[:, 1] = walk + [0, 1, 0]
    m = ml.Motion(sk, np.tile([0, 0, 0, 1.0], (60, 2, 1)), np.zeros((60, 3)), 30, translations=trans)
    with pytest.warns(PinPlacementWarning, match=r"static root joint 'Root'.*path joint 'Hips'.*pelvis_positions"):
        edit([m], [PinPosition(0, 59, m.root_positions[59, [0, 2]], hard=True)], stationary="speed")
    with warnings.catch_warnings():
        warnings.simplefilter("error", PinPlacementWarning)
        # the right pins, and a deliberate 1.5 m drag of the path point, say nothing
        edit([m], [PinPosition(0, 59, m.pelvis_positions[59, [0, 2]] + [0.0, 1.5], hard=True)], stationary="speed")
