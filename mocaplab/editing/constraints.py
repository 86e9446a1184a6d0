"""Spatial and temporal constraints on motion paths (Kim et al. 2009, section 3).

Every constraint is a frozen dataclass whose first argument is the index of
the character it acts on.  Each one is

* **soft** (``hard=False``, the default): met in the least-squares sense with
  weight ``weight`` (the squared residual is multiplied by ``weight``), or
  **hard** (``hard=True``): met exactly through Lagrange multipliers;
* **instant** (``frame=i``) or **variational** (``frames=(start, stop)`` by
  keyword, no ``frame``: ``PinPosition(0, position=p, frames=(30, 91))``):
  a variational constraint is approximated, as in the paper, by one instant
  constraint every ``variational_step`` (10) frames of the interval, its
  last frame always included.

Intervals: every ``frames=(start, stop)`` is half-open, like a Python slice
and like every frame interval in mocaplab (contacts, goals, stationary
segments): frames ``start .. stop - 1``, so ``(30, 91)`` is the 61 frames
30 to 90.  Both ends included is accepted only by name:
``frames_inclusive=(30, 90)`` (and ``other_frames_inclusive=`` for
:class:`Relative` and :class:`Sync`) is stored as ``frames=(30, 91)``.

Units: ground positions ``(x, z)`` in metres, times in seconds on the shared
reference clock.  Local frames are ``(forward, left)``: forward along the
path tangent ``t_j = p[j+1] - p[j-1]``, left along the normal ``R t_j`` (the
tangent turned +90 degrees about +Y).  Global directions
(:class:`PinDirection`) are ground vectors ``(x, z)`` (normalised here) or
yaw angles in radians, ``atan2(x, z)``; local directions (the ``direction``
of :class:`Relative`) are ``(forward, left)`` vectors or angles ``a`` turned
from forward towards left, ``(cos a, sin a)``: 0 faces the same way as the
other character, ``pi`` faces it, ``pi / 2`` looks to its left.

Choices where the paper leaves room
-----------------------------------
* Equations 1 and 2 write relative offsets as multiples of the unnormalised
  tangent ``p[j+1] - p[j-1]``, so a metric offset would stretch and shrink
  with the edited path (a squeeze to 0.6x put two walkers tied 0.8 m apart
  0.45-0.54 m apart).  :class:`Relative` offsets are metres on the *edited*
  path: the solver keeps the linear rows of equations 1 and 2 (scaled by the
  undeformed tangent length) and corrects their right-hand sides to the
  metric target measured on the solution, re-solving until the correction
  settles (see :mod:`mocaplab.editing.laplacian`, "Relative constraints in
  metres"); :meth:`~mocaplab.editing.scene.EditResult.residuals` reports the
  metric error.
* :class:`PinDirection` and the ``direction`` of :class:`Relative` fix the
  direction of the path tangent; its length is kept at the undeformed length,
  so the character's speed there is kept.

The ``target`` of a constraint is the value a user drags: the position of a
:class:`PinPosition`, the direction of a :class:`PinDirection`, the offset of a
:class:`Relative`, the time of an :class:`AbsoluteTime`, the duration of a
:class:`Duration`, the offset of a :class:`Sync`.  ``c.with_target(value)``
returns a moved copy.  Moving the target of any constraint but
:class:`Relative` changes only right-hand sides of the solver's systems (no
refactorisation).

Longer than 800 lines because every constraint of section 3 is here with its validation, its sampling and a runnable example, so that the one interval convention and the one set of checks serve them all.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Sequence
from typing import TYPE_CHECKING, Any, ClassVar

import numpy as np

from .._checks import integer, real
from ..goals import EndEffector

__all__ = [
    "Constraint",
    "PinPosition",
    "PinDirection",
    "Relative",
    "AbsoluteTime",
    "Duration",
    "Sync",
    "EndEffectorConstraint",
    "effector_frames",
    "is_effector",
    "ConstraintError",
    "SPATIAL",
    "TEMPORAL",
    "direction_vector",
    "local_direction_vector",
]


class ConstraintError(ValueError):
    """Constraints that cannot be met: conflicting, redundant or ill-posed.

    A ``ValueError``, raised by the editors (:func:`~mocaplab.editing.edit`,
    :class:`~mocaplab.editing.SceneEditor`).

    Parameters
    ----------
    message : str
        What is wrong and what to change.
    constraints : sequence
        The offending constraints (user constraints, or descriptions such as
        ``"rigid stationary segment of character 0, frames 300-346"``).
    indices : sequence of int
        Their indices in the scene's constraint list (automatic constraints
        have no index and are left out).

    Examples
    --------
    >>> err = ConstraintError("two hard pins disagree", [PinPosition(0, 10, (0.0, 0.0), hard=True)], [2])
    >>> err.indices, err.constraints[0].frame, isinstance(err, ValueError)
    ((2,), 10, True)
    """

    def __init__(self, message: str, constraints: Sequence[Any] = (), indices: Sequence[int] = ()) -> None:
        super().__init__(message)
        self.constraints = tuple(constraints)
        self.indices = tuple(int(i) for i in indices)


def direction_vector(direction: Any, *, name: str = "direction") -> tuple[float, float]:
    """A unit ground direction ``(x, z)`` from a yaw angle or a 2-vector."""
    arr = np.asarray(direction, dtype=float)
    if arr.ndim == 0:
        a = float(arr)
        if not math.isfinite(a):
            raise ValueError(f"Expected a finite angle for `{name}`, got {direction!r}")
        return (math.sin(a), math.cos(a))
    if arr.shape != (2,) or not np.all(np.isfinite(arr)):
        raise ValueError(f"Expected `{name}` as a yaw angle or a finite (x, z) pair, got {direction!r}")
    n = float(np.hypot(arr[0], arr[1]))
    if n < 1e-12:
        raise ValueError(f"Expected a non-zero `{name}` vector, got {direction!r}")
    return (float(arr[0] / n), float(arr[1] / n))


def local_direction_vector(direction: Any, *, name: str = "direction") -> tuple[float, float]:
    """A unit local direction ``(forward, left)`` from an angle or a 2-vector.

    An angle ``a`` (radians) turns from forward towards left: ``(cos a, sin a)``
    (the yaw convention: turning left is a positive yaw).

    Examples
    --------
    >>> [round(v, 12) for v in local_direction_vector(0.0)], [round(v, 12) for v in local_direction_vector(3.141592653589793)]
    ([1.0, 0.0], [-1.0, 0.0])
    """
    arr = np.asarray(direction, dtype=float)
    if arr.ndim == 0:
        a = float(arr)
        if not math.isfinite(a):
            raise ValueError(f"Expected a finite angle for `{name}`, got {direction!r}")
        return (math.cos(a), math.sin(a))
    if arr.shape != (2,) or not np.all(np.isfinite(arr)):
        raise ValueError(f"Expected `{name}` as an angle or a finite (forward, left) pair, got {direction!r}")
    n = float(np.hypot(arr[0], arr[1]))
    if n < 1e-12:
        raise ValueError(f"Expected a non-zero `{name}` vector, got {direction!r}")
    return (float(arr[0] / n), float(arr[1] / n))


def _required(obj: Any, name: str, example: str) -> None:
    if getattr(obj, name) is None:
        raise TypeError(f"{type(obj).__name__}: missing `{name}` (e.g. {example})")


def _pair(value: Any, name: str) -> tuple[float, float]:
    arr = np.asarray(value, dtype=float)
    if arr.shape != (2,) or not np.all(np.isfinite(arr)):
        raise ValueError(f"Expected `{name}` as a finite pair of numbers, got {value!r}")
    return (float(arr[0]), float(arr[1]))


def _scalar(value: Any, name: str) -> float:
    """A finite real number (:func:`mocaplab._checks.real`: TypeError for a string or None, ValueError for NaN)."""
    return real(value, name)


def _index(value: Any, name: str) -> int:
    """A frame or character index: an int >= 0 (a float, even 3.0, is a TypeError: indices are counted)."""
    if isinstance(value, (float, np.floating)):
        raise TypeError(f"Expected `{name}` to be an integer >= 0, got {type(value).__name__} {value!r}")
    return integer(value, name, low=0)


def _interval(value: Any, name: str, *, least: int = 2) -> tuple[int, int]:
    """A half-open ``(start, stop)`` interval of at least ``least`` frames."""
    try:
        a, b = value
    except (TypeError, ValueError):
        raise ValueError(f"Expected `{name}` as a half-open (start, stop) pair of frames, got {value!r}") from None
    a, b = _index(a, f"{name}[0]"), _index(b, f"{name}[1]")
    if b - a < least:
        raise ValueError(
            f"Expected `{name}` (start, stop), half-open, of at least {least} frames, got {value!r}"
            + (" (both ends included is written frames_inclusive=...)" if b - a == least - 1 else "")
        )
    return (a, b)


def _inclusive(self: Any, name: str) -> None:
    """Move ``<name>_inclusive=(first, last)`` into ``<name>=(first, last + 1)``."""
    given = getattr(self, f"{name}_inclusive", None)
    if given is None:
        return
    if getattr(self, name, None) is not None:
        raise TypeError(f"{type(self).__name__}: give `{name}` (half-open) or `{name}_inclusive`, not both")
    a, b = _interval(given, f"{name}_inclusive", least=0)
    object.__setattr__(self, name, (a, b + 1))
    object.__setattr__(self, f"{name}_inclusive", None)


def _sample(start: int, stop: int, step: int) -> list[int]:
    """Every ``step``-th frame of ``start .. stop - 1``, the last one always included."""
    out = list(range(start, stop, step))
    if out[-1] != stop - 1:
        out.append(stop - 1)
    return out


@dataclasses.dataclass(frozen=True)
class Constraint:
    """Common base: ``character``, ``frame`` / ``frames``, ``hard``, ``weight``.

    Not built directly: the subclasses (:class:`PinPosition`,
    :class:`PinDirection`, :class:`Relative`, :class:`AbsoluteTime`,
    :class:`Duration`, :class:`Sync`) declare the fields; the base gives
    them the common checks and the interface the solvers read.

    Examples
    --------
    >>> pin = PinPosition(0, 10, (1.0, 2.0))
    >>> isinstance(pin, Constraint), pin.kind, pin.target, pin.with_target((3, 4)).position
    (True, 'space', (1.0, 2.0), (3.0, 4.0))
    """

    kind: ClassVar[str] = ""  # "space" or "time"
    target_name: ClassVar[str] = ""
    target_in_matrix: ClassVar[bool] = False

    if TYPE_CHECKING:  # fields declared by the subclasses
        character: int
        frame: int | None
        hard: bool
        weight: float

    def _check_common(self, *, allow_variational: bool = True) -> None:
        object.__setattr__(self, "character", _index(self.character, "character"))
        _inclusive(self, "frames")
        _inclusive(self, "other_frames")
        frame = self.frame
        frames = getattr(self, "frames", None)
        if frame is None and frames is None:
            raise ValueError(
                f"{type(self).__name__}: give `frame` (instant) or `frames=(start, stop)` (variational, half-open), "
                "got neither"
            )
        if frame is not None and frames is not None:
            raise ValueError(f"{type(self).__name__}: give either `frame` or `frames`, not both")
        if frame is not None:
            object.__setattr__(self, "frame", _index(frame, "frame"))
        else:
            if not allow_variational:
                raise ValueError(f"{type(self).__name__} has no variational form: give `frame`")
            object.__setattr__(self, "frames", _interval(frames, "frames"))
        if not isinstance(self.hard, (bool, np.bool_)):
            raise TypeError(f"Expected `hard` as a bool, got {self.hard!r}")
        object.__setattr__(self, "hard", bool(self.hard))
        w = _scalar(self.weight, "weight")
        if w <= 0:
            raise ValueError(f"Expected `weight` > 0, got {self.weight!r}")
        object.__setattr__(self, "weight", w)

    # ----------------------------------------------------------- interface
    @property
    def characters(self) -> tuple[int, ...]:
        """Indices of the characters this constraint involves."""
        other = getattr(self, "other", None)
        return (self.character,) if other is None else (self.character, other)

    @property
    def variational(self) -> bool:
        return getattr(self, "frames", None) is not None

    @property
    def target(self) -> Any:
        """The draggable value (see the module docstring)."""
        return getattr(self, self.target_name)

    def with_target(self, new_target: Any) -> Constraint:
        """A copy with the target moved (validated again)."""
        return dataclasses.replace(self, **{self.target_name: new_target})

    def frame_refs(self) -> list[tuple[int, int]]:
        """Every ``(character, frame)`` this constraint reads (for range checks).

        The default serves constraints on one frame of one character; those
        that read two frames or two characters override it.
        """
        return [(self.character, f[0]) for f in self.samples(1_000_000)]

    def samples(self, step: int = 10) -> list[tuple[int, ...]]:
        """Frame tuples of the instant constraints this one stands for.

        The default: the frame itself, or every ``step``-th frame of a
        variational interval (its last frame always included).
        """
        frames: tuple[int, int] | None = getattr(self, "frames", None)
        if frames is None:
            return [(int(self.frame),)]  # type: ignore[arg-type]
        return [(f,) for f in _sample(frames[0], frames[1], step)]

    def structure(self) -> tuple[Any, ...]:
        """Everything that enters the solver's matrix (a drag keeps it)."""
        fields = {f.name: getattr(self, f.name) for f in dataclasses.fields(self)}
        if not self.target_in_matrix:
            fields.pop(self.target_name)
        return (type(self).__name__,) + tuple(sorted(fields.items()))


