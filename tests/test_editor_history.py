"""Undo, redo, reset and checkpoints of the core editors (SceneEditor, DiscreteEditor) on real CMU clips.

One undo step is one gesture: consecutive drags of one constraint (an add
followed by drags of the constraint it added) until ``checkpoint()``; every
other successful edit is a step of its own; a failed edit records nothing.
Undo restores a state exactly: the same constraints and the very same
result (so paths, times and motions are bitwise those shown before).
"""

from __future__ import annotations

import gc
import weakref

import numpy as np
import pytest

from mocaplab.editing import (
    AbsoluteTime,
    ConstraintError,
    DiscreteEditor,
    PinPosition,
    Relative,
    SceneEditor,
    Sync,
    edit,
)

FPS = 30.0


@pytest.fixture(scope="module")
def walk(mocap_dir):
    from mocaplab import data

    return data.cmu("16_15").resample(FPS)


@pytest.fixture(scope="module")
def trio(mocap_dir, walk):
    """Three CMU characters: two walks side by side and a walk that stops."""
    from mocaplab import data

    b = data.cmu("02_01").resample(FPS).transformed(translation=(1.5, 0.0, 0.0))
    c = data.cmu("16_34").resample(FPS).transformed(translation=(-1.5, 0.0, 0.0))
    return [walk, b, c]


def ground(m):
    return m.pelvis_positions[:, [0, 2]]


def trio_constraints(trio):
    a, b, c = trio
    return [
        PinPosition(0, 0, ground(a)[0], hard=True),  # 0
        PinPosition(0, a.n_frames - 1, ground(a)[-1]),  # 1 (dragged)
        Relative(1, 40, 0, 40, (0.0, -1.5)),  # 2
        AbsoluteTime(0, 0, 0.0, hard=True),  # 3
        Sync(2, 30, 0, 60),  # 4
        PinPosition(2, 0, ground(c)[0], hard=True),  # 5
        PinPosition(2, c.n_frames - 1, ground(c)[-1]),  # 6 (dragged)
    ]


def frozen(result):
    """Copies of everything a view shows of a result: paths, times, full-body motions."""
    return (
        [np.array(p) for p in result.paths],
        [np.array(t) for t in result.times],
        [np.array(m.root_positions) for m in result.motions],
        [np.array(m.rotations) for m in result.motions],
    )


def assert_bitwise(result, copies):
    for got, want in zip(frozen(result), copies, strict=True):
        assert len(got) == len(want)
        for g, w in zip(got, want, strict=True):
            assert g.shape == w.shape and np.array_equal(g, w)


# ------------------------------------------------------------------ SceneEditor
def test_undo_restores_the_previous_result_exactly_on_several_characters(trio):
    cons = trio_constraints(trio)
    ed = SceneEditor(trio, cons)
    assert not ed.can_undo and not ed.can_redo
    first = ed.result
    first_copy = frozen(first)
    end_a = ground(trio[0])[-1]
    for s in np.linspace(0.1, 1.0, 6):  # one gesture: six drags of constraint 1
        ed.drag(1, end_a + s * np.array([1.2, -0.6]))
    ed.checkpoint()
    dragged = ed.result
    dragged_copy = frozen(dragged)
    assert not np.allclose(dragged.paths[0], first.paths[0]), "the drag moved character 0"
    end_c = ground(trio[2])[-1]
    for s in np.linspace(0.1, 1.0, 4):  # a second gesture on another constraint
        ed.drag(6, end_c + s * np.array([-0.8, 0.4]))
    ed.checkpoint()
    assert len(ed.undo_stack) == 3, "two gestures, two undo steps"

    back = ed.undo()
    assert back is dragged and ed.constraints == dragged.constraints
    assert_bitwise(back, dragged_copy)
    back = ed.undo()
    assert back is first and ed.constraints == tuple(cons)
    assert_bitwise(back, first_copy)
    assert not ed.can_undo and ed.can_redo
    with pytest.raises(IndexError, match="nothing to undo"):
        ed.undo()

    assert ed.redo() is dragged
    assert_bitwise(ed.result, dragged_copy)
    # the editor keeps working from the restored state: a drag agrees with a fresh solve
    res = ed.drag(1, end_a + np.array([0.3, 0.9]))
    assert not ed.can_redo, "a new edit drops the redo step"
    ref = edit(trio, ed.constraints)
    for k in range(3):
        np.testing.assert_allclose(res.paths[k], ref.paths[k], atol=1e-8)
        np.testing.assert_allclose(res.times[k], ref.times[k], atol=1e-8)


