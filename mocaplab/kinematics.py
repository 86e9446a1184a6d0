"""Forward kinematics, vectorised over frames.

A joint's global rotation is its parent's global rotation times its local
rotation; its global position is the parent's position plus the parent's
global rotation applied to the joint's local translation (its skeleton
offset, or a per-frame translation where the file animates one).  Joints are
ordered so that ``parents[j] < j``; one pass over the joints, each step
vectorised over all frames, computes the whole clip.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from . import quat

__all__ = ["fk", "velocities"]


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

    Examples
    --------
    >>> import numpy as np
    >>> rot = np.tile([0.0, 0.0, 0.0, 1.0], (1, 2, 1))
    >>> _, pos = fk(rot, np.zeros((1, 3)), np.array([[0, 0, 0], [0, 1.0, 0]]), np.array([-1, 0]))
    >>> pos[0, 1].tolist()
    [0.0, 1.0, 0.0]
    """
    n_frames, n_joints = rotations.shape[:2]
    # work joint-major, (J, F, k), so each level gathers contiguous blocks
    lrot = np.ascontiguousarray(np.swapaxes(rotations, 0, 1))
    ltr = None if translations is None else np.ascontiguousarray(np.swapaxes(translations, 0, 1))
    grot = np.empty((n_joints, n_frames, 4))
    gpos = np.empty((n_joints, n_frames, 3))
    grot[0] = lrot[0]
    gpos[0] = root_positions
    # joints of equal depth have their parents done already: one vectorised
    # step per level of the tree instead of one per joint
    for level in _levels(parents):
        p = parents[level]
        local = offsets[level][:, None, :] if ltr is None else ltr[level]
        pr = grot[p]
        grot[level] = quat.mul(pr, lrot[level])
        gpos[level] = gpos[p] + quat.rotate(pr, local)
    return np.swapaxes(grot, 0, 1), np.swapaxes(gpos, 0, 1)


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
