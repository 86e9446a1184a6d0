"""Pruning discrete transformations (Kim et al. 2009, section 5.2).

* **duration**: the removed and the inserted intervals each last between
  ``min_duration`` and ``max_duration`` (0.3 and 2.0 s);
* **enclosing**: among transformations of the same character and type, one
  whose interval strictly contains another's is dropped (deletions and
  replacements compare the removed current frames, duplications the copied
  current frames, insertions the inserted graph frames at the same place;
  replacements must contain both intervals).  We compare within a type:
  an enclosed deletion would happen first as the user drags, but it says
  nothing about, e.g., a duplication;
* **constraints**: a transformation may not remove (delete or replace) a
  frame under an instant constraint, nor the first or last frame of a
  variational one (end effectors included: the first and last frame of each
  of their runs); inserting frames anywhere is allowed;
* **locality**: :class:`Locality` enables transformations per character, per
  type, per time zone (reference-clock seconds of the edited motion) and per
  spatial region (ground positions of the edited path): the frames around
  the seams must all lie in an enabled zone and region.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Iterable, Mapping, Sequence
from typing import Any

import numpy as np
from numpy.typing import NDArray

from ...goals import EndEffector
from ..constraints import SPATIAL, TEMPORAL, EndEffectorConstraint, effector_frames, is_effector
from .transformations import TYPES, Transformation

__all__ = ["Box", "Disk", "Locality", "protected_frames", "protected_by_character", "pruning_violations", "prune"]

Array = NDArray[np.float64]


@dataclasses.dataclass(frozen=True)
class Box:
    """Axis-aligned ground rectangle ``lo <= (x, z) <= hi`` (metres).

    Parameters
    ----------
    lo, hi : (float, float)
        Opposite corners ``(x, z)``, metres, ``lo <= hi`` on both axes.

    Raises
    ------
    ValueError
        For corners that are not ``(x, z)`` pairs or out of order.

    Examples
    --------
    >>> Box((0, 0), (2, 1)).contains([[1.0, 0.5], [3.0, 0.5]]).tolist()
    [True, False]
    """

    lo: tuple[float, float]
    hi: tuple[float, float]

    def __post_init__(self) -> None:
        lo = np.asarray(self.lo, dtype=float)
        hi = np.asarray(self.hi, dtype=float)
        if lo.shape != (2,) or hi.shape != (2,) or not np.all(lo <= hi):
            raise ValueError(f"Expected Box corners lo <= hi as (x, z) pairs, got lo={self.lo!r}, hi={self.hi!r}")
        object.__setattr__(self, "lo", (float(lo[0]), float(lo[1])))
        object.__setattr__(self, "hi", (float(hi[0]), float(hi[1])))

    def contains(self, points: Any) -> NDArray[np.bool_]:
        """Which ground points ``(..., 2)`` are inside."""
        p = np.asarray(points, dtype=float)
        return np.all((p >= self.lo) & (p <= self.hi), axis=-1)


@dataclasses.dataclass(frozen=True)
class Disk:
    """Ground disk of ``radius`` metres around ``center`` ``(x, z)``.

    Parameters
    ----------
    center : (float, float)
        ``(x, z)``, metres.
    radius : float
        Metres (> 0).

    Raises
    ------
    ValueError
        For a center that is not an ``(x, z)`` pair or a radius <= 0.

    Examples
    --------
    >>> Disk((0, 0), 1.5).contains([[1.0, 1.0], [1.5, 1.0]]).tolist()
    [True, False]
    """

    center: tuple[float, float]
    radius: float

    def __post_init__(self) -> None:
        c = np.asarray(self.center, dtype=float)
        if c.shape != (2,) or not float(self.radius) > 0:
            raise ValueError(f"Expected Disk center (x, z) and radius > 0, got {self.center!r}, {self.radius!r}")
        object.__setattr__(self, "center", (float(c[0]), float(c[1])))
        object.__setattr__(self, "radius", float(self.radius))

    def contains(self, points: Any) -> NDArray[np.bool_]:
        p = np.asarray(points, dtype=float)
        return np.linalg.norm(p - self.center, axis=-1) <= self.radius


@dataclasses.dataclass(frozen=True)
class Locality:
    """Where and what discrete transformations may happen (section 5.2, "Locality").

    Parameters
    ----------
    characters : iterable of int, optional
        Characters allowed to change (default: all).
    types : iterable of str
        Enabled types among :data:`TYPES` (default: all).
    time_zones : sequence of (t0, t1), optional
        Reference-clock intervals (seconds, of the current edit) in which the
        frames around a transformation's seams must all lie (in one zone).
    regions : sequence of Box or Disk, optional
        Ground regions (current edited positions) in which those frames must
        all lie (in one region).

    Examples
    --------
    >>> Locality(types=("duplication",), regions=[Disk((0.0, 0.0), 2.0)]).types
    frozenset({'duplication'})
    """

    characters: frozenset[int] | None = None
    types: frozenset[str] = frozenset(TYPES)
    time_zones: tuple[tuple[float, float], ...] | None = None
    regions: tuple[Any, ...] | None = None

    def __post_init__(self) -> None:
        if self.characters is not None:
            object.__setattr__(self, "characters", frozenset(int(k) for k in self.characters))
        types = frozenset([self.types] if isinstance(self.types, str) else self.types)
        bad = sorted(types - set(TYPES))
        if bad:
            raise ValueError(f"Unknown transformation type(s) {bad}; expected some of {list(TYPES)}")
        object.__setattr__(self, "types", types)
        if self.time_zones is not None:
            zones = []
            for z in self.time_zones:
                t0, t1 = (float(v) for v in z)
                if not t0 <= t1:
                    raise ValueError(f"Expected time zones (t0, t1) with t0 <= t1, got {z!r}")
                zones.append((t0, t1))
            object.__setattr__(self, "time_zones", tuple(zones))
        if self.regions is not None:
            regions = tuple(self.regions)
            for r in regions:
                if not hasattr(r, "contains"):
                    raise TypeError(f"Expected regions with a .contains(points) method (Box, Disk), got {r!r}")
            object.__setattr__(self, "regions", regions)

    def allows(self, t: Transformation, times: Array | None = None, positions: Array | None = None) -> bool:
        """Whether ``t`` is enabled, given the edited ``times`` (F,) and ``positions`` (F, 2) of its character."""
        if self.characters is not None and t.character not in self.characters:
            return False
        if t.kind not in self.types:
            return False
        lo, hi = t.span
        if self.time_zones is not None:
            if times is None:
                return False
            tt = np.asarray(times)[max(lo, 0) : hi + 1]
            if not any(bool(np.all((tt >= z0) & (tt <= z1))) for z0, z1 in self.time_zones):
                return False
        if self.regions is not None:
            if positions is None:
                return False
            pp = np.asarray(positions)[max(lo, 0) : hi + 1]
            if not any(bool(np.all(r.contains(pp))) for r in self.regions):
                return False
        return True


def protected_by_character(constraints: Iterable[Any]) -> dict[int, set[int]]:
    """:func:`protected_frames` of every character at once: ``{character: frames}``."""
    prot: dict[int, set[int]] = {}
    for c in constraints:
        for k, fs in _protected(c).items():
            prot.setdefault(k, set()).update(fs)
    return prot


def protected_frames(constraints: Iterable[Any], character: int) -> set[int]:
    """Frames of ``character`` that may not be removed (section 5.2, "Constraints").

    Every frame of an instant constraint, and the first and last frames of
    a variational one (also for end-effector constraints of
    :mod:`mocaplab.goals`).
    """
    out: set[int] = set()
    for c in constraints:
        out |= _protected(c).get(character, set())
    return out


def _protected(c: Any) -> dict[int, set[int]]:
    res: dict[int, set[int]] = {}

    def put(k: int, f: int) -> None:
        res.setdefault(int(k), set()).add(int(f))

    if is_effector(c):
        ee = c.constraint if isinstance(c, EndEffectorConstraint) else c
        return {int(c.character): _effector_boundaries(ee)}
    if not isinstance(c, SPATIAL + TEMPORAL):
        return res
    cc: Any = c
    frames = getattr(cc, "frames", None)
    if frames is None:
        put(cc.character, cc.frame)
        if hasattr(cc, "end_frame"):
            put(cc.character, cc.end_frame)
        other = getattr(cc, "other", None)
        if other is not None:
            put(other, cc.other_frame)
        return res
    put(c.character, frames[0])
    put(c.character, frames[1] - 1)  # half-open: the last frame
    other = getattr(c, "other", None)
    if other is not None:
        of = getattr(c, "other_frames", None) or frames
        put(other, of[0])
        put(other, of[1] - 1)
    return res


def _effector_boundaries(ee: EndEffector) -> set[int]:
    """First and last frame of each run of frames an end effector constrains (its own convention decides)."""
    f = ee.frames
    if isinstance(f, (int, np.integer)):
        extent = int(f) + 1
    elif isinstance(f, tuple) and len(f) == 2:
        extent = int(f[1])
    else:
        extent = int(max(f)) + 1 if len(f) else 1
    out: set[int] = set()
    for a, b in effector_frames(ee, max(extent, 1)):
        out |= {a, b - 1}
    return out


def pruning_violations(
    t: Transformation,
    *,
    constraints: Sequence[Any] = (),
    min_duration: float = 0.3,
    max_duration: float = 2.0,
    locality: Locality | None = None,
    times: Array | None = None,
    positions: Array | None = None,
) -> tuple[str, ...]:
    """Which pruning rules ``t`` breaks (empty if none): "duration", "constraints", "locality".

    ``constraints`` refer to the current frames of the character at the
    time ``t`` is considered; ``times``/``positions`` are its edited ones
    (for locality zones and regions).
    """
    return _violations(
        t, protected_frames(constraints, t.character), min_duration, max_duration, locality, times, positions
    )


def _violations(
    t: Transformation,
    prot: set[int],
    min_duration: float,
    max_duration: float,
    locality: Locality | None,
    times: Array | None,
    positions: Array | None,
) -> tuple[str, ...]:
    out = []
    eps = 1e-9
    for n in (t.removed[1] - t.removed[0], t.inserted[1] - t.inserted[0]):
        if n and not (min_duration - eps <= n / t.fps <= max_duration + eps):
            out.append("duration")
            break
    a, b = t.removed
    if any(a <= f < b for f in prot):
        out.append("constraints")
    if locality is not None and not locality.allows(t, times, positions):
        out.append("locality")
    return tuple(out)


def _interval(t: Transformation) -> tuple[Any, int, int]:
    """Group key and interval compared by the enclosing rule."""
    if t.kind == "deletion":
        return ("del",), t.removed[0], t.removed[1]
    if t.kind == "duplication":
        return ("dup",), t.removed[0], t.removed[0] + t.inserted[1] - t.inserted[0]
    if t.kind == "insertion":
        return ("ins", t.removed[0]), t.inserted[0], t.inserted[1]
    return ("rep",), t.removed[0], t.removed[1]


def _encloses(A: Transformation, B: Transformation) -> bool:
    ka, a0, a1 = _interval(A)
    kb, b0, b1 = _interval(B)
    if A.character != B.character or ka != kb:
        return False
    if A.kind == "replacement":
        inner = B.inserted[0] >= A.inserted[0] and B.inserted[1] <= A.inserted[1]
        return a0 <= b0 and b1 <= a1 and inner and (A.removed, A.inserted) != (B.removed, B.inserted)
    return a0 <= b0 and b1 <= a1 and (a0, a1) != (b0, b1)


def prune(
    candidates: Sequence[Transformation],
    *,
    constraints: Sequence[Any] = (),
    locality: Locality | None = None,
    times: Mapping[int, Array] | None = None,
    positions: Mapping[int, Array] | None = None,
    min_duration: float = 0.3,
    max_duration: float = 2.0,
    protected: Mapping[int, set[int]] | None = None,
) -> list[Transformation]:
    """Apply the four pruning rules of section 5.2 (module docstring).

    Duration, constraint and locality rules first, then enclosing among
    the survivors.  ``times``/``positions`` map a character to its edited
    frame times and ground positions.  ``protected`` (character -> frames,
    :func:`protected_by_character` of ``constraints``) saves recomputing it
    when one set of constraints prunes every character's candidates.
    """
    kept = []
    prot = protected_by_character(constraints) if protected is None else protected
    for t in candidates:
        v = _violations(
            t,
            prot.get(t.character, set()),
            min_duration,
            max_duration,
            locality,
            None if times is None else times.get(t.character),
            None if positions is None else positions.get(t.character),
        )
        if not v:
            kept.append(t)
    groups: dict[tuple[Any, ...], list[Transformation]] = {}
    for t in kept:
        groups.setdefault((t.character, _interval(t)[0]), []).append(t)
    out = []
    for g in groups.values():
        for A in g:
            if not any(_encloses(A, B) for B in g if B is not A):
                out.append(A)
    return sorted(out, key=lambda t: (t.character, t.removed, t.inserted))