@dataclasses.dataclass(frozen=True)
class PinPosition(Constraint):
    """Pin the root of ``character`` at ``frame`` to ground point ``position`` (x, z), metres.

    Parameters
    ----------
    character : int
        Index of the character in the scene.
    frame : int, optional
        The frame (instant form).
    position : (float, float)
        Ground point ``(x, z)``, metres; required.  The drag target.
    hard : bool, default False
        Met exactly (Lagrange multipliers) instead of in the least-squares sense.
    weight : float, default 1.0
        Weight of a soft constraint's squared residual (> 0).
    frames : (start, stop), optional
        Variational form instead of ``frame``: a half-open interval of frames,
        sampled every 10 frames (its last frame always included).
    frames_inclusive : (first, last), optional
        The same interval with both ends included (stored as ``frames``).

    Raises
    ------
    TypeError
        Without ``position``, or with a ``hard`` that is not a bool.
    ValueError
        For both or neither of ``frame`` and ``frames``, or a weight <= 0.

    Examples
    --------
    >>> PinPosition(0, 10, (1.0, 2.0), hard=True).position
    (1.0, 2.0)
    >>> PinPosition(0, position=(0.0, 0.0), frames=(0, 31)).samples()
    [(0,), (10,), (20,), (30,)]
    >>> PinPosition(0, position=(0.0, 0.0), frames_inclusive=(0, 30)).frames
    (0, 31)
    """

    character: int
    frame: int | None = None
    position: tuple[float, float] = None  # type: ignore[assignment]  # required (checked)
    _: dataclasses.KW_ONLY
    hard: bool = False
    weight: float = 1.0
    frames: tuple[int, int] | None = None
    frames_inclusive: tuple[int, int] | None = dataclasses.field(default=None, repr=False, compare=False)

    kind: ClassVar[str] = "space"
    target_name: ClassVar[str] = "position"

    def __post_init__(self) -> None:
        self._check_common()
        _required(self, "position", "PinPosition(0, 10, (1.0, 2.0))")
        object.__setattr__(self, "position", _pair(self.position, "position"))


