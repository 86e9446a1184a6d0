"""The one undo mechanism (mocaplab.undo.UndoStack)."""

from __future__ import annotations

import pytest

from mocaplab.undo import UndoStack


def test_undo_redo_walks_the_history() -> None:
    s = UndoStack(0)
    for v in (1, 2, 3):
        s.push(v)
    assert [s.undo(), s.undo(), s.undo()] == [2, 1, 0]
    assert not s.can_undo and s.can_redo
    with pytest.raises(IndexError, match="nothing to undo"):
        s.undo()
    assert [s.redo(), s.redo(), s.redo()] == [1, 2, 3]
    with pytest.raises(IndexError, match="nothing to redo"):
        s.redo()


def test_push_drops_redo_states() -> None:
    s = UndoStack("a")
    s.push("b")
    s.push("c")
    s.undo()
    s.push("d")
    assert not s.can_redo and s.current == "d" and s.undo() == "b"


def test_a_gesture_is_one_step_until_checkpoint() -> None:
    s = UndoStack(0)
    for v in range(1, 20):
        s.push(v, merge=("drag", 3))
    assert len(s) == 2 and s.current == 19
    s.checkpoint()
    s.push(20, merge=("drag", 3))
    assert len(s) == 3 and s.undo() == 19 and s.undo() == 0
    # merging never overwrites the initial state
    t = UndoStack(0)
    t.push(1, merge="k")
    t.undo()
    t.push(2, merge="k")
    assert t.initial == 0 and t.undo() == 0


def test_reset_is_undoable_and_limit_keeps_initial() -> None:
    s = UndoStack(0, limit=3)
    for v in range(1, 6):
        s.push(v)
    assert len(s) == 3 and s.current == 5
    assert s.reset() == 0 and s.current == 0
    assert s.undo() == 5
    with pytest.raises(ValueError, match="limit"):
        UndoStack(0, limit=1)
