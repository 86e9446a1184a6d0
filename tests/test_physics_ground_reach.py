"""Which out-of-balance frames a ground adjustment balances exactly, and which take the closest approach (s3.3).

:func:`mocaplab.physics.ground_reach` splits the frames a ground adjustment
corrects that are out of balance into those where equation 7 has a
solution and those where the touch-up applies the closest-approach
rotation.  The claims: the split covers exactly those frames; the lower
body reaches every frame of a bent walk where the arms reach few; the
closest-approach frames still move toward the polygon in a step (they are
not given zero weight); the split does not depend on ``rho``, on the
history it is read from, nor on how the file names, roots, scales or
orients the skeleton.
"""

from __future__ import annotations

import warnings

import numpy as np
import pytest
from conventions import as_original
from test_physics_touchup import bend

from mocaplab.contacts import foot_contacts
from mocaplab.physics import FLIGHT_SCHEDULE, GROUND_SCHEDULE, GroundReach, ground_reach, start, step, touch_up

LOWER, UPPER, ARMS = GROUND_SCHEDULE


@pytest.fixture(scope="module")
def walk30(mocap_dir):
    from mocaplab import data

    return data.cmu("16_15").resample(30)


@pytest.fixture(scope="module")
def bent_state(walk30):
    """A walk bent into an arc of radius 2 m, ready for its first ground adjustment."""
    return start(bend(walk30, 2.0), contacts=foot_contacts(walk30))


def test_the_split_covers_the_corrected_frames_out_of_balance(bent_state):
    s = bent_state
    out = (s.balance.distance > 0) & s.interior
    edge = s.edge_frames
    counts = {}
    for adj in GROUND_SCHEDULE:
        reach = ground_reach(s, adj)
        assert isinstance(reach, GroundReach) and reach.adjustment is adj
        assert reach.exact.shape == reach.closest.shape == (s.motion.n_frames,)
        assert not np.any(reach.exact & reach.closest)
        np.testing.assert_array_equal(reach.exact | reach.closest, out)
        assert not reach.exact[:edge].any() and not reach.closest[-edge:].any()  # no adjustment corrects the ends
        assert not reach.exact.flags.writeable and not reach.closest.flags.writeable
        assert (reach.n_exact, reach.n_closest) == (int(reach.exact.sum()), int(reach.closest.sum()))
        counts[adj.label] = reach.n_exact, reach.n_closest
    # the lower body tilts the whole body far enough on every frame; the arms are too light for most
    assert counts[LOWER.label][1] == 0 and counts[LOWER.label][0] == out.sum() > 40, counts
    assert counts[ARMS.label][1] > 2 * counts[ARMS.label][0], counts


def test_the_closest_approach_frames_move_toward_the_polygon(bent_state):
    """Section 3.3: a frame no rotation of S2 balances still gets the rotation that brings its ZMP closest.

    Here the arms balance 23 frames exactly and 54 take the closest approach; their mean ZMP distance falls
    from 34.6 to 28.6 mm, 94 % of them closer.  Given zero weight (an earlier version), they keep it
    (42.5 -> 42.7 mm after the two steps before, weakened the same way).
    """
    s = step(step(bent_state))  # the lower body, then the upper body: the arms come next
    assert s.next_adjustment is ARMS
    reach = ground_reach(s)
    after = step(s)
    before_mm, after_mm = (1000 * np.mean(x.balance.distance[reach.closest]) for x in (s, after))
    assert reach.n_closest > 20
    assert after_mm < 0.9 * before_mm, (before_mm, after_mm)
    # frame by frame: most of them are closer to the polygon than before
    assert np.mean(after.balance.distance[reach.closest] < s.balance.distance[reach.closest]) > 0.7


def test_read_from_a_history_with_any_step_size(bent_state):
    """Each state of a history tells what the next step worked with; ``rho`` does not change the split."""
    h = touch_up(bent_state.reference, contacts=bent_state.contacts, iterations=2)
    for k, state in enumerate(h.states[:-1]):
        reach = ground_reach(state)
        assert reach.adjustment.label == h.states[k + 1].label
        weak = ground_reach(state, state.next_adjustment.replace(rho=0.05))
        np.testing.assert_array_equal(reach.exact, weak.exact)
        np.testing.assert_array_equal(reach.closest, weak.closest)
    # the frames out of balance shrink pass after pass, so the split is not fixed by the input
    first, last = ground_reach(h.states[0], ARMS), ground_reach(h.states[h.best], ARMS)
    assert last.n_exact + last.n_closest < first.n_exact + first.n_closest


def test_bad_input_names_what_was_expected(bent_state):
    before = np.array(bent_state.balance.distance)
    with pytest.raises(TypeError, match="Expected `state` to be a TouchUpState"):
        ground_reach(bent_state.motion)
    with pytest.raises(TypeError, match="Expected `adjustment` to be an Adjustment or None, got str"):
        ground_reach(bent_state, "arms")
    with pytest.raises(ValueError, match="Expected a ground adjustment, got the flight adjustment"):
        ground_reach(bent_state, FLIGHT_SCHEDULE[0])
    np.testing.assert_array_equal(bent_state.balance.distance, before)


@pytest.mark.parametrize("convention", ["mixamo", "game_studio", "centimetres", "z_up"])
def test_the_same_split_under_another_file_convention(cmu, converted, convention):
    """Other joint names, a static root above the pelvis, centimetres, Z up: the same frames, no name passed."""
    frames = slice(0, 360)
    m, _ = converted("16_15", convention, frames)
    ref = as_original(cmu("16_15")[frames], convention)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # touch-up notes about the input
        s, s0 = start(m), start(ref)
    for adj in GROUND_SCHEDULE:
        a, b = ground_reach(s, adj), ground_reach(s0, adj)
        assert b.n_closest + b.n_exact > 100  # 144 frames out of balance; the arms reach 31 of them
        np.testing.assert_array_equal(a.exact, b.exact, err_msg=adj.label)
        np.testing.assert_array_equal(a.closest, b.closest, err_msg=adj.label)