@dataclasses.dataclass(frozen=True)
class PinDirection(Constraint):
    """Pin the path direction (tangent) of ``character`` at ``frame``.

    ``direction`` is a ground vector ``(x, z)`` or a yaw angle (radians,
    ``atan2(x, z)``); stored as a unit vector.  The tangent keeps its
    undeformed length.  Variational form: ``PinDirection(k, direction=d,
    frames=(a, b))``.

    Parameters
    ----------
    character : int
        Index of the character in the scene.
    frame : int, optional
        The frame (instant form).
    direction : (float, float) or float
        Ground vector ``(x, z)`` or yaw angle in radians; required.  The drag
        target.
    hard : bool, default False
        Met exactly (Lagrange multipliers) instead of in the least-squares sense.
    weight : float, default 1.0
        Weight of a soft constraint's squared residual (> 0).
    frames : (start, stop), optional
        Variational form instead of ``frame``: a half-open interval of frames,
        sampled every 10 frames (its last frame always included).
    frames_inclusive : (first, last), optional
        The same interval with both ends included (stored as ``frames``).

    Examples
    --------
    >>> PinDirection(0, 10, (3.0, 4.0)).direction
    (0.6, 0.8)
    >>> x, z = PinDirection(0, 10, np.pi / 2).direction
    >>> round(x, 6), round(z, 6)
    (1.0, 0.0)
    """

    character: int
    frame: int | None = None
    direction: Any = None
    _: dataclasses.KW_ONLY
    hard: bool = False
    weight: float = 1.0
    frames: tuple[int, int] | None = None
    frames_inclusive: tuple[int, int] | None = dataclasses.field(default=None, repr=False, compare=False)

    kind: ClassVar[str] = "space"
    target_name: ClassVar[str] = "direction"

    def __post_init__(self) -> None:
        self._check_common()
        _required(self, "direction", "PinDirection(0, 10, (0.0, 1.0))")
        object.__setattr__(self, "direction", direction_vector(self.direction))


