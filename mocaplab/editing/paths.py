"""Motion paths: the root projected on the ground (Kim et al. 2009, section 3.1).

A :class:`MotionPath` holds, per frame ``i``,

* ``positions[i] = p_i``: the root's ground position ``(x, z)``, metres;
* ``tangents[i] = t_i = p_{i+1} - p_{i-1}`` (central difference; at the two
  ends ``2 (p_1 - p_0)`` and ``2 (p_{F-1} - p_{F-2})`` so every tangent spans
  two frame steps);
* ``normals[i] = n_i = R t_i`` with ``R`` the +90 degree turn about +Y:
  ``R (x, z) = (z, -x)`` (a character walking along ``t`` has ``n`` on its
  left);
* ``directions[i] = theta_i``: the root heading (yaw of the root rotation,
  :func:`mocaplab.quat.yaw`) measured from the tangent direction, so the
  heading follows a deformed path.

Angles of ground vectors use the yaw convention ``atan2(x, z)``.

Degenerate tangents (stationary frames, ``|t_i| < 2 min_speed / fps``) are
replaced by linear interpolation of the nearest non-degenerate tangents
before and after (copied at the ends).  The paper asks for a "minuscule"
threshold; we use a speed (0.1 m/s by default) because below it the tangent
direction of captured data is noise.  Every tangent, filled or not, is a
fixed linear function of the positions: :meth:`MotionPath.tangent_operator`
returns that sparse matrix, which the solver uses in the direction and
relative constraints.

Laplacian coordinates (equation 3): ``p_i = p_{i-1} + x_i t_i + y_i R t_i``
for the interior frames ``1 <= i <= F - 2``.
"""

from __future__ import annotations

import dataclasses
from functools import cached_property
from typing import Any

import numpy as np
import scipy.sparse as sp
from numpy.typing import ArrayLike, NDArray
from scipy.ndimage import gaussian_filter1d

from .. import quat
from ..motion import Motion

__all__ = [
    "MotionPath",
    "rot90",
    "ground_angle",
    "central_tangents",
    "laplacian_coordinates",
    "stationary_segments",
    "wrap_angle",
]

Array = NDArray[np.float64]


def rot90(v: ArrayLike) -> Array:
    """Turn ground vectors ``(x, z)`` by +90 degrees about +Y: ``(z, -x)``."""
    v = np.asarray(v, dtype=float)
    return np.stack([v[..., 1], -v[..., 0]], axis=-1)


def ground_angle(v: ArrayLike) -> Array:
    """Yaw angle ``atan2(x, z)`` of ground vectors ``(..., 2)``."""
    v = np.asarray(v, dtype=float)
    return np.arctan2(v[..., 0], v[..., 1])


def wrap_angle(a: ArrayLike) -> Array:
    """Angles wrapped to ``(-pi, pi]``."""
    a = np.asarray(a, dtype=float)
    return np.pi - np.mod(np.pi - a, 2.0 * np.pi)


def central_tangents(positions: ArrayLike) -> Array:
    """Raw tangents ``p_{i+1} - p_{i-1}`` (one-sided, doubled, at the ends), shape (F, 2)."""
    p = np.asarray(positions, dtype=float)
    t = np.empty_like(p)
    if len(p) < 2:
        t[:] = 0.0
        return t
    t[1:-1] = p[2:] - p[:-2]
    t[0] = 2.0 * (p[1] - p[0])
    t[-1] = 2.0 * (p[-1] - p[-2])
    return t


def laplacian_coordinates(positions: ArrayLike) -> Array:
    """Local coordinates ``(x_i, y_i)`` of equation 3, shape (F, 2) (NaN at both ends).

    Where ``|p_{i+1} - p_{i-1}|`` vanishes (below 1e-9 m) the coordinates are
    undefined; we use ``(0.5, 0)`` (the midpoint).
    """
    p = np.asarray(positions, dtype=float)
    out = np.full(p.shape, np.nan)
    if len(p) < 3:
        return out
    t = p[2:] - p[:-2]
    d = p[1:-1] - p[:-2]
    n2 = np.einsum("ij,ij->i", t, t)
    ok = n2 > 1e-18
    safe = np.where(ok, n2, 1.0)
    x = np.einsum("ij,ij->i", d, t) / safe
    y = np.einsum("ij,ij->i", d, rot90(t)) / safe
    out[1:-1, 0] = np.where(ok, x, 0.5)
    out[1:-1, 1] = np.where(ok, y, 0.0)
    return out


