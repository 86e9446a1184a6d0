"""Joint hierarchies given as node transforms, turned into a Motion (shared by the FBX and glTF readers).

FBX and glTF describe a skeleton as a tree of nodes, each with a local
transform (translation, rotation, scale) that may be animated, and with nodes
above the skeleton (an armature, a group, an axis conversion) that move it
too.  :func:`motion_from_transforms` composes the transforms into world
matrices and rebuilds the Motion whose forward kinematics gives the same
joint positions:

* **Joint frames** are those of the rest pose turned to the world axes, as in
  BVH: with every local rotation the identity the skeleton stands in the
  file's rest pose, and a joint's offset is its rest position minus its
  parent's (world axes, metres).
* **Rotations.** A joint's world rotation is its world matrix with the scale
  divided out, times the inverse of its rest rotation; the local rotation is
  ``inv(parent world rotation) * world rotation``.
* **Offsets.** The child's world position seen from the parent's frame; when
  it stays within :data:`OFFSET_TOLERANCE` metres of its first value over the
  clip it is the skeleton's offset, otherwise the animated offsets of every
  joint go to :attr:`Motion.translations`.
"""

from __future__ import annotations

import os
from collections.abc import Sequence

import numpy as np
from numpy.typing import NDArray

from .. import quat
from ..motion import Motion, Skeleton, _owned
from .errors import MocapFormatError

__all__ = ["motion_from_transforms", "world_matrices", "check_reach", "OFFSET_TOLERANCE"]

#: Metres a joint's offset from its parent may wander over the clip (float32
#: rounding of the file's values) and still be one constant skeleton offset.
OFFSET_TOLERANCE = 1e-5

# FBX rotation order index -> its axes (eEulerXYZ turns about X first: R = Rz Ry Rx)
_ORDER_NAMES = ("XYZ", "XZY", "YZX", "YXZ", "ZXY", "ZYX")


def motion_from_transforms(
    path: str,
    local: NDArray[np.float64],
    rest: NDArray[np.float64],
    parents: Sequence[int],
    *,
    inherit: Sequence[int] | None = None,
    joints: Sequence[int],
    names: Sequence[str],
    rotation_orders: Sequence[int] | None = None,
    fps: float,
    unit: float = 1.0,
    name: str | None = None,
) -> Motion:
    """The Motion of a tree of node transforms (parents first), some of whose nodes are the joints.

    Parameters
    ----------
    path : str
        The file, for error messages and the default name.
    local : ndarray, shape (F, N, 10)
        Each node's local ``(translation (3), rotation (x, y, z, w), scale (3))``
        per frame, in file units.
    rest : ndarray, shape (1, N, 10)
        The same in the rest pose.
    parents : sequence of int, length N
        Each node's parent among the N (-1 for the top one); parents first.
    inherit : sequence of int, optional
        Per node: 0 normal scale inheritance, 1 ignore the parent's scale.
    joints : sequence of int, length J
        Which of the N nodes are joints, increasing; the first is the root
        joint.  The other nodes (above the root, or between two joints) move
        the joints below them but are not joints.
    names : sequence of str, length J
        Joint names.
    rotation_orders : sequence of int, optional
        Per joint, the FBX rotation order (0 XYZ ... 5 ZYX) for its BVH channels.
    fps : float
    unit : float
        Metres per file unit.
    name : str, optional
        Label (default: the file stem).

    Returns
    -------
    Motion
    """
    inherit = [0] * len(parents) if inherit is None else list(inherit)
    joints = list(joints)
    world = world_matrices(local, parents, inherit)[:, joints]
    rest_world = world_matrices(rest, parents, inherit)[0, joints]
    world[..., 3] *= unit
    rest_world[..., 3] *= unit
    is_joint = {k: j for j, k in enumerate(joints)}
    joint_parents = []
    for k in joints:
        p = parents[k]
        while p >= 0 and p not in is_joint:
            p = parents[p]
        joint_parents.append(is_joint.get(p, -1))
    orders = [0] * len(names) if rotation_orders is None else list(rotation_orders)
    return _motion(path, world, rest_world, list(names), joint_parents, orders, fps, name)


def world_matrices(local: NDArray[np.float64], parents: Sequence[int], inherit: Sequence[int]) -> NDArray[np.float64]:
    """World matrices (F, N, 3, 4) of nodes given local TRS ``(t, q, s)`` rows (F, N, 10), parents first.

    A node inheriting its parent's transform normally gets ``W = W_parent M``;
    one that ignores its parent's scale (Maya's segment scale compensation)
    gets ``W = W_parent S_parent^-1 M``.  Component-wise scale inheritance
    (3ds Max) is treated as normal inheritance.
    """
    n_frames, n = local.shape[:2]
    m = np.empty((n_frames, n, 3, 4))
    m[..., :3] = quat.to_matrix(quat.normalize(local[..., 3:7])) * local[..., None, 7:10]
    m[..., 3] = local[..., :3]
    world = np.empty_like(m)
    for k in range(n):
        p = parents[k]
        if p < 0:
            world[:, k] = m[:, k]
            continue
        lin = world[:, p, :, :3]
        if inherit[k] == 1:
            lin = lin / local[:, p, None, 7:10]
        world[:, k, :, :3] = lin @ m[:, k, :, :3]
        world[:, k, :, 3] = (lin @ m[:, k, :, 3, None])[..., 0] + world[:, p, :, 3]
    return world