def _paired_samples(
    frame: int | None,
    frames: tuple[int, int] | None,
    other_frame: int | None,
    other_frames: tuple[int, int] | None,
    step: int,
) -> list[tuple[int, int]]:
    if frames is None:
        return [(int(frame), int(other_frame))]  # type: ignore[arg-type]
    own = _sample(frames[0], frames[1], step)
    if other_frames is None:
        return [(f, f) for f in own]
    a0, a1 = frames[0], frames[1] - 1  # first and last frame
    b0, b1 = other_frames[0], other_frames[1] - 1
    return [(f, int(round(b0 + (f - a0) * (b1 - b0) / (a1 - a0)))) for f in own]


@dataclasses.dataclass(frozen=True)
class Relative(Constraint):
    """Root of ``character`` at ``frame`` relative to ``other`` at ``other_frame`` (eqs. 1, 2).

    Parameters
    ----------
    character : int
        The character placed.
    frame : int, optional
        Its frame (instant form).
    other : int
        The character it is placed relative to; required.
    other_frame : int, optional
        The other's frame (instant form; required with ``frame``).
    offset : (forward, left), metres
        Position of ``character`` in the moving tangent frame of ``other``,
        in metres on the edited path (see the module docstring).
    direction : (forward, left) or angle, optional
        Path direction of ``character`` in that frame (``None``: free): a
        vector, or an angle ``a`` turned from forward towards left, ``(cos a,
        sin a)``: ``0`` walks the same way as ``other``, ``pi`` towards it.
    frames, other_frames : (start, stop), optional
        Variational form (half-open intervals): ``frames`` of ``character``
        matched linearly to ``other_frames`` of ``other`` (default: the same
        frame numbers), e.g. ``Relative(1, other=0, offset=(0.0, 0.6),
        frames=(40, 91))``.
    frames_inclusive, other_frames_inclusive : (first, last), optional
        The same intervals with both ends included.
    hard : bool, default False
        Met exactly (Lagrange multipliers) instead of in the least-squares sense.
    weight : float, default 1.0
        Weight of a soft constraint's squared residual (> 0).

    Drag target: ``offset``.  The offset enters the matrix, so moving it
    refactorises (still fast; positions pins are the cheap drag).

    Examples
    --------
    >>> Relative(1, 50, 0, 70, (0.0, 0.6), direction=np.pi).direction[0]
    -1.0
    """

    character: int
    frame: int | None = None
    other: int = None  # type: ignore[assignment]  # required (checked)
    other_frame: int | None = None
    offset: tuple[float, float] = None  # type: ignore[assignment]  # required (checked)
    _: dataclasses.KW_ONLY
    direction: Any = None
    hard: bool = False
    weight: float = 1.0
    frames: tuple[int, int] | None = None
    other_frames: tuple[int, int] | None = None
    frames_inclusive: tuple[int, int] | None = dataclasses.field(default=None, repr=False, compare=False)
    other_frames_inclusive: tuple[int, int] | None = dataclasses.field(default=None, repr=False, compare=False)

    kind: ClassVar[str] = "space"
    target_name: ClassVar[str] = "offset"
    target_in_matrix: ClassVar[bool] = True

    def __post_init__(self) -> None:
        self._check_common()
        _required(self, "other", "Relative(1, 50, 0, 70, (0.0, 0.6)) or Relative(1, other=0, ...)")
        _required(self, "offset", "Relative(1, 50, 0, 70, (0.0, 0.6))")
        object.__setattr__(self, "other", _index(self.other, "other"))
        object.__setattr__(self, "offset", _pair(self.offset, "offset"))
        if self.direction is not None:
            object.__setattr__(self, "direction", local_direction_vector(self.direction))
        if self.frames is None:
            if self.other_frame is None:
                raise ValueError("Relative: instant form needs `other_frame`")
            if self.other_frames is not None:
                raise ValueError("Relative: `other_frames` goes with `frames` (variational), not with `frame`")
            object.__setattr__(self, "other_frame", _index(self.other_frame, "other_frame"))
        else:
            if self.other_frame is not None:
                raise ValueError("Relative: variational form takes `other_frames=(start, stop)`, not `other_frame`")
            if self.other_frames is not None:
                object.__setattr__(self, "other_frames", _interval(self.other_frames, "other_frames"))
        if self.other == self.character and self.samples(1)[0][0] == self.samples(1)[0][1]:
            raise ValueError("Relative: a character cannot be placed relative to itself at the same frame")

    def frame_refs(self) -> list[tuple[int, int]]:
        out = []
        for a, b in self.samples(1_000_000):
            out += [(self.character, a), (self.other, b)]
        return out

    def samples(self, step: int = 10) -> list[tuple[int, ...]]:
        return _paired_samples(self.frame, self.frames, self.other_frame, self.other_frames, step)  # type: ignore[return-value]


