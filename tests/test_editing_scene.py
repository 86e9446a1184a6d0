"""edit() and SceneEditor: purity, editor/function agreement, full-body output on the shared clock."""

from __future__ import annotations

import numpy as np
import pytest

from mocaplab import quat
from mocaplab.editing import (
    AbsoluteTime,
    Duration,
    EndEffectorConstraint,
    PinDirection,
    PinPosition,
    Relative,
    SceneEditor,
    Sync,
    edit,
)


@pytest.fixture(scope="module")
def pair(mocap_dir):
    from mocaplab import data

    a = data.cmu("16_15").resample(30)
    b = data.cmu("02_01").resample(30).transformed(translation=[1.5, 0, 0])
    return [a, b]


def ground(m):
    return m.root_positions[:, [0, 2]]


def scene(pair):
    a, b = pair
    return [
        PinPosition(0, 0, ground(a)[0], hard=True),  # 0
        PinPosition(0, 100, ground(a)[100] + [0.6, 0.2]),  # 1
        PinDirection(1, 10, 0.2),  # 2
        Relative(1, 50, 0, 70, (0.2, 1.0)),  # 3
        AbsoluteTime(0, 0, 0.0, hard=True),  # 4
        Sync(1, 50, 0, 70, offset=0.1),  # 5
        Duration(1, 0, 80, 3.5),  # 6
    ]


def assert_same(r1, r2, atol=1e-8):
    for k in range(len(r1.paths)):
        np.testing.assert_allclose(r1.paths[k], r2.paths[k], atol=atol)
        np.testing.assert_allclose(r1.shape_paths[k], r2.shape_paths[k], atol=atol)
        np.testing.assert_allclose(r1.times[k], r2.times[k], atol=atol)


def test_inputs_never_mutated(pair):
    copies = [(np.array(m.rotations), np.array(m.root_positions)) for m in pair]
    cons = scene(pair)
    cons_before = list(cons)
    ed = SceneEditor(pair, cons)
    res = ed.drag(1, ground(pair[0])[100] + [1.5, -0.5])
    _ = res.motions[0], res.motions[1], res.edited_motions[1]
    for m, (rot, root) in zip(pair, copies, strict=True):
        np.testing.assert_array_equal(m.rotations, rot)
        np.testing.assert_array_equal(m.root_positions, root)
    assert cons == cons_before
    assert not res.paths[0].flags.writeable and not res.times[1].flags.writeable


@pytest.mark.parametrize(
    "index, target",
    [
        (1, (2.0, 1.5)),  # soft position pin
        (0, (0.3, -1.0)),  # hard position pin
        (2, (-0.4, 0.9)),  # direction
        (3, (0.5, -1.2)),  # relative offset (refactorises)
        (5, 0.6),  # sync offset
        (6, 2.0),  # duration
        (4, 1.25),  # hard absolute time
    ],
)
def test_drag_equals_edit_with_moved_constraint(pair, index, target):
    cons = scene(pair)
    ed = SceneEditor(pair, cons)
    n_fact = ed.factorizations
    for step in (0.25, 0.5, 1.0):  # a drag is a sequence of moves
        t = np.asarray(target, dtype=float)
        if t.ndim:
            base = np.asarray(cons[index].target, dtype=float)
            moved = tuple(base + step * (t - base))
        else:
            moved = float(cons[index].target) + step * (float(t) - float(cons[index].target))
        res = ed.drag(index, moved)
    ref = edit(pair, ed.constraints)
    assert_same(res, ref)
    expected = np.asarray(moved, dtype=float)
    if index == 2:
        expected = expected / np.linalg.norm(expected)
    np.testing.assert_allclose(ed.constraints[index].target, expected)
    if index != 3:
        assert ed.factorizations == n_fact  # only right-hand sides changed
    assert res.hard_residual_space < 1e-6 and res.hard_residual_time < 1e-6


def test_add_remove_replace(pair):
    cons = scene(pair)
    ed = SceneEditor(pair, cons[:3])
    i = ed.add(cons[3])
    assert i == 3
    assert_same(ed.result, edit(pair, cons[:4]))
    ed.remove(1)
    assert_same(ed.result, edit(pair, [cons[0], cons[2], cons[3]]))
    ed.replace(0, PinPosition(0, 0, (0.0, 0.0)))
    assert_same(ed.result, edit(pair, [PinPosition(0, 0, (0.0, 0.0)), cons[2], cons[3]]))
    with pytest.raises(IndexError):
        ed.drag(7, (0, 0))
    with pytest.raises(TypeError, match="option"):
        SceneEditor(pair, [], bogus=1)


def test_edited_motion_follows_path_and_turns_root(pair):
    res = edit(pair, scene(pair))
    for k, m in enumerate(pair):
        e = res.edited_motions[k]
        np.testing.assert_allclose(e.root_positions[:, [0, 2]], res.paths[k], atol=1e-12)
        np.testing.assert_allclose(e.root_positions[:, 1], m.root_positions[:, 1])  # height kept
        np.testing.assert_array_equal(e.rotations[:, 1:], m.rotations[:, 1:])
        turn = quat.yaw(e.rotations[:, 0]) - quat.yaw(m.rotations[:, 0])
        d = np.angle(np.exp(1j * (turn - res.heading_change[k])))
        np.testing.assert_allclose(d, 0.0, atol=1e-6)


