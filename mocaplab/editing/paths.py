"""Motion paths: the pelvis projected on the ground (Kim et al. 2009, section 3.1).

The path follows the motion's *path joint*, :attr:`mocaplab.motion.Motion.path_joint`
(the ``pelvis`` role of :mod:`mocaplab.roles`): joint 0 for CMU clips, the
travelling pelvis below a static reference joint for the common export
layout that has one.  "Root" below means that joint, whatever its index.

A :class:`MotionPath` holds, per frame ``i``,

* ``positions[i] = p_i``: the path joint's ground position ``(x, z)``, metres;
* ``tangents[i] = t_i = p_{i+1} - p_{i-1}`` (central difference; at the two
  ends ``2 (p_1 - p_0)`` and ``2 (p_{F-1} - p_{F-2})`` so every tangent spans
  two frame steps);
* ``normals[i] = n_i = R t_i`` with ``R`` the +90 degree turn about +Y:
  ``R (x, z) = (z, -x)`` (a character walking along ``t`` has ``n`` on its
  left);
* ``directions[i] = theta_i``: the root heading (yaw of the path joint's
  world rotation, :func:`mocaplab.quat.yaw`) measured from the tangent
  direction, so the heading follows a deformed path.

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

Back from a path to a motion: :func:`apply_path` moves the whole body by one
rigid ground motion per frame (a turn ``dyaw_i`` about the vertical axis and
a horizontal translation, applied at joint 0 by
:meth:`~mocaplab.motion.Motion.transformed`) chosen so that the path joint
lands on the new path point, ``t_i = p'_i - R(dyaw_i) p_i``, height kept.
Every joint, per-joint translation channels included, moves with it, so the
same code serves any skeleton layout.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping, Sequence
from functools import cached_property
from typing import Any

import numpy as np
import scipy.sparse as sp
from numpy.typing import ArrayLike, NDArray
from scipy.ndimage import gaussian_filter1d

from .. import quat
from ..contacts import intervals_from_mask
from ..motion import Motion
from ..roles import Roles, parse_name, resolve_roles

__all__ = [
    "MotionPath",
    "apply_path",
    "contact_joints",
    "with_roles",
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
    def from_motion(
        cls, motion: Motion, *, min_speed: float = 0.1, roles: Mapping[str, Any] | None = None
    ) -> MotionPath:
        """The ground path of ``motion``'s path joint (x, z) with its headings.

        The path joint is :attr:`~mocaplab.motion.Motion.path_joint` (the
        pelvis role; ``roles`` overrides roles, see :func:`with_roles`), its
        heading the yaw of its world rotation.
        """
        if not isinstance(motion, Motion):
            raise TypeError(f"Expected a Motion, got {type(motion).__name__}")
        if motion.n_frames < 3:
            raise ValueError(f"Expected a motion of at least 3 frames for a path, got {motion.n_frames}")
        motion = with_roles(motion, roles)
        pos = motion.pelvis_positions[:, [0, 2]]
        head = quat.yaw(motion.pelvis_rotations)
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


def with_roles(motion: Motion, roles: Mapping[str, Any] | None) -> Motion:
    """``motion`` with joint roles fixed by hand (``roles=None``: ``motion`` itself).

    The editing entry points (``edit``, ``SceneEditor``, ``build_graph``,
    the widgets) accept ``roles=`` and call this once on their inputs: the
    skeleton gets the overrides (:meth:`~mocaplab.motion.Skeleton.with_roles`),
    so :attr:`~mocaplab.motion.Motion.path_joint` and every role the editing
    code asks for follow them, and the edited motions carry them on.

    Parameters
    ----------
    motion : Motion
    roles : mapping of role name to joint name, or Roles, optional
        See :func:`mocaplab.roles.resolve_roles`.

    Returns
    -------
    Motion
        Same arrays, a skeleton with ``role_overrides``.
    """
    if roles is None:
        return motion
    if not isinstance(roles, Mapping):
        raise TypeError(f"Expected `roles` to be a mapping of role names to joint names, got {type(roles).__name__}")
    sk = motion.skeleton.with_roles(**dict(roles))
    resolve_roles(sk)  # unknown roles or joints raise here, naming them
    return motion.replace(skeleton=sk)


def contact_joints(motion: Motion, joints: Sequence[str] | None = None, *, roles: Any = None) -> tuple[str, ...]:
    """The joints whose foot contacts are detected: ``joints``, or the feet of the roles.

    Parameters
    ----------
    motion : Motion
    joints : sequence of str, optional
        Joint names (checked against the skeleton).  Default: the ankle and
        toe of each foot, :meth:`mocaplab.roles.Roles.foot_joints`.
    roles : mapping or Roles, optional
        Role overrides (:func:`mocaplab.roles.resolve_roles`).

    Returns
    -------
    tuple of str
    """
    if joints is None:
        return resolve_roles(motion, roles).foot_joints()
    names = (joints,) if isinstance(joints, str) else tuple(joints)
    if not names or not all(isinstance(n, str) for n in names):
        raise ValueError(f"Expected `joints` as a non-empty sequence of joint names, got {joints!r}")
    missing = [n for n in names if n not in motion.skeleton.names]
    if missing:
        raise ValueError(
            f"Expected `joints` among the skeleton's joints, got {missing} which it does not have; "
            f"joints are {list(motion.skeleton.names)}"
        )
    return names


def _side(name: str, roles: Roles | None) -> str | None:
    """Side of a joint: its limb role's, else the side word of its name (the naming table's)."""
    side = roles.side_of(name) if roles is not None else None
    return side if side is not None else parse_name(name)[0]


def apply_path(motion: Motion, positions: ArrayLike, heading_change: ArrayLike) -> Motion:
    """``motion`` moved, frame by frame, rigidly over the ground onto a new path.

    Frame ``i`` turns by ``heading_change[i]`` about the vertical axis and
    translates by ``t_i = positions[i] - R(heading_change[i]) p_i`` (``p_i``
    the path joint's ground position, ``y`` unchanged), through
    :meth:`~mocaplab.motion.Motion.transformed` (at joint 0, or at the pelvis
    below a static reference root, which stays static): the path joint lands
    on ``positions[i]`` and every joint moves with it, whatever the layout.

    Parameters
    ----------
    motion : Motion
    positions : array_like, shape (F, 2)
        New ground positions ``(x, z)`` of the path joint, metres.
    heading_change : array_like, shape (F,)
        Yaw added to each frame, radians.

    Returns
    -------
    Motion

    Examples
    --------
    >>> import numpy as np
    >>> from mocaplab.motion import Motion, Skeleton
    >>> m = Motion(Skeleton(["hips"], [-1], [[0, 0, 0]]), np.tile([0, 0, 0, 1.0], (2, 1, 1)), [[1, 1, 0], [1, 1, 1]], 30)
    >>> apply_path(m, [[0, 0], [0, 2]], [0.0, np.pi / 2]).root_positions.round(6).tolist()
    [[0.0, 1.0, 0.0], [0.0, 1.0, 2.0]]
    """
    F = motion.n_frames
    p = np.asarray(positions, dtype=float)
    if p.shape != (F, 2):
        raise ValueError(f"Expected `positions` of shape ({F}, 2), got {p.shape}")
    dyaw = np.asarray(heading_change, dtype=float)
    if dyaw.shape != (F,):
        raise ValueError(f"Expected `heading_change` of shape ({F},), got {dyaw.shape}")
    old = motion.pelvis_positions
    turned = quat.rotate(quat.from_yaw(dyaw), old)
    t = np.zeros((F, 3))
    t[:, 0] = p[:, 0] - turned[:, 0]
    t[:, 2] = p[:, 1] - turned[:, 2]
    return motion.transformed(yaw=dyaw, translation=t)


def stationary_segments(
    motion: Motion,
    *,
    speed: float = 0.15,
    min_duration: float = 0.3,
    contacts: Any = None,
    smoothing: float = 0.05,
    joints: Sequence[str] | None = None,
    roles: Mapping[str, Any] | None = None,
) -> list[tuple[int, int]]:
    """Stationary sub-paths (section 4.2): slow path joint or both feet planted.

    A frame is stationary when the path joint's ground speed, smoothed by a
    Gaussian of ``smoothing`` seconds, is below ``speed`` m/s, or when both
    feet are firmly planted (every contact joint of each foot, ankle and
    toe, in contact).  ``contacts``: a :class:`mocaplab.contacts.Contacts`,
    or ``"auto"`` to detect them with :func:`mocaplab.contacts.foot_contacts`
    on ``joints`` (default: the feet of the roles, :func:`contact_joints`).
    A contact joint's side is that of its limb role, else the side word of
    its name (:func:`mocaplab.roles.parse_name`).  Runs shorter than
    ``min_duration`` seconds (or 3 frames) are dropped: walking has short
    double-support phases that must stay deformable.

    Parameters
    ----------
    motion : Motion
    speed : float
        Ground speed threshold of the path joint, m/s (default 0.15).
    min_duration : float
        Shortest segment kept, seconds (default 0.3).
    contacts : Contacts, "auto" or None
        Foot contacts for the "both feet planted" test; None (default)
        uses the speed alone.
    smoothing : float
        Standard deviation of the Gaussian smoothing the speed, seconds (0: none).
    joints : sequence of str, optional
        Contact joints for ``contacts="auto"``.
    roles : mapping, optional
        Role overrides (:func:`mocaplab.roles.resolve_roles`).

    Returns
    -------
    list of (start, stop)
        Half-open frame intervals.

    Raises
    ------
    TypeError
        If ``motion`` is not a Motion.
    ValueError
        For a ``contacts`` string other than ``"auto"``.

    Examples
    --------
    A character stands for a second, then walks 1 m in a second:

    >>> import numpy as np
    >>> from mocaplab import Motion, Skeleton
    >>> x = np.concatenate([np.zeros(30), np.linspace(0, 1, 31)[1:]])
    >>> root = np.column_stack([x, np.ones(60), np.zeros(60)])
    >>> m = Motion(Skeleton(["hips"], [-1], [[0, 0, 0]]), np.tile([0, 0, 0, 1.0], (60, 1, 1)), root, 30)
    >>> stationary_segments(m)
    [(0, 28)]
    """
    if not isinstance(motion, Motion):
        raise TypeError(f"Expected a Motion, got {type(motion).__name__}")
    if motion.n_frames < 3:
        return []
    motion = with_roles(motion, roles)
    p = motion.pelvis_positions[:, [0, 2]]
    v = np.linalg.norm(np.gradient(p, axis=0), axis=1) * motion.fps
    sigma = smoothing * motion.fps
    if sigma > 0:
        v = gaussian_filter1d(v, sigma, mode="nearest")
    still = v < speed
    if contacts is not None:
        if isinstance(contacts, str):
            if contacts != "auto":
                raise ValueError(f"Expected `contacts` to be a Contacts, 'auto' or None, got {contacts!r}")
            from ..contacts import foot_contacts

            contacts = foot_contacts(motion, joints=contact_joints(motion, joints))
        try:
            found: Roles | None = motion.skeleton.roles
        except ValueError:  # roles that cannot be inferred: sides from the names alone
            found = None
        # "firmly planted": every contact joint of the foot (ankle and toe) down
        planted = {"left": np.ones(motion.n_frames, bool), "right": np.ones(motion.n_frames, bool)}
        count = {"left": 0, "right": 0}
        for name in contacts.joints:
            side = _side(name, found)
            if side in planted:
                planted[side] &= contacts.of(name)
                count[side] += 1
        if count["left"] and count["right"]:
            still = still | (planted["left"] & planted["right"])
    min_len = max(3, int(np.ceil(min_duration * motion.fps)))
    return [(a, b) for a, b in intervals_from_mask(still) if b - a >= min_len]