@dataclasses.dataclass(frozen=True)
class AbsoluteTime(Constraint):
    """Frame ``frame`` of ``character`` happens at reference time ``time`` (s): ``t_i = time``.

    Variational form ``AbsoluteTime(k, time=t, frames=(start, stop))``: frame
    ``start`` at ``time`` and the interval played at its original speed
    (``t_i = time + (i - start) h``).

    Parameters
    ----------
    character : int
        Index of the character in the scene.
    frame : int, optional
        The frame (instant form).
    time : float
        Reference time, seconds; required.  The drag target.
    hard : bool, default False
        Met exactly (Lagrange multipliers) instead of in the least-squares sense.
    weight : float, default 1.0
        Weight of a soft constraint's squared residual (> 0).
    frames : (start, stop), optional
        Variational form instead of ``frame``: a half-open interval of frames,
        sampled every 10 frames (its last frame always included).
    frames_inclusive : (first, last), optional
        The same interval with both ends included (stored as ``frames``).

    Examples
    --------
    >>> AbsoluteTime(0, 10, 1.5).time
    1.5
    >>> AbsoluteTime(0, time=2.0, frames=(0, 25)).samples()
    [(0,), (10,), (20,), (24,)]
    """

    character: int
    frame: int | None = None
    time: float = None  # type: ignore[assignment]  # required (checked)
    _: dataclasses.KW_ONLY
    hard: bool = False
    weight: float = 1.0
    frames: tuple[int, int] | None = None
    frames_inclusive: tuple[int, int] | None = dataclasses.field(default=None, repr=False, compare=False)

    kind: ClassVar[str] = "time"
    target_name: ClassVar[str] = "time"

    def __post_init__(self) -> None:
        self._check_common()
        _required(self, "time", "AbsoluteTime(0, 10, 1.5)")
        object.__setattr__(self, "time", _scalar(self.time, "time"))


