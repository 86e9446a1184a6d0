"""Incremental refinement: after a drag only the characters whose path or timing changed are refined again."""

from __future__ import annotations

import numpy as np
import pytest

from mocaplab.editing import PinPosition, SceneEditor
from mocaplab.goals import EndEffector, RelativeTo


@pytest.fixture(scope="module")
def four(mocap_dir):
    from mocaplab import data

    walk = data.cmu("16_15").resample(30)[:90]
    return [walk.transformed(yaw=0.4 * k, translation=[2.5 * k, 0.0, 0.0]) for k in range(4)]


def pins(chars):
    out = []
    for k, m in enumerate(chars):
        p = m.root_positions[:, [0, 2]]
        out += [PinPosition(k, 0, p[0], hard=True), PinPosition(k, 80, p[80])]
    return out


def test_drag_refines_only_the_dragged_character(four):
    ed = SceneEditor(four, pins(four))
    before = list(ed.result.refined())
    moved = np.asarray(ed.constraints[3].position) + [0.4, -0.3]  # character 1's end pin
    after = list(ed.drag(3, moved).refined())
    for k in (0, 2, 3):
        assert after[k] is before[k], f"character {k} was refined again though its path did not move"
    assert after[1] is not before[1]
    scratch = SceneEditor(four, list(ed.constraints)).result.refined()[1]
    assert np.abs(after[1].global_positions() - scratch.global_positions()).max() < 1e-6
    # and the reused motions are what a fresh refinement gives
    fresh = SceneEditor(four, list(ed.constraints)).result.refined()
    for k in (0, 2, 3):
        np.testing.assert_allclose(after[k].global_positions(), fresh[k].global_positions(), atol=1e-9)


def test_tolerance_zero_and_a_moved_neighbour(four):
    ed = SceneEditor(four, pins(four), refine_tolerance=0.0)
    before = list(ed.result.refined())
    after = list(ed.drag(3, np.asarray(ed.constraints[3].position) + [0.4, -0.3]).refined())
    # decoupled characters: their paths are unchanged to the bit or within 1e-12 m; tolerance 0 still reuses
    # what did not move at all and refines what moved
    assert after[1] is not before[1]
    changed = [k for k in (0, 2, 3) if np.abs(ed.result.paths[k] - SceneEditor(four, pins(four)).result.paths[k]).max() > 0]
    for k in (0, 2, 3):
        assert (after[k] is before[k]) == (k not in changed)


@pytest.mark.filterwarnings("ignore:end effector target:UserWarning")  # the drag takes character 2 out of reach
def test_characters_tied_by_end_effectors_refine_together(four):
    a, b = four[0], four[2]
    gap = a.global_positions()[40, a.skeleton.index("RightHand")] - b.global_positions()[40, b.skeleton.index("LeftHand")]
    hand = EndEffector("RightHand", 40, RelativeTo("LeftHand", offset=gap + [0.05, 0.0, 0.0], character=2), character=0)
    cons = [*pins(four), hand]
    ed = SceneEditor(four, cons)
    before = list(ed.result.refined())
    after = list(ed.drag(5, np.asarray(ed.constraints[5].position) + [0.3, 0.2]).refined())  # character 2 moves
    assert after[2] is not before[2] and after[0] is not before[0], "character 0 follows character 2's hand"
    assert after[1] is before[1] and after[3] is before[3]
    fresh = SceneEditor(four, list(ed.constraints)).result.refined()
    for k in range(4):
        np.testing.assert_allclose(after[k].global_positions(), fresh[k].global_positions(), atol=1e-6)


def test_bad_tolerance(four):
    with pytest.raises(ValueError, match="refine_tolerance"):
        SceneEditor(four[:1], refine_tolerance=-1.0)