def _fill_operator(n: int, good: NDArray[np.bool_]) -> sp.csr_matrix | None:
    """(n, n) matrix copying good rows and linearly interpolating the others."""
    idx = np.arange(n)
    if good.all():
        return None
    if not good.any():
        raise ValueError("no good row to interpolate from")
    prev = np.maximum.accumulate(np.where(good, idx, -1))
    nxt = np.minimum.accumulate(np.where(good, idx, n)[::-1])[::-1]
    prev_ok = prev >= 0
    next_ok = nxt < n
    a = np.where(prev_ok, prev, nxt)
    b = np.where(next_ok, nxt, prev)
    span = (b - a).astype(float)
    wb = np.where(span > 0, (idx - a) / np.where(span > 0, span, 1.0), 0.0)
    wa = 1.0 - wb
    rows = np.concatenate([idx, idx])
    cols = np.concatenate([a, b])
    vals = np.concatenate([wa, wb])
    return sp.csr_matrix((vals, (rows, cols)), shape=(n, n))


def _difference_operator(n: int) -> sp.csr_matrix:
    """(n, n) matrix of :func:`central_tangents` (per coordinate)."""
    if n < 2:
        return sp.csr_matrix((n, n))
    rows = [np.arange(1, n - 1), np.arange(1, n - 1), np.array([0, 0, n - 1, n - 1])]
    cols = [np.arange(2, n), np.arange(0, n - 2), np.array([1, 0, n - 1, n - 2])]
    vals = [np.ones(n - 2), -np.ones(n - 2), np.array([2.0, -2.0, 2.0, -2.0])]
    return sp.csr_matrix((np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))), shape=(n, n))