@dataclasses.dataclass(frozen=True)
class Duration(Constraint):
    """Frames ``frame`` to ``end_frame`` of ``character`` last ``duration`` s: ``t_end - t_frame = duration``.

    Parameters
    ----------
    character : int
        Index of the character in the scene.
    frame, end_frame : int
        First and last frame of the span, ``frame < end_frame`` (no
        variational form).
    duration : float
        Seconds (> 0).  The drag target.
    hard : bool, default False
        Met exactly (Lagrange multipliers) instead of in the least-squares sense.
    weight : float, default 1.0
        Weight of a soft constraint's squared residual (> 0).

    Raises
    ------
    ValueError
        For ``end_frame <= frame`` or a duration <= 0.

    Examples
    --------
    >>> slow = Duration(0, 10, 40, 1.2)
    >>> slow.samples(), slow.with_target(2.0).duration
    ([(10, 40)], 2.0)
    """

    character: int
    frame: int
    end_frame: int
    duration: float
    _: dataclasses.KW_ONLY
    hard: bool = False
    weight: float = 1.0

    kind: ClassVar[str] = "time"
    target_name: ClassVar[str] = "duration"

    def __post_init__(self) -> None:
        if self.frame is None:
            raise ValueError("Duration has no variational form: give `frame` and `end_frame`")
        self._check_common(allow_variational=False)
        object.__setattr__(self, "end_frame", _index(self.end_frame, "end_frame"))
        if self.end_frame <= self.frame:
            raise ValueError(
                f"Degenerate interval for Duration: expected frame < end_frame, got {self.frame} and {self.end_frame}"
            )
        d = _scalar(self.duration, "duration")
        if d <= 0:
            raise ValueError(f"Expected `duration` > 0 s, got {self.duration!r}")
        object.__setattr__(self, "duration", d)

    @property
    def frames(self) -> None:  # no variational form
        return None

    def frame_refs(self) -> list[tuple[int, int]]:
        return [(self.character, self.frame), (self.character, self.end_frame)]

    def samples(self, step: int = 10) -> list[tuple[int, ...]]:
        return [(self.frame, self.end_frame)]