def test_motions_play_synchronised_on_one_clock(pair):
    a, b = pair
    cons = scene(pair)
    cons[5] = Sync(1, 50, 0, 70, offset=0.0, hard=True)
    res = edit(pair, cons, clock_fps=30.0)
    N = len(res.clock)
    assert all(m.n_frames == N for m in res.motions)
    assert np.allclose(np.diff(res.clock), 1 / 30)
    t_meet = res.times[0][70]
    assert res.times[1][50] == pytest.approx(t_meet, abs=1e-6)
    n = int(round((t_meet - res.clock[0]) * 30))
    if abs(res.clock[n] - t_meet) < 1e-6:  # the meeting falls on a tick: both show their meeting frames
        np.testing.assert_allclose(
            res.motions[0].root_positions[n], res.edited_motions[0].root_positions[70], atol=1e-6
        )
        np.testing.assert_allclose(
            res.motions[1].root_positions[n], res.edited_motions[1].root_positions[50], atol=1e-6
        )
    # in general the sampled pose is the warp-interpolated one
    u0 = np.interp(res.clock, res.times[0], np.arange(a.n_frames))
    x0 = np.interp(u0, np.arange(a.n_frames), res.paths[0][:, 0])
    np.testing.assert_allclose(res.motions[0].root_positions[:, 0], x0, atol=1e-9)
    for k, t in enumerate(res.times):
        act = res.active[k]
        assert act.any() and np.all(res.clock[act] >= t[0] - 1e-9) and np.all(res.clock[act] <= t[-1] + 1e-9)


def test_motions_are_lazy(pair):
    ed = SceneEditor(pair, scene(pair))
    res = ed.drag(1, (1.0, 2.0))
    assert res.motions._items == {}  # nothing computed during the drag
    _ = res.motions[1]
    assert set(res.motions._items) == {1}


def test_identity_motion_round_trip(pair):
    a, _ = pair
    res = edit([a], [PinPosition(0, 5, ground(a)[5])])
    m = res.motions[0]
    assert m.n_frames == a.n_frames
    np.testing.assert_allclose(m.root_positions, a.root_positions, atol=1e-6)
    np.testing.assert_allclose(np.abs(np.sum(m.rotations * a.rotations, axis=-1)), 1.0, atol=1e-6)


def test_report_and_transformations(pair):
    res = edit(pair, scene(pair))
    rep = res.report()
    for key in (
        "hard_residual_space",
        "hard_residual_time",
        "soft_residual_space",
        "soft_residual_time",
        "shape_distortion",
        "length_change",
        "min_time_step",
    ):
        assert key in rep
    assert len(rep["length_change"]) == 2
    assert res.min_time_step > 0
    assert res.transformations == ()
    assert set(res.residuals()) == set(range(len(scene(pair))))


def test_end_effectors_recorded_and_refined(pair):
    from mocaplab import goals
    a, b = pair
    hand = a.global_positions()[40, a.skeleton.index("RightHand")] + [0.0, 0.1, 0.0]
    ee = goals.EndEffector("RightHand", 40, hand)
    cons = scene(pair) + [EndEffectorConstraint(0, ee)]
    ed = SceneEditor(pair, cons)
    res = ed.result
    assert len(res.end_effectors[0]) == 1 and res.end_effectors[1] == ()
    # an end effector does not touch the path solve
    assert_same(res, edit(pair, scene(pair)))
    out = res.refined()
    assert len(out) == 2 and out[0].n_frames == len(res.clock)
    n = res._tick(0, 40)
    got = out[0].global_positions()[n, a.skeleton.index("RightHand")]
    np.testing.assert_allclose(got, hand, atol=0.03)


def test_time_range_failures_are_not_called_step_bound_conflicts(pair):
    """A hard time out of numeric range fails as such in every monotonicity round; a real conflict with the
    time-step bounds keeps saying so."""
    from mocaplab.editing import ConstraintError

    a = pair[0]
    ed = SceneEditor([a], [AbsoluteTime(0, a.n_frames - 1, 1.0, hard=True)])
    for far in (1e15, 1e20, 1e100):  # beyond the scene's reach (timewarp.TIME_REACH), refused before solving
        with pytest.raises(ConstraintError, match=r"Expected `time` within \+-[0-9.]+ s \(10 times") as info:
            ed.drag(0, far)
        assert "cannot be met with time steps" not in str(info.value), far
        assert info.value.indices == (0,)
    with pytest.raises(ConstraintError, match=r"cannot be met with time steps within \[min_step, max_step\]"):
        edit([a], [AbsoluteTime(0, 40, 2.0, hard=True), AbsoluteTime(0, 60, 2.1, hard=True)])