def test_reset_returns_to_the_initial_constraints_and_is_undoable(trio):
    cons = trio_constraints(trio)
    ed = SceneEditor(trio, cons)
    first = ed.result
    ed.drag(1, ground(trio[0])[-1] + [1.0, 0.0])
    ed.checkpoint()
    ed.remove(4)
    edited = ed.result
    n = len(ed.undo_stack)
    assert ed.reset() is first and ed.constraints == tuple(cons)
    assert len(ed.undo_stack) == n + 1 and ed.can_undo
    assert ed.undo() is edited and len(ed.constraints) == len(cons) - 1
    ed.reset()
    n = len(ed.undo_stack)
    ed.reset()  # already there: no empty step
    assert len(ed.undo_stack) == n


def test_add_then_drags_are_one_step_and_checkpoint_ends_a_gesture(walk):
    P = ground(walk)
    ed = SceneEditor([walk], [PinPosition(0, 0, P[0], hard=True)])
    before = ed.result
    i = ed.add(PinPosition(0, 60, P[60]))  # a press on the path ...
    for s in (0.2, 0.5, 0.8):
        ed.drag(i, P[60] + s)  # ... and a drag of the new pin
    ed.checkpoint()
    assert len(ed.undo_stack) == 2
    ed.drag(i, P[60] + 1.0)  # a later gesture on the same pin
    ed.drag(0, P[0] + 0.1)  # another constraint: a step of its own even without a checkpoint
    assert len(ed.undo_stack) == 4
    ed.undo()
    ed.undo()
    assert ed.undo() is before and len(ed.constraints) == 1, "one undo removes the pin pressed and dragged"


def _alive(refs):
    gc.collect()
    return [all(r() is not None for r in per) for per in refs]


def test_old_undo_states_release_their_motions_and_rebuild_them_bitwise(trio):
    """The history holds few built motions (memory), and an undo far back rebuilds them bitwise."""
    cons = trio_constraints(trio)
    ed = SceneEditor(trio, cons)
    end_a = ground(trio[0])[-1]
    results, copies, refs = [ed.result], [frozen(ed.result)], []
    refs.append([weakref.ref(m) for m in ed.result.motions] + [weakref.ref(m) for m in ed.result.edited_motions])
    for g in range(8):
        for s in np.linspace(0.1, 1.0, 5):  # one gesture: five drags (the merged ones take no place)
            ed.drag(1, end_a + (0.1 * g + s) * np.array([0.4, -0.2]))
        ed.checkpoint()  # the gesture ends: its relative constraints settle (the state's result)
        r = ed.result
        for m in r.motions:
            m.global_positions()
        results.append(r)
        copies.append(frozen(r))
        refs.append([weakref.ref(m) for m in r.motions] + [weakref.ref(m) for m in r.edited_motions])
    assert len(ed.undo_stack) == 9
    alive = _alive(refs)
    assert alive[-4:] == [True] * 4, "the few most recent states keep their motions (undo stays fast)"
    assert sum(alive) <= 4, f"older states release their built motions, got {alive}"

    assert ed.undo() is results[-2]
    assert ed.result.motions[0] is refs[-2][0](), "a recent undo reuses the very same built motions"
    while ed.can_undo:
        ed.undo()
    assert ed.result is results[0]
    assert_bitwise(ed.result, copies[0])
    for i in range(1, 9):
        assert ed.redo() is results[i]
        assert_bitwise(results[i], copies[i])
    assert sum(_alive(refs)) <= 4


def test_failed_edits_record_nothing_and_change_nothing(walk):
    P = ground(walk)
    F = walk.n_frames
    ed = SceneEditor([walk], [PinPosition(0, 0, P[0], hard=True), PinPosition(0, F - 1, P[-1], hard=True)])
    ed.drag(1, P[-1] + 0.5)
    ed.checkpoint()
    result, constraints, n = ed.result, ed.constraints, len(ed.undo_stack)
    copy = frozen(result)
    failures = [
        (IndexError, lambda: ed.drag(5, (0.0, 0.0))),
        (ValueError, lambda: ed.add(PinPosition(0, F + 10, P[0]))),  # frame out of range
        (ConstraintError, lambda: ed.add(PinPosition(0, 0, P[0] + 3.0, hard=True))),  # contradicts a hard pin
        (TypeError, lambda: ed.replace(0, "not a constraint")),
        (
            ConstraintError,
            lambda: ed.set_constraints(
                [PinPosition(0, 5, P[5], hard=True)] * 2 + [PinPosition(0, 5, P[5] + 1, hard=True)]
            ),
        ),
    ]
    for error, call in failures:
        with pytest.raises(error):
            call()
        assert ed.result is result and ed.constraints == constraints and len(ed.undo_stack) == n
    assert_bitwise(ed.result, copy)
    assert ed.undo() is not result and len(ed.undo_stack) == n