@dataclasses.dataclass(frozen=True)
class Sync(Constraint):
    """Synchronise two characters: ``t[frame] = t_other[other_frame] + offset`` (s).

    Variational form (half-open intervals): ``Sync(k, other=j, frames=(a, b),
    other_frames=(c, d))``, ``frames`` of ``character`` matched linearly to
    ``other_frames`` of ``other`` (default: the same frame numbers).

    Parameters
    ----------
    character : int
        Index of the character in the scene.
    frame : int, optional
        Its frame (instant form).
    other : int
        The character it is synchronised with; required.
    other_frame : int, optional
        The other's frame (instant form; required with ``frame``).
    offset : float, default 0.0
        ``t[frame] - t_other[other_frame]``, seconds.  The drag target.
    hard : bool, default False
        Met exactly (Lagrange multipliers) instead of in the least-squares sense.
    weight : float, default 1.0
        Weight of a soft constraint's squared residual (> 0).
    frames, other_frames : (start, stop), optional
        Variational form: half-open intervals matched linearly.
    frames_inclusive, other_frames_inclusive : (first, last), optional
        The same intervals with both ends included.

    Examples
    --------
    >>> Sync(1, 50, 0, 70, offset=0.5).samples()
    [(50, 70)]
    >>> Sync(1, other=0, frames=(40, 61), other_frames=(0, 41)).samples()
    [(40, 0), (50, 20), (60, 40)]
    """

    character: int
    frame: int | None = None
    other: int = None  # type: ignore[assignment]  # required (checked)
    other_frame: int | None = None
    _: dataclasses.KW_ONLY
    offset: float = 0.0
    hard: bool = False
    weight: float = 1.0
    frames: tuple[int, int] | None = None
    other_frames: tuple[int, int] | None = None
    frames_inclusive: tuple[int, int] | None = dataclasses.field(default=None, repr=False, compare=False)
    other_frames_inclusive: tuple[int, int] | None = dataclasses.field(default=None, repr=False, compare=False)

    kind: ClassVar[str] = "time"
    target_name: ClassVar[str] = "offset"

    def __post_init__(self) -> None:
        self._check_common()
        _required(self, "other", "Sync(1, 50, 0, 70) or Sync(1, other=0, frames=(40, 60))")
        object.__setattr__(self, "other", _index(self.other, "other"))
        object.__setattr__(self, "offset", _scalar(self.offset, "offset"))
        if self.frames is None:
            if self.other_frame is None:
                raise ValueError("Sync: instant form needs `other_frame`")
            object.__setattr__(self, "other_frame", _index(self.other_frame, "other_frame"))
        else:
            if self.other_frame is not None:
                raise ValueError("Sync: variational form takes `other_frames=(start, stop)`, not `other_frame`")
            if self.other_frames is not None:
                object.__setattr__(self, "other_frames", _interval(self.other_frames, "other_frames"))
        if self.other == self.character:
            s = self.samples(1)[0]
            if s[0] == s[1]:
                raise ValueError("Sync: a frame cannot be synchronised with itself")

    def frame_refs(self) -> list[tuple[int, int]]:
        out = []
        for a, b in self.samples(1_000_000):
            out += [(self.character, a), (self.other, b)]
        return out

    def samples(self, step: int = 10) -> list[tuple[int, ...]]:
        return _paired_samples(self.frame, self.frames, self.other_frame, self.other_frames, step)  # type: ignore[return-value]