def _motion(
    path: str,
    world: NDArray[np.float64],
    rest: NDArray[np.float64],
    names: list[str],
    joint_parents: list[int],
    orders: list[int],
    fps: float,
    name: str | None,
) -> Motion:
    """The Motion whose forward kinematics gives the joints' world matrices ``world`` (F, J, 3, 4), in metres.

    Joint frames are those of the rest pose ``rest`` (J, 3, 4) turned to the
    world axes, as in BVH: with every local rotation the identity the
    skeleton stands in the file's rest pose, and offsets are rest-pose
    differences in world axes.
    """
    parents = np.array(joint_parents, dtype=np.int64)
    positions = world[..., 3]
    world_q = quat.mul(_rotations(path, world, names, "frame"), quat.inv(_rotations(path, rest, names, "rest pose")))
    par = parents[1:]
    local = world_q.copy()
    local[:, 1:] = quat.mul(quat.inv(world_q[:, par]), world_q[:, 1:])
    local = quat.unroll(local, axis=0)
    rel = np.zeros_like(positions)
    rel[:, 1:] = quat.rotate(quat.inv(world_q[:, par]), positions[:, 1:] - positions[:, par])
    offsets = rel[0].copy()
    offsets[0] = positions[0, 0]
    drift = np.abs(rel - rel[:1]).max(axis=(0, 2))
    moving = drift > OFFSET_TOLERANCE
    moving[0] = False
    translations = None
    if moving.any():
        translations = rel
        translations[:, 0] = offsets[0]
    channels = [
        _channels(order, position=j == 0 or bool(moving[j])) for j, order in enumerate(orders)
    ]
    skeleton = Skeleton(names=tuple(_unique(names)), parents=parents, offsets=offsets, channels=tuple(channels))
    motion = Motion(
        skeleton=skeleton,
        rotations=_owned(local),
        root_positions=_owned(np.ascontiguousarray(positions[:, 0])),
        fps=fps,
        translations=None if translations is None else _owned(translations),
        name=name if name is not None else os.path.splitext(os.path.basename(path))[0],
    )
    check_reach(path, motion)
    return motion


def _rotations(path: str, matrices: NDArray[np.float64], names: list[str], when: str) -> NDArray[np.float64]:
    """Unit quaternions (..., 4) of the rotation part of world matrices (..., 3, 4) with their scale divided out."""
    linear = matrices[..., :3]
    lengths = np.linalg.norm(linear, axis=-2, keepdims=True)
    if not np.all(np.isfinite(matrices)) or np.any(lengths < 1e-12):
        raise MocapFormatError(path, 0, "finite joint transforms with non-zero scale", f"a degenerate {when} transform")
    rot = linear / lengths
    det = np.linalg.det(rot)
    if np.any(det < 0):
        where = np.argwhere(det < 0)[0]
        raise MocapFormatError(
            path, 0, "joints without mirroring (no negative scale)", f"joint {names[where[-1]]!r} mirrored ({when})"
        )
    return quat.from_matrix(rot)


def _channels(order: int, *, position: bool) -> tuple[str, ...]:
    """BVH channels of a joint: positions when it moves, rotations in its FBX order reversed."""
    axes = _ORDER_NAMES[order] if 0 <= order < len(_ORDER_NAMES) else "XYZ"
    rotations = tuple(f"{a}rotation" for a in reversed(axes))
    return (("Xposition", "Yposition", "Zposition") if position else ()) + rotations


def _unique(names: list[str]) -> list[str]:
    """Joint names made unique (``Bone``, ``Bone_2``, ...) and non-empty."""
    seen: set[str] = set()
    out = []
    for i, n in enumerate(names):
        base = n or f"joint{i}"
        cand, k = base, 1
        while cand in seen:
            k += 1
            cand = f"{base}_{k}"
        seen.add(cand)
        out.append(cand)
    return out


def check_reach(path: str, motion: Motion, *, skeleton_path: str | None = None) -> None:
    """Raise :class:`MocapFormatError` naming ``path`` when the joint positions of ``motion`` overflow.

    Values finite in a file (an offset of ``1e300`` file units, a root at
    ``1.5e308``) can still add up to infinity in forward kinematics and fail
    far from the file.  Every world position is the root position plus
    rotated offsets (or animated translations) along a chain, so its size is
    at most the sum of their largest components times the square root of 3;
    when that sum (with room for rounding in the rotations) is finite, nothing
    can overflow and nothing is computed.  Otherwise the joint and end-site
    positions are computed and checked.

    Parameters
    ----------
    path : str
        The file, named in the error.
    motion : Motion
        The clip just read (metres).
    skeleton_path : str, optional
        The file that gave the skeleton when it is another one (an ASF for
        an AMC clip): named instead when the skeleton alone overflows.
    """
    sk = motion.skeleton
    with np.errstate(over="ignore", invalid="ignore"):
        reach = np.abs(sk.offsets).max(axis=1)
        if motion.translations is not None:
            reach = np.maximum(reach, np.abs(motion.translations).max(axis=(0, 2)))
        ends = np.abs(sk.end_site_offsets).max(initial=0.0)
        body = (float(reach[1:].sum()) + float(ends)) * 16.0
        bound = body + float(np.abs(motion.root_positions).max()) * 16.0
    if np.isfinite(bound):
        return
    if skeleton_path is not None and not np.isfinite(body):
        path = skeleton_path
    with np.errstate(over="ignore", invalid="ignore"):
        positions = motion.global_positions()
        ends_at = motion.end_site_positions()
    for what, arr, names in (
        ("joint", positions, sk.names),
        ("end site of joint", ends_at, [sk.names[p] for p in sk.end_site_parents]),
    ):
        bad = ~np.isfinite(arr).all(axis=-1)
        if bad.any():
            frame, j = (int(i) for i in np.argwhere(bad)[0])
            raise MocapFormatError(
                path, 0, "joint positions that stay finite in metres (forward kinematics)",
                f"an overflow at frame {frame}, {what} {names[j]!r}",
            )