@dataclasses.dataclass(frozen=True, eq=False)
class MotionPath:
    """The ground path of a motion's root, with its tangent frames.

    Parameters
    ----------
    positions : array_like, shape (F, 2)
        Root ground positions ``(x, z)``, metres.
    headings : array_like, shape (F,)
        Root heading (yaw, radians) per frame.
    fps : float
        Frames per second.
    min_speed : float
        Tangents shorter than ``2 * min_speed / fps`` (the root slower than
        ``min_speed`` m/s) are degenerate and filled by interpolation.

    Attributes
    ----------
    tangents : ndarray, shape (F, 2)
        Central-difference tangents, degenerate ones interpolated.
    normals : ndarray, shape (F, 2)
        ``R tangents`` (left of the walking direction).
    directions : ndarray, shape (F,)
        Heading minus tangent angle, wrapped to ``(-pi, pi]``.
    degenerate : ndarray of bool, shape (F,)

    Examples
    --------
    >>> import numpy as np
    >>> p = np.c_[np.zeros(5), np.arange(5.0)]          # walking along +z
    >>> path = MotionPath(p, np.zeros(5), 30.0)
    >>> path.tangents[2].tolist(), path.normals[2].tolist(), float(path.directions[2])
    ([0.0, 2.0], [2.0, -0.0], 0.0)
    """

    positions: Array
    headings: Array
    fps: float
    min_speed: float = 0.1

    def __post_init__(self) -> None:
        p = np.array(self.positions, dtype=float)
        if p.ndim != 2 or p.shape[1] != 2 or p.shape[0] < 3:
            raise ValueError(f"Expected `positions` of shape (F, 2) with F >= 3, got {p.shape}")
        h = np.array(self.headings, dtype=float).reshape(-1)
        if h.shape != (p.shape[0],):
            raise ValueError(f"Expected `headings` of shape ({p.shape[0]},), got {h.shape}")
        if not (np.all(np.isfinite(p)) and np.all(np.isfinite(h))):
            raise ValueError("Expected finite `positions` and `headings`")
        fps = float(self.fps)
        if not fps > 0:
            raise ValueError(f"Expected `fps` > 0, got {self.fps!r}")
        p.flags.writeable = False
        h.flags.writeable = False
        object.__setattr__(self, "positions", p)
        object.__setattr__(self, "headings", h)
        object.__setattr__(self, "fps", fps)
        object.__setattr__(self, "min_speed", float(self.min_speed))

    @classmethod
    def from_motion(cls, motion: Motion, *, min_speed: float = 0.1) -> MotionPath:
        """The ground path of ``motion``'s root (x, z) with its root headings."""
        if not isinstance(motion, Motion):
            raise TypeError(f"Expected a Motion, got {type(motion).__name__}")
        if motion.n_frames < 3:
            raise ValueError(f"Expected a motion of at least 3 frames for a path, got {motion.n_frames}")
        pos = motion.root_positions[:, [0, 2]]
        head = quat.yaw(motion.rotations[:, 0])
        return cls(pos, head, motion.fps, min_speed)

    # ------------------------------------------------------------ frames
    @property
    def n_frames(self) -> int:
        return int(self.positions.shape[0])

    @cached_property
    def raw_tangents(self) -> Array:
        """Unfilled central differences, shape (F, 2)."""
        t = central_tangents(self.positions)
        t.flags.writeable = False
        return t

    @cached_property
    def degenerate(self) -> NDArray[np.bool_]:
        """Frames whose tangent is shorter than ``2 min_speed / fps``, shape (F,)."""
        d = np.linalg.norm(self.raw_tangents, axis=1) < 2.0 * self.min_speed / self.fps
        d.flags.writeable = False
        return d

    @property
    def has_tangents(self) -> bool:
        """False when every frame is degenerate (a fully stationary clip)."""
        return not bool(self.degenerate.all())

    @cached_property
    def _fill(self) -> sp.csr_matrix | None:
        if not self.has_tangents:
            return None
        return _fill_operator(self.n_frames, ~self.degenerate)

    def tangent_operator(self) -> sp.csr_matrix:
        """Sparse (F, F) matrix ``D`` with ``tangents = D @ positions``.

        Raises
        ------
        ValueError
            If every frame is degenerate (no tangent can be derived).
        """
        if not self.has_tangents:
            raise ValueError("every frame of this path is stationary: its tangents are undefined")
        diff = _difference_operator(self.n_frames)
        return diff if self._fill is None else (self._fill @ diff).tocsr()

    @cached_property
    def tangents(self) -> Array:
        """Tangents with degenerate ones filled, shape (F, 2).

        A fully stationary path uses the heading direction, scaled to the
        degeneracy threshold, as its tangent.
        """
        if not self.has_tangents:
            t = np.stack([np.sin(self.headings), np.cos(self.headings)], axis=1) * (2 * self.min_speed / self.fps)
        else:
            t = self.raw_tangents if self._fill is None else self._fill @ self.raw_tangents
            t = np.array(t)
        t.flags.writeable = False
        return t

    @cached_property
    def normals(self) -> Array:
        n = rot90(self.tangents)
        n.flags.writeable = False
        return n

    @cached_property
    def tangent_angles(self) -> Array:
        """Yaw of each tangent, shape (F,)."""
        a = ground_angle(self.tangents)
        a.flags.writeable = False
        return a

    @cached_property
    def directions(self) -> Array:
        """Root heading relative to the tangent, shape (F,), radians."""
        d = wrap_angle(self.headings - self.tangent_angles)
        d.flags.writeable = False
        return d

    @cached_property
    def length(self) -> float:
        """Arc length of the path, metres."""
        return float(np.sum(np.linalg.norm(np.diff(self.positions, axis=0), axis=1)))

    def laplacian_coordinates(self) -> Array:
        """Equation 3 local coordinates ``(x_i, y_i)``, shape (F, 2), NaN at the ends."""
        return laplacian_coordinates(self.positions)

    def local_offset(self, frame: int, point: ArrayLike) -> tuple[float, float]:
        """``point`` (x, z) as ``(forward, left)`` metres in the tangent frame at ``frame``."""
        t = self.tangents[frame] / np.linalg.norm(self.tangents[frame])
        d = np.asarray(point, dtype=float) - self.positions[frame]
        return (float(d @ t), float(d @ rot90(t)))

    def local_direction(self, frame: int, direction: ArrayLike) -> tuple[float, float]:
        """Ground ``direction`` (x, z) as a unit ``(forward, left)`` pair in the tangent frame at ``frame``."""
        t = self.tangents[frame] / np.linalg.norm(self.tangents[frame])
        v = np.asarray(direction, dtype=float)
        v = v / np.linalg.norm(v)
        return (float(v @ t), float(v @ rot90(t)))

    def from_local(self, frame: int, offset: ArrayLike) -> Array:
        """Ground point of a ``(forward, left)`` offset in the tangent frame at ``frame``, shape (2,)."""
        t = self.tangents[frame] / np.linalg.norm(self.tangents[frame])
        o = np.asarray(offset, dtype=float)
        return self.positions[frame] + o[0] * t + o[1] * rot90(t)

    def with_positions(self, positions: ArrayLike) -> MotionPath:
        """A path through new positions whose headings keep ``directions`` (tangent-relative)."""
        p = np.asarray(positions, dtype=float)
        new = MotionPath(p, np.zeros(len(p)), self.fps, self.min_speed)
        heads = wrap_angle(self.directions + new.tangent_angles)
        return MotionPath(p, heads, self.fps, self.min_speed)


