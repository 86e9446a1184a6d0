"""Forward kinematics, vectorised over frames.

A joint's global rotation is its parent's global rotation times its local
rotation; its global position is the parent's position plus the parent's
global rotation applied to the joint's local translation (its skeleton
offset, or a per-frame translation where the file animates one).  Joints are
ordered so that ``parents[j] < j``; one pass over the joints, each step
vectorised over all frames, computes the whole clip.
"""

from __future__ import annotations

from collections.abc import Iterable
from functools import lru_cache

import numpy as np
from numpy.typing import NDArray

from . import quat

__all__ = ["angular_velocities", "fk", "fk_below", "joint_depths", "subtree_levels", "velocities"]


def fk(
    rotations: NDArray[np.float64],
    root_positions: NDArray[np.float64],
    offsets: NDArray[np.float64],
    parents: NDArray[np.int64],
    *,
    translations: NDArray[np.float64] | None = None,
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Global rotations and positions of every joint, for one pose, a clip or a batch.

    Parameters
    ----------
    rotations : ndarray, shape (..., J, 4)
        Local joint rotations, unit quaternions ``(x, y, z, w)``: one pose
        ``(J, 4)``, a clip ``(F, J, 4)`` or any batch of them.
    root_positions : ndarray, shape (..., 3)
        World position of joint 0, with the same leading shape.
    offsets : ndarray, shape (J, 3)
        Rest translation of each joint in its parent's frame.
    parents : ndarray of int, shape (J,)
        ``parents[0] == -1`` and ``parents[j] < j``.
    translations : ndarray, shape (..., J, 3), optional
        Per-frame local translations replacing ``offsets`` (the root row is
        ignored: ``root_positions`` places the root).

    Returns
    -------
    global_rotations : ndarray, shape (..., J, 4)
    global_positions : ndarray, shape (..., J, 3)
        New arrays (views of component-major buffers, so not C-contiguous;
        ``np.ascontiguousarray`` them if that matters).

    Examples
    --------
    >>> import numpy as np
    >>> pose = np.tile([0.0, 0.0, 0.0, 1.0], (2, 1))  # one pose of two joints
    >>> _, pos = fk(pose, np.zeros(3), np.array([[0, 0, 0], [0, 1.0, 0]]), np.array([-1, 0]))
    >>> pos[1].tolist()
    [0.0, 1.0, 0.0]
    """
    rotations = np.asarray(rotations, dtype=float)
    root_positions = np.asarray(root_positions, dtype=float)
    offsets = np.asarray(offsets, dtype=float)
    parents = np.asarray(parents, dtype=np.int64)
    if rotations.ndim < 2 or rotations.shape[-1] != 4:
        raise ValueError(f"Expected `rotations` of shape (..., J, 4), got {rotations.shape}")
    lead, n_joints = rotations.shape[:-2], rotations.shape[-2]
    if root_positions.shape != lead + (3,):
        raise ValueError(f"Expected `root_positions` of shape {lead + (3,)}, got {root_positions.shape}")
    if offsets.shape != (n_joints, 3) or parents.shape != (n_joints,):
        raise ValueError(
            f"Expected `offsets` ({n_joints}, 3) and `parents` ({n_joints},), got {offsets.shape} and {parents.shape}"
        )
    if translations is not None:
        translations = np.asarray(translations, dtype=float)
        if translations.shape != lead + (n_joints, 3):
            raise ValueError(f"Expected `translations` of shape {lead + (n_joints, 3)}, got {translations.shape}")
    if len(lead) != 1:  # one pose or a batch: the kernel below runs over one flat frame axis
        n = int(np.prod(lead))
        grot, gpos = fk(
            rotations.reshape(n, n_joints, 4), root_positions.reshape(n, 3), offsets, parents,
            translations=None if translations is None else translations.reshape(n, n_joints, 3),
        )
        return grot.reshape(lead + (n_joints, 4)), gpos.reshape(lead + (n_joints, 3))
    n_frames = lead[0]
    # Component-major layout, (4, J, F) and (3, J, F): each quaternion or
    # vector component of a set of joints is one contiguous (n, F) block, so
    # the products below run on contiguous memory without temporaries of
    # strided views.  The results are returned as transposed views.
    lq = np.ascontiguousarray(rotations.transpose(2, 1, 0))
    lt = None if translations is None else np.ascontiguousarray(np.asarray(translations, dtype=float).transpose(2, 1, 0))
    gq = np.empty_like(lq)
    gp = np.empty((3, n_joints, n_frames))
    gq[:, 0] = lq[:, 0]
    gp[:, 0] = root_positions.T
    # joints of equal depth have their parents done already: one vectorised
    # step per level of the tree instead of one per joint
    for level in _levels(parents):
        p = parents[level]
        parent = gq[:, p]  # parents' global rotations, (4, n, F)
        ax, ay, az, aw = parent
        # global rotation: parent * local
        gq[0, level], gq[1, level], gq[2, level], gq[3, level] = quat.mul_components(parent, lq[:, level])
        # position: parent + parent rotation applied to the local translation,
        # v' = v + w t + u x t with t = 2 u x v
        if lt is None:
            vx, vy, vz = offsets[level].T[:, :, None]  # (n, 1), the same every frame
        else:
            vx, vy, vz = lt[:, level]
        tx = 2.0 * (ay * vz - az * vy)
        ty = 2.0 * (az * vx - ax * vz)
        tz = 2.0 * (ax * vy - ay * vx)
        px, py, pz = gp[:, p]
        gp[0, level] = px + vx + aw * tx + (ay * tz - az * ty)
        gp[1, level] = py + vy + aw * ty + (az * tx - ax * tz)
        gp[2, level] = pz + vz + aw * tz + (ax * ty - ay * tx)
    return gq.transpose(2, 1, 0), gp.transpose(2, 1, 0)


def fk_below(
    rotations: NDArray[np.float64],
    fk_result: tuple[NDArray[np.float64], NDArray[np.float64]],
    offsets: NDArray[np.float64],
    parents: NDArray[np.int64],
    tops: Iterable[int],
    *,
    translations: NDArray[np.float64] | None = None,
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Partial forward kinematics: recompute only the subtrees of ``tops``.

    The one partial-FK function of the package: after an IK step has turned
    a few joints (the legs), the joints outside the subtrees of ``tops``
    keep the global transforms in ``fk_result``; the subtrees are recomputed
    from ``rotations`` level by level (all joints of one depth at once),
    vectorised over frames.  The root (joint 0) is never recomputed: give
    ``fk_result`` with the root already placed.

    Parameters
    ----------
    rotations : ndarray, shape (F, J, 4)
        Local rotations (the new ones).
    fk_result : (global_rotations, global_positions)
        Shapes (F, J, 4) and (F, J, 3): transforms valid outside the subtrees.
    offsets, parents
        The skeleton's, as for :func:`fk`.
    tops : iterable of int
        Joints whose subtrees (the joints themselves included) changed.
    translations : ndarray, shape (F, J, 3), optional
        Animated local translations, as for :func:`fk`.

    Returns
    -------
    global_rotations, global_positions : ndarray
        New arrays; the inputs are not modified.
    """
    grot, gpos = (np.array(a, copy=True) for a in fk_result)
    parents = np.asarray(parents, dtype=np.int64)
    for level in subtree_levels(parents, tuple(sorted({int(t) for t in tops}))):
        p = parents[level]
        local = offsets[level] if translations is None else translations[:, level]
        grot[:, level] = quat.mul(grot[:, p], rotations[:, level])
        gpos[:, level] = gpos[:, p] + quat.rotate(grot[:, p], local)
    return grot, gpos


def subtree_levels(parents: NDArray[np.int64], tops: tuple[int, ...]) -> tuple[NDArray[np.int64], ...]:
    """Joints of the subtrees of ``tops`` (root excluded), grouped by depth, shallowest first."""
    return _subtree_levels(np.asarray(parents, dtype=np.int64).tobytes(), tuple(int(t) for t in tops))


@lru_cache(maxsize=128)
def _subtree_levels(parents_bytes: bytes, tops: tuple[int, ...]) -> tuple[NDArray[np.int64], ...]:
    parents = np.frombuffer(parents_bytes, dtype=np.int64)
    below = np.zeros(len(parents), dtype=bool)
    below[list(tops)] = True
    for j in range(1, len(parents)):
        below[j] |= below[parents[j]]
    below[0] = False
    depth = joint_depths(parents)
    levels = []
    for d in np.unique(depth[below]):
        level = np.flatnonzero(below & (depth == d))
        level.flags.writeable = False
        levels.append(level)
    return tuple(levels)


def _levels(parents: NDArray[np.int64]) -> list[NDArray[np.int64]]:
    """Joint indices grouped by depth below the root (root excluded)."""
    depth = joint_depths(parents)
    return [np.flatnonzero(depth == d) for d in range(1, int(depth.max(initial=0)) + 1)]


def joint_depths(parents: NDArray[np.int64]) -> NDArray[np.int64]:
    """Number of bones from the root to each joint, shape (J,).

    Parameters
    ----------
    parents : ndarray of int, shape (J,)
        ``parents[0] == -1`` and ``parents[j] < j``.

    Examples
    --------
    >>> joint_depths(np.array([-1, 0, 1, 0])).tolist()
    [0, 1, 2, 1]
    """
    parents = np.asarray(parents, dtype=np.int64)
    depth = np.zeros(len(parents), dtype=np.int64)
    for j in range(1, len(parents)):
        depth[j] = depth[parents[j]] + 1
    return depth


def _spans(n: int, fps: float, span: float | None) -> tuple[NDArray[np.int64], NDArray[np.int64], NDArray[np.float64]]:
    """Frames ahead and behind each frame for a central difference over ``span`` seconds, and its seconds."""
    h = 1 if span is None else max(1, int(round(0.5 * span * fps)))
    idx = np.arange(n)
    ahead, behind = np.minimum(idx + h, n - 1), np.maximum(idx - h, 0)
    return ahead, behind, (ahead - behind) / fps


def velocities(positions: NDArray[np.float64], fps: float, *, span: float | None = None) -> NDArray[np.float64]:
    """Per-frame velocities (units per second) by central differences.

    One-sided differences at the ends; a single frame has zero velocity.

    Parameters
    ----------
    positions : ndarray, shape (F, ...)
    fps : float
    span : float, optional
        Seconds the difference spans, ``round(span * fps / 2)`` frames (at
        least one) on each side, fewer at the ends: the same clip at another
        frame rate gives about the same velocities (over one frame each side,
        the default, capture noise grows with the rate).

    Examples
    --------
    >>> velocities(np.array([0.0, 1.0, 4.0, 9.0, 16.0]), 10.0).tolist()
    [10.0, 20.0, 40.0, 60.0, 70.0]
    >>> velocities(np.array([0.0, 1.0, 4.0, 9.0, 16.0]), 10.0, span=0.4).tolist()
    [20.0, 30.0, 40.0, 50.0, 60.0]
    """
    positions = np.asarray(positions, dtype=float)
    n = positions.shape[0]
    if n < 2:
        return np.zeros_like(positions)
    ahead, behind, dt = _spans(n, fps, span)
    return (positions[ahead] - positions[behind]) / dt.reshape((n,) + (1,) * (positions.ndim - 1))


def angular_velocities(
    rotations: NDArray[np.float64], fps: float, *, span: float | None = None
) -> NDArray[np.float64]:
    """Per-frame angular velocities (radians per second, world axes) of global rotations, by central differences.

    The rotation vector of ``q[i + 1] q[i - 1]^-1`` over two frame
    intervals, one-sided at the ends (as :func:`velocities`); a single frame
    has zero angular velocity.  Applied to local rotations it gives the
    angular velocities in each parent's axes.

    Parameters
    ----------
    rotations : ndarray, shape (F, ..., 4)
        Global (world) rotations, unit quaternions ``(x, y, z, w)``.
    fps : float
    span : float, optional
        Seconds the difference spans (see :func:`velocities`).

    Returns
    -------
    ndarray, shape (F, ..., 3)

    Examples
    --------
    A turn about y at 2 rad/s, sampled at 10 fps:

    >>> from mocaplab import quat
    >>> q = quat.from_axis_angle([0.0, 1.0, 0.0], 0.2 * np.arange(4))
    >>> angular_velocities(q, 10.0).round(6).tolist()[1]
    [0.0, 2.0, 0.0]
    """
    q = np.asarray(rotations, dtype=float)
    n = q.shape[0]
    if n < 2:
        return np.zeros(q.shape[:-1] + (3,))
    ahead, behind, dt = _spans(n, fps, span)
    return quat.log(quat.mul(q[ahead], quat.inv(q[behind]))) / dt.reshape((n,) + (1,) * (q.ndim - 1))
