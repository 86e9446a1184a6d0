"""Constraint objects (Kim et al. 2009, sections 3.1 and 3.2) and their validation."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from mocaplab.editing import (
    AbsoluteTime,
    ConstraintError,
    Duration,
    PinDirection,
    PinPosition,
    Relative,
    SceneEditor,
    Sync,
    edit,
)


def test_constructors_take_character_first():
    p = PinPosition(1, 10, (1.0, 2.0), hard=True)
    assert (p.character, p.frame, p.position, p.hard, p.weight) == (1, 10, (1.0, 2.0), True, 1.0)
    d = PinDirection(0, 5, np.pi / 2)
    assert d.direction == pytest.approx((1.0, 0.0))  # yaw angle -> unit (x, z)
    assert PinDirection(0, 5, (0.0, 3.0)).direction == (0.0, 1.0)
    # a Relative's direction is local (forward, left): angle a -> (cos a, sin a), 0 = the same way as `other`
    r = Relative(0, 3, 1, 4, (0.5, -1.0), direction=0.0)
    assert r.characters == (0, 1) and r.direction == pytest.approx((1.0, 0.0))
    assert Relative(0, 3, 1, 4, (0.5, -1.0), direction=np.pi).direction == pytest.approx((-1.0, 0.0))
    assert Relative(0, 3, 1, 4, (0.5, -1.0), direction=np.pi / 2).direction == pytest.approx((0.0, 1.0))
    assert Relative(0, 3, 1, 4, (0.5, -1.0), direction=(0.0, -2.0)).direction == pytest.approx((0.0, -1.0))
    assert AbsoluteTime(0, 2, 1.5).time == 1.5
    assert Duration(0, 2, 20, 1.0).duration == 1.0
    s = Sync(0, 2, 1, 7, offset=0.25)
    assert s.offset == 0.25 and s.characters == (0, 1)


def test_frozen_and_with_target():
    p = PinPosition(0, 10, (1.0, 2.0))
    with pytest.raises(dataclasses.FrozenInstanceError):
        p.frame = 3  # type: ignore[misc]
    q = p.with_target((3.0, 4.0))
    assert q.position == (3.0, 4.0) and p.position == (1.0, 2.0)
    assert q.structure() == p.structure()  # a drag keeps the matrix
    r = Relative(0, 3, 1, 4, (0.5, 0.0))
    assert r.with_target((1.0, 0.0)).structure() != r.structure()  # offsets live in the matrix
    assert Sync(0, 1, 1, 1).with_target(0.5).offset == 0.5
    assert Duration(0, 1, 9, 1.0).with_target(2.0).duration == 2.0
    assert AbsoluteTime(0, 1, 1.0).target == 1.0


def test_variational_samples_every_tenth_frame():
    p = PinPosition(0, position=(0.0, 0.0), frames=(5, 33))  # half-open: frames 5..32
    assert p.variational
    assert p.samples() == [(5,), (15,), (25,), (32,)]
    r = Relative(0, other=1, offset=(1.0, 0.0), frames=(0, 21), other_frames=(100, 141))
    assert r.samples() == [(0, 100), (10, 120), (20, 140)]
    s = Sync(0, other=1, frames=(0, 21))
    assert s.samples() == [(0, 0), (10, 10), (20, 20)]


def test_variational_constraints_by_keyword_equal_the_positional_none_form():
    # no positional None needed; the old spelling still works and means the same
    assert PinPosition(0, position=(1.0, 2.0), frames=(5, 32)) == PinPosition(0, None, (1.0, 2.0), frames=(5, 32))
    assert PinDirection(0, direction=0.3, frames=(5, 32)) == PinDirection(0, None, 0.3, frames=(5, 32))
    assert AbsoluteTime(0, time=1.0, frames=(5, 32)) == AbsoluteTime(0, None, 1.0, frames=(5, 32))
    r = Relative(1, other=0, offset=(0.0, 0.6), direction=np.pi, frames=(40, 91), hard=True)
    assert r == Relative(1, None, 0, None, (0.0, 0.6), direction=np.pi, frames=(40, 91), hard=True)
    assert Sync(1, other=0, frames=(40, 91)) == Sync(1, None, 0, None, frames=(40, 91))
    # intervals are half-open, everywhere: (40, 91) samples 40 and 90
    assert r.samples()[0] == (40, 40) and r.samples()[-1] == (90, 90)


def test_both_ends_included_only_by_name():
    # one convention (half-open); the inclusive form is its own keyword, stored as the half-open one
    assert PinPosition(0, position=(1.0, 2.0), frames_inclusive=(5, 32)) == PinPosition(0, position=(1.0, 2.0), frames=(5, 33))
    r = Relative(1, other=0, offset=(0.0, 0.6), frames_inclusive=(40, 90), other_frames_inclusive=(10, 60))
    assert (r.frames, r.other_frames) == ((40, 91), (10, 61)) and r.samples()[-1] == (90, 60)
    assert Sync(1, other=0, frames_inclusive=(0, 20)).samples() == Sync(1, other=0, frames=(0, 21)).samples()
    assert AbsoluteTime(0, time=1.0, frames_inclusive=(5, 32)).frames == (5, 33)
    with pytest.raises(TypeError, match="not both"):
        PinPosition(0, position=(1.0, 2.0), frames=(5, 33), frames_inclusive=(5, 32))
    with pytest.raises(ValueError, match="frames_inclusive"):
        PinPosition(0, position=(1.0, 2.0), frames=(5, 6))  # one frame: the hint names the inclusive keyword


@pytest.mark.parametrize(
    "make, message",
    [
        (lambda: PinPosition(0, 10), "missing `position`"),
        (lambda: PinDirection(0, frames=(1, 5)), "missing `direction`"),
        (lambda: Relative(0, 10, offset=(0, 0)), "missing `other`"),
        (lambda: Relative(0, 10, 1, 12), "missing `offset`"),
        (lambda: AbsoluteTime(0, 10), "missing `time`"),
        (lambda: Sync(0, 10), "missing `other`"),
    ],
)
def test_missing_arguments_are_named(make, message):
    with pytest.raises(TypeError, match=message):
        make()


def test_end_effector_constraint_frames_mean_what_the_goal_layer_means():
    from mocaplab import goals
    from mocaplab.editing import EndEffectorConstraint
    from mocaplab.editing.constraints import effector_frames

    # the same tuple means the same frames in an EndEffectorConstraint and in a goals.EndEffector
    c = EndEffectorConstraint(1, joint="RightHand", frames=(10, 20), target=(0.0, 1.0, 0.0))
    ee = goals.EndEffector("RightHand", (10, 20), (0.0, 1.0, 0.0))
    assert c.frames == (10, 20) and c.constraint.character == 1
    assert effector_frames(c, 100) == [(10, 20)] == ee.intervals(100)  # 10 frames, 10..19
    assert c.constraint.intervals(100) == [(10, 20)]
    both = EndEffectorConstraint(1, joint="RightHand", frames_inclusive=(10, 19), target=(0.0, 1.0, 0.0))
    assert both.frames == (10, 20) and both.constraint.intervals(100) == [(10, 20)]
    one = EndEffectorConstraint(0, joint="RightHand", frame=7, target=(0.0, 1.0, 0.0))
    assert effector_frames(one, 100) == [(7, 8)]
    assert effector_frames(EndEffectorConstraint(2, ee), 100) == [(10, 20)]
    assert EndEffectorConstraint(2, ee).constraint.character == 2
    with pytest.raises(TypeError, match="not both"):
        EndEffectorConstraint(0, ee, frame=3)
    with pytest.raises(TypeError, match="joint="):
        EndEffectorConstraint(0, frame=3)
    with pytest.raises(ValueError, match="at least 1 frames"):
        EndEffectorConstraint(0, joint="RightHand", frames=(20, 10), target=(0.0, 1.0, 0.0))


@pytest.mark.parametrize(
    "make, message",
    [
        (lambda: PinPosition(0, None, (0, 0), frames=(10, 11)), "at least 2 frames"),
        (lambda: PinPosition(0, None, (0, 0)), "give `frame`"),
        (lambda: PinPosition(0, position=(0, 0)), "got neither"),
        (lambda: PinPosition(0, 1, (0, 0), frames=(1, 5)), "not both"),
        (lambda: PinPosition(0, -1, (0, 0)), "`frame` to be an integer >= 0"),
        (lambda: PinPosition(0, 1, (0, np.nan)), "position"),
        (lambda: PinPosition(0, 1, (0, 0), weight=0.0), "weight"),
        (lambda: PinDirection(0, 1, (0.0, 0.0)), "non-zero"),
        (lambda: Duration(0, 10, 10, 1.0), "Degenerate interval"),
        (lambda: Duration(0, 1, 10, -1.0), "duration"),
        (lambda: Sync(0, 4, 0, 4), "itself"),
        (lambda: Relative(0, 4, 1, None, (0, 0)), "other_frame"),
    ],
)
def test_bad_constraints_are_named(make, message):
    with pytest.raises((ValueError, TypeError), match=message):
        make()


def test_character_index_type():
    with pytest.raises(TypeError, match="character"):
        PinPosition("a", 1, (0, 0))  # type: ignore[arg-type]


@pytest.fixture(scope="module")
def walks(mocap_dir):
    from mocaplab import data

    return [data.cmu("16_15").resample(30), data.cmu("02_01").resample(30)]


def test_scene_errors_name_the_constraint(walks):
    n = walks[0].n_frames
    with pytest.raises(ValueError, match=rf"constraint #1 .*frame {n + 5} out of range for character 0"):
        edit(walks, [PinPosition(0, 0, (0, 0)), PinPosition(0, n + 5, (0, 0))])
    with pytest.raises(ValueError, match="constraint #0 .*unknown character 2"):
        edit(walks, [Sync(0, 3, 2, 3)])
    with pytest.raises(TypeError, match="constraint #0"):
        edit(walks, ["pin"])


def test_conflicting_hard_constraints_raise_naming_them(walks):
    p0 = tuple(walks[0].root_positions[10, [0, 2]])
    cons = [
        PinPosition(0, 0, p0, hard=True),
        PinPosition(1, 4, (0.0, 0.0)),
        PinPosition(0, 10, p0, hard=True),
        PinPosition(0, 10, (p0[0] + 1, p0[1]), hard=True),
    ]
    with pytest.raises(ConstraintError) as info:
        edit(walks, cons)
    assert info.value.indices == (2, 3)
    assert "#2" in str(info.value) and "#3" in str(info.value) and "#0" not in str(info.value)
    times = [
        AbsoluteTime(1, 10, 0.0, hard=True),
        AbsoluteTime(1, 20, 1.0, hard=True),
        Duration(1, 10, 20, 2.0, hard=True),
    ]
    with pytest.raises(ConstraintError) as info:
        edit(walks, times)
    assert info.value.indices == (0, 1, 2)
    # a hard relative placement on a hard pin, and a hard pin of the placed character elsewhere
    rel = [
        PinPosition(0, 30, p0, hard=True),
        Relative(1, 5, 0, 30, (0.0, 0.0), hard=True),
        PinPosition(1, 5, (p0[0] + 0.3, p0[1]), hard=True),
    ]
    with pytest.raises(ConstraintError, match="0.3 m away") as info:
        edit(walks, rel)
    assert info.value.indices == (0, 1, 2)
    # the same placement twice is consistent
    assert edit(walks, rel[:2] + rel[1:2]).hard_residual_space < 1e-9


@pytest.fixture(scope="module")
def stop(mocap_dir):
    from mocaplab import data

    return data.cmu("16_34").resample(30)  # a walk that stops: a stationary segment at the end


def test_redundant_but_consistent_hard_constraints_are_accepted(walks, stop):
    from mocaplab.editing import MotionPath

    S = stop.root_positions[:, [0, 2]]
    ((a, b),) = SceneEditor(stop, []).segments[0]
    tangent = MotionPath.from_motion(stop).tangents
    cases = {
        "two hard pins at their places on one standing segment": [
            PinPosition(0, 0, S[0], hard=True),
            PinPosition(0, a + 5, S[a + 5], hard=True),
            PinPosition(0, b - 5, S[b - 5], hard=True),
        ],
        "a hard direction pin on a standing frame": [
            PinPosition(0, 0, S[0], hard=True),
            PinPosition(0, b - 1, S[b - 1], hard=True),
            PinDirection(0, a + 10, tangent[a + 10], hard=True),
        ],
        "the same hard pin twice": [
            PinPosition(0, 0, S[0], hard=True),
            PinPosition(0, 20, S[20], hard=True),
            PinPosition(0, 20, S[20], hard=True),
        ],
    }
    for name, cons in cases.items():
        res = edit(stop, cons)
        assert res.hard_residual_space < 1e-9, name
        assert res.notes and all("#2" in n and "redundant" in n for n in res.notes), (name, res.notes)
        np.testing.assert_allclose(res.paths[0], S, atol=1e-9, err_msg=name)  # every pin at its place: no change
    # time: t10, t20 and their duration, all consistent
    res = edit(stop, [AbsoluteTime(0, 10, 1.0, hard=True), AbsoluteTime(0, 20, 2.0, hard=True), Duration(0, 10, 20, 1.0, hard=True)])
    assert res.hard_residual_time < 1e-9 and any("#2" in n for n in res.notes)
    # nothing redundant, nothing noted
    assert edit(stop, cases["the same hard pin twice"][:2]).notes == ()


def test_redundant_hard_constraints_that_disagree_raise_naming_them(stop):
    S = stop.root_positions[:, [0, 2]]
    ((a, b),) = SceneEditor(stop, []).segments[0]
    cons = [
        PinPosition(0, 0, S[0], hard=True),
        PinPosition(0, a + 5, S[a + 5], hard=True),
        PinPosition(0, b - 5, S[b - 5], hard=True),
    ]
    ed = SceneEditor(stop, cons)
    before = ed.result
    # a standing segment moves rigidly: dragging one of its two hard pins away from the other cannot be met
    with pytest.raises(ConstraintError, match=r"rigid stationary segment of character 0.*#1") as info:
        ed.drag(2, S[b - 5] + [0.3, 0.0])
    assert info.value.indices == (1, 2)
    assert ed.result is before and ed.constraints == tuple(cons)  # the editor is unchanged
    # moving both pins together (a rigid motion) is fine
    res = ed.set_constraints([cons[0], cons[1].with_target(S[a + 5] + [0.3, 0.0]), cons[2].with_target(S[b - 5] + [0.3, 0.0])])
    assert res.hard_residual_space < 1e-7
    # the same pin twice with different targets
    with pytest.raises(ConstraintError, match="#2") as info:
        edit(stop, [cons[0], PinPosition(0, 20, S[20], hard=True), PinPosition(0, 20, S[20] + 0.1, hard=True)])
    assert info.value.indices == (1, 2)


def test_hard_constraints_against_time_step_bounds(walks):
    # 100 frames squeezed into 0.1 s needs steps below h_min
    with pytest.raises(ConstraintError, match="time steps within"):
        edit(walks, [AbsoluteTime(0, 0, 0.0, hard=True), AbsoluteTime(0, 100, 0.1, hard=True)])


def test_editor_keeps_state_after_error(walks):
    p = walks[0].root_positions[:, [0, 2]]
    ed = SceneEditor(walks, [PinPosition(0, 0, p[0], hard=True), PinPosition(0, 50, p[50])])
    before = ed.result
    with pytest.raises(ConstraintError):
        ed.add(PinPosition(0, 0, p[0] + 1, hard=True))
    assert len(ed.constraints) == 2
    again = ed.drag(1, p[50] + [0.3, 0.0])
    ref = edit(walks, [PinPosition(0, 0, p[0], hard=True), PinPosition(0, 50, p[50] + [0.3, 0.0])])
    np.testing.assert_allclose(again.paths[0], ref.paths[0], atol=1e-9)
    assert before.paths[0] is not again.paths[0]


def test_rank_screen_agrees_with_the_exact_rank():
    # the sparse Cholesky screen only clears full-row-rank hard rows; anything else goes to the SVD search
    import scipy.sparse as sp

    from mocaplab.editing.lsq import full_row_rank_screen

    rng = np.random.default_rng(3)
    for _ in range(20):
        m, n = rng.integers(2, 40), rng.integers(40, 80)
        H = sp.random(m, n, density=0.15, random_state=rng, format="csr") + sp.eye(m, n, format="csr")
        dense = H.toarray()
        assert full_row_rank_screen(H) == (np.linalg.matrix_rank(dense) == m)
        # a row that is a combination of two others, a repeated row, an empty row, too many rows
        i, j = rng.choice(m, 2, replace=False)
        for bad in (
            np.vstack([dense, 2.0 * dense[i] - 0.5 * dense[j]]),
            np.vstack([dense, dense[i]]),
            np.vstack([dense, np.zeros(n)]),
            np.vstack([dense, rng.standard_normal((n, n))]),
        ):
            assert not full_row_rank_screen(sp.csr_matrix(bad))


def test_hard_pins_over_constraining_a_rigid_segment_are_named(walks):
    # a stationary segment moves as a similarity in phase 1 (4 modes): two hard pins fix it, a third is redundant
    w = walks[0]
    P = w.root_positions[:, [0, 2]]
    cons = [PinPosition(0, 12, P[12], hard=True)] + [PinPosition(0, f, P[f], hard=True) for f in (15, 25, 35)]
    opts = {"stationary": [[(10, 40)]], "scale_compensation": False}
    ok = edit([w], cons, **opts)  # at their places: consistent, the redundant pin is noted
    assert ok.hard_residual_space < 1e-9 and len(ok.notes) == 2  # #2 and #3 are implied by the segment, #0 and #1
    bent = cons[:3] + [cons[3].with_target(P[35] + [0.0, 0.2])]
    with pytest.raises(ConstraintError, match="rigid stationary segment") as info:
        edit([w], bent, **opts)
    assert info.value.indices == (0, 1, 3)  # a minimal dependent set, with the segment
    assert edit([w], cons[:2], **opts).hard_residual_space < 1e-6


def _pins_in_long_segment(motion, middle_shift):
    p = motion.pelvis_positions[:, [0, 2]]
    n = motion.n_frames
    return [
        PinPosition(0, 0, p[0], hard=True),
        PinPosition(0, n // 2, p[n // 2] + np.asarray(middle_shift, float), hard=True),
        PinPosition(0, n - 1, p[-1], hard=True),
    ]


@pytest.mark.timeout(120)  # the diagnosis by dense rank tests took minutes; bench_laplacian times it
def test_hard_pins_fighting_a_long_rigid_segment_are_named_quickly(cmu):
    # 02_06 stands still for 2021 frames (one rigid stationary segment): a hard pin dragged 0.3 m inside it
    # cannot hold with the hard pin at frame 0 on the same rigid segment.  The diagnosis is made on the
    # segment's few free modes (bench_laplacian times it; dense rank tests on its rows took minutes)
    motion = cmu("02_06")
    result = edit([motion], [])
    segment = next((a, b) for a, b in result.stationary[0] if a <= motion.n_frames // 2 < b)
    assert segment[0] == 0 and segment[1] - segment[0] > 2000
    pins = _pins_in_long_segment(motion, (0.3, 0.0))
    with pytest.raises(ConstraintError) as info:
        edit([motion], pins)
    message = str(info.value)
    assert f"frames {segment[0]}-{segment[1] - 1}" in message and "rigid stationary segment" in message
    assert "#1" in message and "#0" in message and "soft" in message
    assert set(info.value.indices) == {0, 1}
    assert pins[1] in info.value.constraints and pins[0] in info.value.constraints


def test_consistent_hard_pins_on_a_long_rigid_segment_are_redundant_not_conflicting(cmu):
    motion = cmu("02_06")
    pins = _pins_in_long_segment(motion, (0.0, 0.0))
    result = edit([motion], pins)
    assert any("#1" in note and "redundant" in note for note in result.notes)
    assert result.hard_residual_space < 1e-6
    for pin in pins:
        np.testing.assert_allclose(result.paths[0][pin.frame], pin.position, atol=1e-6)
