"""Undo, redo and reset for the stateful editors (one history mechanism).

Every stateful editor in mocaplab (the scene editor behind the path and
time-track widgets, the discrete editor, the staggered-pose editor) keeps its
edits in an :class:`UndoStack` of immutable states.  The stack stores
whatever the editor calls a state (a snapshot tuple, a parameter record); it
never looks inside.

A drag sends many small edits of one handle.  They belong to one undo step:
:meth:`UndoStack.push` with a ``merge`` key replaces the newest state instead
of adding one when the key equals the previous push's key, and
:meth:`UndoStack.checkpoint` (called when a gesture ends) stops the merging.

Reset is itself an edit: it pushes the initial state, so a reset can be
undone.  Redo states are dropped by any new push, as in every editor users
know.

Example
-------
>>> s = UndoStack("a")
>>> s.push("b"); s.push("c")
>>> s.undo(), s.undo(), s.can_undo
('b', 'a', False)
>>> s.redo()
'b'
"""

from __future__ import annotations

from collections.abc import Hashable
from typing import Any, Generic, TypeVar

T = TypeVar("T")

__all__ = ["UndoStack", "Undoable"]


class UndoStack(Generic[T]):
    """A linear history of states with undo, redo, reset and merged gestures.

    Parameters
    ----------
    initial : state
        The state :meth:`reset` returns to.
    limit : int, optional
        Most states kept (the oldest are forgotten, never the initial one).
    """

    def __init__(self, initial: T, *, limit: int = 500) -> None:
        if isinstance(limit, bool) or not isinstance(limit, int) or limit < 2:
            raise ValueError(f"Expected `limit` to be an integer >= 2, got {limit!r}")
        self._initial = initial
        self._states: list[T] = [initial]
        self._index = 0
        self._limit = limit
        self._merge: Hashable | None = None

    @property
    def initial(self) -> T:
        return self._initial

    @property
    def current(self) -> T:
        return self._states[self._index]

    @property
    def can_undo(self) -> bool:
        return self._index > 0

    @property
    def can_redo(self) -> bool:
        return self._index < len(self._states) - 1

    def __len__(self) -> int:
        """Number of states held (the current one included)."""
        return len(self._states)

    def push(self, state: T, *, merge: Hashable | None = None) -> None:
        """Record ``state`` as the newest; drops every redo state.

        With ``merge`` equal to the previous push's (not None, no
        :meth:`checkpoint` between), ``state`` replaces the newest state.
        """
        del self._states[self._index + 1 :]
        if merge is not None and merge == self._merge and self._index > 0:
            self._states[self._index] = state
        else:
            self._states.append(state)
            if len(self._states) > self._limit:
                del self._states[1]
            self._index = len(self._states) - 1
        self._merge = merge

    def checkpoint(self) -> None:
        """End a gesture: the next push adds a state even with the same ``merge`` key."""
        self._merge = None

    def amend(self, state: T) -> None:
        """Replace the current state by ``state``, the same edit completed (no new step, redo states kept)."""
        self._states[self._index] = state
        if self._index == 0:
            self._initial = state

    def undo(self) -> T:
        """Step back one state and return it; :class:`IndexError` when there is none."""
        if not self.can_undo:
            raise IndexError("nothing to undo")
        self._index -= 1
        self._merge = None
        return self._states[self._index]

    def redo(self) -> T:
        """Step forward one state and return it; :class:`IndexError` when there is none."""
        if not self.can_redo:
            raise IndexError("nothing to redo")
        self._index += 1
        self._merge = None
        return self._states[self._index]

    def reset(self) -> T:
        """Push the initial state (an undoable edit) and return it."""
        self.push(self._initial)
        self._merge = None
        return self._initial

    def __repr__(self) -> str:
        return f"<UndoStack: state {self._index} of {len(self._states)}>"


class Undoable:
    """The undo API every stateful editor offers, over its :attr:`undo_stack`.

    A class sets ``self.undo_stack`` (an :class:`UndoStack` of its states) and
    implements :meth:`_go` (make a state current, return what the editor
    returns after an edit) and :meth:`_here` (that value now); it may
    override :meth:`_at_start` and :meth:`_gesture_ended`.
    """

    undo_stack: UndoStack[Any]

    def _go(self, state: Any) -> Any:  # pragma: no cover - each editor implements it
        raise NotImplementedError

    def _here(self) -> Any:  # pragma: no cover - each editor implements it
        raise NotImplementedError

    def _at_start(self) -> bool:
        """Whether the editor is in its initial state (reset then records nothing)."""
        return self.undo_stack.current is self.undo_stack.initial

    def _gesture_ended(self) -> None:
        """Called by :meth:`checkpoint` after the stack's own (editor bookkeeping)."""

    @property
    def can_undo(self) -> bool:
        """Whether :meth:`undo` has a step to undo."""
        return self.undo_stack.can_undo

    @property
    def can_redo(self) -> bool:
        """Whether :meth:`redo` has an undone step to redo."""
        return self.undo_stack.can_redo

    def checkpoint(self) -> None:
        """End a gesture: the next edit starts a new undo step."""
        self.undo_stack.checkpoint()
        self._gesture_ended()

    def undo(self) -> Any:
        """Go back one undo step; :class:`IndexError` when there is none."""
        return self._go(self.undo_stack.undo())

    def redo(self) -> Any:
        """Redo the step undone last; :class:`IndexError` when there is none."""
        return self._go(self.undo_stack.redo())

    def reset(self) -> Any:
        """Back to the initial state (an undoable step; none when already there)."""
        if not self._at_start():
            return self._go(self.undo_stack.reset())
        return self._here()