@dataclasses.dataclass(frozen=True)
class EndEffectorConstraint:
    """An end-effector constraint (section 4.3) on ``character``, for full-body refinement.

    Path editing ignores it; the scene records it (``EditResult.end_effectors``)
    and hands it to :func:`mocaplab.editing.refinement.refine_scene` (Kim et al. 2009,
    section 4.3).  Frames are the character's own frames.

    Two forms:

    * ``EndEffectorConstraint(character, joint=..., frame=i, target=...)`` or
      ``frames=(start, stop)`` (half-open, like every interval here; both
      ends included only as ``frames_inclusive=(first, last)``), with
      ``target`` a world point (3,), one point per frame of the clip
      ``(F, 3)``, or a :class:`~mocaplab.goals.RelativeTo` /
      :class:`~mocaplab.goals.ObjectFrame`; ``chain`` and ``blend`` as in
      :class:`~mocaplab.goals.EndEffector`.
    * ``EndEffectorConstraint(character, end_effector)``: a
      :class:`~mocaplab.goals.EndEffector` as it is.

    ``constraint`` is the :class:`~mocaplab.goals.EndEffector` either way.

    Parameters
    ----------
    character : int
        Index of the character in the scene.
    constraint : EndEffector, optional
        The second form; then none of the keywords below.
    joint : str, optional
        The end effector joint (first form; required there).
    frame : int, optional
        One frame (first form).
    frames : (start, stop), optional
        A half-open interval of frames (first form).
    target : array_like, shape (3,) or (F, 3), RelativeTo or ObjectFrame, optional
        Where the joint goes, metres (first form; required there).
    chain : sequence of str, optional
        Joints solved by damped least squares instead of the two-bone limb.
    blend : float, optional
        Blending window, seconds (default: that of the refine call).
    frames_inclusive : (first, last), optional
        ``frames`` with both ends included.

    Raises
    ------
    TypeError
        For both forms at once, or a first form without ``joint`` or ``target``.
    ValueError
        For both or neither of ``frame`` and ``frames``.

    Examples
    --------
    >>> c = EndEffectorConstraint(0, joint="RightHand", frames=(10, 21), target=(0.0, 1.0, 0.0))
    >>> c.constraint.frames == c.frames == (10, 21)
    True
    """

    character: int
    constraint: Any = None
    _: dataclasses.KW_ONLY
    joint: str | None = None
    frame: int | None = None
    frames: tuple[int, int] | None = None
    target: Any = None
    chain: Sequence[str] | None = None
    blend: float | None = None
    frames_inclusive: tuple[int, int] | None = dataclasses.field(default=None, repr=False, compare=False)

    kind: ClassVar[str] = "body"

    def __post_init__(self) -> None:
        object.__setattr__(self, "character", _index(self.character, "character"))
        _inclusive(self, "frames")
        keywords = {k: getattr(self, k) for k in ("joint", "frame", "frames", "target", "chain", "blend")}
        if self.constraint is not None:
            given = sorted(k for k, v in keywords.items() if v is not None)
            if given:
                raise TypeError(
                    f"EndEffectorConstraint: give either an EndEffector or joint=/frame(s)=/target=, not both (got {given})"
                )
            if not isinstance(self.constraint, EndEffector):
                raise TypeError(
                    f"Expected `constraint` to be a mocaplab.goals.EndEffector, got {type(self.constraint).__name__}"
                )
            ee = self.constraint
            if ee.character != self.character:
                ee = dataclasses.replace(ee, character=self.character)
            object.__setattr__(self, "constraint", ee)
            return
        if self.joint is None or self.target is None:
            raise TypeError(
                "EndEffectorConstraint: give `joint=` and `target=` with `frame=` or `frames=(start, stop)` "
                "(e.g. EndEffectorConstraint(0, joint='RightHand', frame=40, target=(0.3, 1.1, 2.0)))"
            )
        if (self.frame is None) == (self.frames is None):
            raise ValueError(
                "EndEffectorConstraint: give `frame` (one frame) or `frames=(start, stop)` (half-open), one of them"
            )
        if self.frame is not None:
            object.__setattr__(self, "frame", _index(self.frame, "frame"))
            frames: Any = int(self.frame)
        else:
            frames = _interval(self.frames, "frames", least=1)
            object.__setattr__(self, "frames", frames)
        ee = EndEffector(
            str(self.joint),
            frames,
            self.target,
            character=self.character,
            chain=None if self.chain is None else tuple(self.chain),
            blend=self.blend,
        )
        object.__setattr__(self, "constraint", ee)

    @property
    def characters(self) -> tuple[int, ...]:
        return (self.character,)

    def frame_refs(self) -> list[tuple[int, int]]:
        return []


def effector_frames(effector: Any, n_frames: int) -> list[tuple[int, int]]:
    """Half-open ``(start, stop)`` runs of frames an end effector constrains.

    ``effector`` is an :class:`EndEffectorConstraint` or a
    :class:`~mocaplab.goals.EndEffector` (whose own
    :meth:`~mocaplab.goals.EndEffector.intervals` decide).
    """
    ee = effector.constraint if isinstance(effector, EndEffectorConstraint) else effector
    return ee.intervals(n_frames)


def is_effector(c: Any) -> bool:
    """Whether ``c`` is an end-effector constraint (either form)."""
    return isinstance(c, (EndEffector, EndEffectorConstraint))


SPATIAL = (PinPosition, PinDirection, Relative)
TEMPORAL = (AbsoluteTime, Duration, Sync)