def _runs(mask: NDArray[np.bool_]) -> list[tuple[int, int]]:
    m = np.concatenate([[False], np.asarray(mask, bool), [False]])
    d = np.diff(m.astype(np.int8))
    starts = np.flatnonzero(d == 1)
    stops = np.flatnonzero(d == -1)
    return [(int(a), int(b)) for a, b in zip(starts, stops, strict=True)]


def stationary_segments(
    motion: Motion,
    *,
    speed: float = 0.15,
    min_duration: float = 0.3,
    contacts: Any = None,
    smoothing: float = 0.05,
) -> list[tuple[int, int]]:
    """Stationary sub-paths (section 4.2): slow root or both feet planted.

    A frame is stationary when the root's ground speed, smoothed by a
    Gaussian of ``smoothing`` seconds, is below ``speed`` m/s, or when both
    feet are firmly planted (every contact joint of each foot, ankle and toe,
    in contact) (``contacts``: a :class:`mocaplab.contacts.Contacts`
    whose joint names contain Left/Right, or ``"auto"`` to detect them with
    :func:`mocaplab.contacts.foot_contacts`).  Runs shorter than
    ``min_duration`` seconds (or 3 frames) are dropped: walking has short
    double-support phases that must stay deformable.

    Returns
    -------
    list of (start, stop)
        Half-open frame intervals.
    """
    if not isinstance(motion, Motion):
        raise TypeError(f"Expected a Motion, got {type(motion).__name__}")
    p = motion.root_positions[:, [0, 2]]
    if motion.n_frames < 3:
        return []
    v = np.linalg.norm(np.gradient(p, axis=0), axis=1) * motion.fps
    sigma = smoothing * motion.fps
    if sigma > 0:
        v = gaussian_filter1d(v, sigma, mode="nearest")
    still = v < speed
    if contacts is not None:
        if isinstance(contacts, str):
            if contacts != "auto":
                raise ValueError(f"Expected `contacts` to be a Contacts, 'auto' or None, got {contacts!r}")
            try:
                from ..contacts import foot_contacts
            except ImportError:  # pragma: no cover - contacts module missing
                contacts = None
            else:
                contacts = foot_contacts(motion)
        if contacts is not None:
            # "firmly planted": every contact joint of the foot (ankle and toe) down
            left = np.ones(motion.n_frames, bool)
            right = np.ones(motion.n_frames, bool)
            n_left = n_right = 0
            for name in contacts.joints:
                low = name.lower()
                if "left" in low or name.startswith("L"):
                    left &= contacts.of(name)
                    n_left += 1
                elif "right" in low or name.startswith("R"):
                    right &= contacts.of(name)
                    n_right += 1
            if n_left and n_right:
                still = still | (left & right)
    min_len = max(3, int(np.ceil(min_duration * motion.fps)))
    return [(a, b) for a, b in _runs(still) if b - a >= min_len]