# ------------------------------------------------------------------ DiscreteEditor
def stretched(walk, factor):
    P = ground(walk)
    return [
        PinPosition(0, 0, P[0], hard=True),
        PinPosition(0, walk.n_frames - 1, P[0] + factor * (P[-1] - P[0]), hard=True),
    ]


@pytest.fixture(scope="module")
def stretched_once(walk):
    """A DiscreteEditor whose one drag gesture (10 moves, one checkpoint) inserted steps."""
    ed = DiscreteEditor([walk], stretched(walk, 1.0))
    first = ed.result
    first_copy = frozen(first)
    P = ground(walk)
    for s in np.linspace(0.05, 0.5, 10):
        ed.drag(1, P[0] + (1 + s) * (P[-1] - P[0]))
    ed.checkpoint()
    return ed, first, first_copy


def test_discrete_undo_removes_the_steps_a_drag_inserted(walk, stretched_once):
    ed, first, first_copy = stretched_once
    dragged = ed.result
    assert dragged.transformations and dragged.characters[0].n_frames > walk.n_frames
    applied, history, tracks = ed.applied, ed.history, ed.tracks
    dragged_copy = frozen(dragged)
    work = ed.factorizations
    assert len(ed.undo_stack) == 2, "the whole drag is one undo step"

    back = ed.undo()
    assert back is first and back.transformations == () and ed.applied == () and ed.history == ()
    assert back.characters[0].n_frames == walk.n_frames and ed.tracks[0].n_frames == walk.n_frames
    assert ed.constraints == tuple(stretched(walk, 1.0))
    assert_bitwise(back, first_copy)
    assert ed.scene.result.paths[0].shape == (walk.n_frames, 2), "the continuous editor is the untransformed one"
    assert ed.factorizations >= work, "factorizations count the work done; undo does not lower it"

    assert ed.redo() is dragged
    assert ed.applied == applied and ed.history == history and ed.tracks == tracks
    assert_bitwise(ed.result, dragged_copy)
    assert ed.reset() is first and ed.can_undo
    assert ed.undo() is dragged


def test_discrete_editor_keeps_working_after_undo(walk, stretched_once):
    ed, first, _ = stretched_once
    while ed.can_undo:
        ed.undo()
    assert ed.result is first
    P = ground(walk)
    res = ed.drag(1, P[0] + 0.8 * (P[-1] - P[0]))  # shorter: maybe a deletion, never the old insertion
    assert not ed.can_redo
    np.testing.assert_allclose(res.paths[0][-1], P[0] + 0.8 * (P[-1] - P[0]), atol=1e-6)
    mapped = ed.map_constraints(ed.constraints)
    ref = edit(
        [t.motion for t in ed.tracks],
        mapped,
        **{k: v for k, v in ed.options.items() if k != "stationary"},
        stationary=[list(s) for s in ed.scene.segments],
    )
    np.testing.assert_allclose(res.paths[0], ref.paths[0], atol=1e-8)
    ed.undo()
    assert ed.result is first


def test_discrete_reset_returns_to_the_untransformed_input(walk):
    """The constructor's greedy steps (max_initial) are one undo step: reset and undo reach the input clips."""
    cons = stretched(walk, 1.5)
    ed = DiscreteEditor([walk], cons)
    built = ed.result
    assert ed.applied and built.characters[0].n_frames != walk.n_frames, "the first update inserted steps"
    assert ed.can_undo and len(ed.undo_stack) == 2
    P = ground(walk)
    ed.drag(1, P[0] + 1.4 * (P[-1] - P[0]))
    ed.checkpoint()
    back = ed.reset()
    assert (
        back.transformations == () and ed.applied == () and ed.history == () and ed.tracks[0].n_frames == walk.n_frames
    )
    assert back.characters[0].n_frames == walk.n_frames and ed.constraints == tuple(cons)
    ref = edit([walk], cons)
    np.testing.assert_allclose(back.paths[0], ref.paths[0], atol=1e-9)
    np.testing.assert_allclose(back.times[0], ref.times[0], atol=1e-9)
    ed.undo()
    ed.undo()
    assert ed.result is built and ed.applied == built.transformations, "undo goes back to the greedy steps"
    assert ed.undo() is back and not ed.can_undo
    assert edit([walk], cons, discrete=True).transformations == built.transformations, "edit() keeps the steps"


def test_discrete_failed_edit_records_nothing(walk):
    ed = DiscreteEditor([walk], stretched(walk, 1.0))
    result, n = ed.result, len(ed.undo_stack)
    with pytest.raises(ValueError):
        ed.add(PinPosition(0, walk.n_frames + 3, (0.0, 0.0)))
    with pytest.raises(IndexError):
        ed.drag(9, (0.0, 0.0))
    assert ed.result is result and len(ed.undo_stack) == n and not ed.can_undo
