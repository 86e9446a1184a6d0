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

__all__ = ["fk", "fk_below", "subtree_levels", "velocities"]


def fk(
    rotations: NDArray[np.float64],
    root_positions: NDArray[np.float64],
    offsets: NDArray[np.float64],
    parents: NDArray[np.int64],
    *,
    translations: NDArray[np.float64] | None = None,
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Global rotations and positions of every joint on every frame.

    Parameters
    ----------
    rotations : ndarray, shape (F, J, 4)
        Local joint rotations, unit quaternions ``(x, y, z, w)``.
    root_positions : ndarray, shape (F, 3)
        World position of joint 0.
    offsets : ndarray, shape (J, 3)
        Rest translation of each joint in its parent's frame.
    parents : ndarray of int, shape (J,)
        ``parents[0] == -1`` and ``parents[j] < j``.
    translations : ndarray, shape (F, J, 3), optional
        Per-frame local translations replacing ``offsets`` (the root row is
        ignored: ``root_positions`` places the root).

    Returns
    -------
    global_rotations : ndarray, shape (F, J, 4)
    global_positions : ndarray, shape (F, J, 3)
        New arrays (transposed views of component-major buffers, so not
        C-contiguous; ``np.ascontiguousarray`` them if that matters).

    Examples
    --------
    >>> import numpy as np
    >>> rot = np.tile([0.0, 0.0, 0.0, 1.0], (1, 2, 1))
    >>> _, pos = fk(rot, np.zeros((1, 3)), np.array([[0, 0, 0], [0, 1.0, 0]]), np.array([-1, 0]))
    >>> pos[0, 1].tolist()
    [0.0, 1.0, 0.0]
    """
    rotations = np.asarray(rotations, dtype=float)
    root_positions = np.asarray(root_positions, dtype=float)
    offsets = np.asarray(offsets, dtype=float)
    parents = np.asarray(parents, dtype=np.int64)
    if rotations.ndim != 3 or rotations.shape[2] != 4:
        raise ValueError(f"Expected `rotations` of shape (F, J, 4), got {rotations.shape}")
    n_frames, n_joints = rotations.shape[:2]
    if root_positions.shape != (n_frames, 3):
        raise ValueError(f"Expected `root_positions` of shape ({n_frames}, 3), got {root_positions.shape}")
    if offsets.shape != (n_joints, 3) or parents.shape != (n_joints,):
        raise ValueError(
            f"Expected `offsets` ({n_joints}, 3) and `parents` ({n_joints},), got {offsets.shape} and {parents.shape}"
        )
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
        ax, ay, az, aw = gq[:, p]  # parents' global rotations, (n, F) each
        bx, by, bz, bw = lq[:, level]
        # global rotation: Hamilton product parent * local
        gq[0, level] = aw * bx + ax * bw + ay * bz - az * by
        gq[1, level] = aw * by - ax * bz + ay * bw + az * bx
        gq[2, level] = aw * bz + ax * by - ay * bx + az * bw
        gq[3, level] = aw * bw - ax * bx - ay * by - az * bz
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
    depth = np.zeros(len(parents), dtype=np.int64)
    for j in range(1, len(parents)):
        below[j] |= below[parents[j]]
        depth[j] = depth[parents[j]] + 1
    below[0] = False
    levels = []
    for d in np.unique(depth[below]):
        level = np.flatnonzero(below & (depth == d))
        level.flags.writeable = False
        levels.append(level)
    return tuple(levels)


def _levels(parents: NDArray[np.int64]) -> list[NDArray[np.int64]]:
    """Joint indices grouped by depth below the root (root excluded)."""
    parents = np.asarray(parents)
    depth = np.zeros(len(parents), dtype=np.int64)
    for j in range(1, len(parents)):
        depth[j] = depth[parents[j]] + 1
    return [np.flatnonzero(depth == d) for d in range(1, int(depth.max(initial=0)) + 1)]


def velocities(positions: NDArray[np.float64], fps: float) -> NDArray[np.float64]:
    """Per-frame velocities (units per second) by central differences.

    One-sided differences at the ends; a single frame has zero velocity.
    """
    positions = np.asarray(positions, dtype=float)
    if positions.shape[0] < 2:
        return np.zeros_like(positions)
    return np.gradient(positions, 1.0 / fps, axis=0)
