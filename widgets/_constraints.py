"""How the editing widgets read and name constraints (:mod:`.path_editor`, :mod:`.time_track`, :mod:`._drag`).

The constraints are the core's (:mod:`mocaplab.editing`); these helpers only
read them for display: their kind, frame and residual, and what an edit
from one constraint list to another did in words (:func:`constraint_change`,
the status after Undo / Redo / Reset).
"""

from __future__ import annotations

import dataclasses
import difflib
from collections.abc import Callable, Hashable, Sequence
from typing import Any

import numpy as np

from mocaplab import editing

__all__ = ["constraint_change", "core_residual", "frame_of", "is_a", "kind_of", "other_frame_of"]


def core_residual(result: Any, index: int) -> float | None:
    """The editor's own residual of constraint ``index`` (``EditResult.residuals()``), if it reports one."""
    residuals = getattr(result, "residuals", None)
    if not callable(residuals):
        return None
    value = residuals().get(index)
    return None if value is None else float(value)


def kind_of(constraint: Any) -> str:
    return type(constraint).__name__


def is_a(constraint: Any, name: str) -> bool:
    """Whether ``constraint`` is a ``mocaplab.editing.<name>`` (by class name if the editing module lacks it)."""
    cls = getattr(editing, name, None)
    return isinstance(constraint, cls) if cls is not None else kind_of(constraint) == name


def frame_of(constraint: Any) -> int:
    """The constraint's frame (the first frame of a variational constraint)."""
    frame = getattr(constraint, "frame", None)
    if frame is None:
        frame = constraint.frames[0]
    return int(frame)


def other_frame_of(constraint: Any) -> int:
    """The other character's frame of a Relative or Sync constraint (first of a variational one)."""
    frame = getattr(constraint, "other_frame", None)
    if frame is None:
        frame = constraint.other_frames[0]
    return int(frame)


#: What a status line calls each constraint (the class name for any other).
_NOUNS = {
    "PinPosition": "pin",
    "PinDirection": "direction pin",
    "Relative": "relative offset",
    "AbsoluteTime": "time handle",
    "Duration": "duration",
    "Sync": "sync",
}


def _constraint_key(c: Any) -> Hashable:
    """A value key of a constraint (equal keys: the same constraint), arrays compared by their bytes."""
    if not dataclasses.is_dataclass(c):
        return (type(c).__name__, repr(c))
    out: list[Hashable] = [type(c).__name__]
    for f in dataclasses.fields(c):
        value = getattr(c, f.name)
        arr = np.asarray(value) if not isinstance(value, str) else None
        if arr is None or arr.dtype == object:
            out.append((f.name, repr(value)))
        else:
            out.append((f.name, arr.shape, str(arr.dtype), arr.tobytes()))
    return tuple(out)


def constraint_change(old: Sequence[Any], new: Sequence[Any], *, who: Callable[[int], str] | None = None) -> str:
    """What an edit from constraint list ``old`` to ``new`` did, in words.

    ``"moved pin at frame 40 of character 0"``, ``"added time handle at
    frame 12 of character 1"``, ``"removed direction pin ..."``; several
    changes are joined with ``"; "`` (the first three, then how many more).

    Parameters
    ----------
    old, new : sequence of constraints
    who : callable, optional
        ``who(k)`` names character ``k`` (default ``"character k"``).

    Examples
    --------
    >>> from mocaplab.editing import PinPosition
    >>> a, b = PinPosition(0, 40, (0.0, 1.0)), PinPosition(0, 40, (0.5, 1.0))
    >>> constraint_change([a], [b]), constraint_change([a], []), constraint_change([], [a, b])
    ('moved pin at frame 40 of character 0', 'removed pin at frame 40 of character 0', 'added 2 pins')
    """
    name = who or (lambda k: f"character {k}")

    def phrase(c: Any) -> str:
        noun = _NOUNS.get(kind_of(c), kind_of(c))
        hard = "hard " if getattr(c, "hard", False) and noun == "pin" else ""
        return f"{hard}{noun} at frame {frame_of(c)} of {name(int(c.character))}"

    def many(verb: str, items: Sequence[Any]) -> list[str]:
        if len(items) > 1 and len({kind_of(c) for c in items}) == 1:
            return [f"{verb} {len(items)} {_NOUNS.get(kind_of(items[0]), kind_of(items[0]))}s"]
        return [f"{verb} {phrase(c)}" for c in items]

    done: list[str] = []
    matcher = difflib.SequenceMatcher(None, [_constraint_key(c) for c in old], [_constraint_key(c) for c in new])
    for op, i1, i2, j1, j2 in matcher.get_opcodes():
        if op == "equal":
            continue
        pairs = list(zip(old[i1:i2], new[j1:j2], strict=False)) if op == "replace" else []
        for a, b in pairs:
            same = kind_of(a) == kind_of(b) and int(a.character) == int(b.character) and frame_of(a) == frame_of(b)
            done.append(f"moved {phrase(b)}" if same else f"replaced {phrase(a)} by {phrase(b)}")
        done += many("removed", old[i1 + len(pairs) : i2]) + many("added", new[j1 + len(pairs) : j2])
    if not done:
        return "no constraint changed"
    more = f"; and {len(done) - 3} more" if len(done) > 3 else ""
    return "; ".join(done[:3]) + more
