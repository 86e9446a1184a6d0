"""The adjustment machinery shared by both stages of a touch-up (Shin, Kovar and Gleicher 2003, Figure 2).

The ground and flight steps (:mod:`mocaplab.physics.ground`, section 3.3;
:mod:`mocaplab.physics.flight`, section 3.4) each compute, on every frame,
a world rotation of S2.  This module turns such a correction into a
motion, steps 2 and 3 of Figure 2: it is scaled by ``rho`` and smoothed
over time with a Gaussian kernel of width ``sigma`` (:func:`_smooth`; the
rotation as a world rotation vector, i.e. the logarithm of the
displacement relative to the identity, which is how Lee and Shin filter
orientation displacements; the root translation linearly), then applied
as a displacement map (:func:`_apply`: S2's top joint rotated, S3's top
joint counter-rotated), the forward kinematics following in closed form
(:class:`_Posed` carries them along).  It depends on the link sets of
:mod:`mocaplab.physics.schedule` only.

Choices made where the paper leaves them open
---------------------------------------------
* Rotation centre: the top joint of the S2 part when it has a parent in S1
  (the S1/S2 boundary, e.g. the first spine joint with the legs in S1).
  When S2 holds the root (then S1 holds no planted foot in any sensible
  split), it is the ZMP's projection on the ground on ground frames; in
  flight it is the S1/S2 boundary joint, or the centre of mass when S1 is
  empty.  On ground frames, S1 parts hanging below a root-holding S2 are
  carried like S3.
* The part holding the root turns about the travelling joint (the pelvis,
  :attr:`mocaplab.motion.Motion.path_joint`) and its displacement is the
  smoothed displacement of that joint, whether or not it is joint 0: a
  skeleton with a static reference joint above the pelvis is touched up
  exactly like the same skeleton without it.
* The per-frame rotation of an adjustment is clamped to +-0.35 rad
  (:data:`MAX_ANGLE`, 20 degrees) on ground and flight frames alike, a
  guard against frames with absurd accelerations or momenta.
* Kernel widths and windows are stored in seconds: the paper's 40/20/10 and
  10/10/5 frames were at 30 fps.  A kernel of width ``w`` is a Gaussian of
  standard deviation ``w / 4`` (``w`` spans +-2 std), truncated at **4**
  std (:data:`KERNEL_TRUNCATE`).  Cut at 2 std, its edges jump to 13.5 %
  of its peak, and the frame-to-frame noise of the per-frame corrections
  went through those jumps into the accelerations that the ZMP depends on
  (several m/s^2 out of corrections of millimetres); every pass added more,
  and on CMU walks bent into curves 12 passes ended up worse than 3 (16_15
  at 120 fps bent by 0.4 of its length, ground schedule, the frame weights
  of :mod:`mocaplab.physics.ground` switched off: mean ZMP distance 6.4 cm, 1.6 cm after 3 passes and
  2.7 cm after 12 with the 2-std cut, 1.6 and 1.0 cm with the 4-std one;
  the frame weights alone also stop that drift, and both are kept).  Near the ends
  of the clip the kernel is cut at the first or last frame and renormalised
  (a weighted mean over the frames that exist): extending the edge value
  instead (``mode="nearest"``) gives an end frame up to half the kernel's
  weight, so one badly balanced end frame leaned the whole start or end
  of a captured walk by many centimetres.
"""

from __future__ import annotations

from functools import lru_cache
from typing import NamedTuple

import numpy as np
from numpy.typing import NDArray
from scipy.ndimage import gaussian_filter1d

from .. import quat
from ..motion import Motion, _owned, readonly
from .schedule import LinkSets, _subtree

Array = NDArray[np.float64]

#: Largest per-frame rotation of one adjustment, radians (20 degrees), on
#: ground and flight frames alike: a guard against frames with absurd
#: accelerations or momenta.
MAX_ANGLE = 0.35
#: Width of the smoothing kernels in standard deviations on each side (see
#: the module notes: a kernel cut at 2 std let frame-to-frame noise of the
#: per-frame corrections into the accelerations, and passes diverged).
KERNEL_TRUNCATE = 4.0


def _smooth(x: Array, width: float) -> Array:
    """Gaussian smoothing over frames: std ``width / 4``, truncated at 4 std.

    At the ends the kernel is cut to the existing frames and renormalised
    (see the module notes): a normalised convolution, the zero-padded
    filter divided by the filtered ones.
    """
    n = x.shape[0]
    std = width / 4.0
    if std <= 0 or n < 2:
        return x
    out = gaussian_filter1d(x, std, axis=0, mode="constant", truncate=KERNEL_TRUNCATE)
    out /= _kernel_mass(n, float(std)).reshape((n,) + (1,) * (x.ndim - 1))
    return out


@lru_cache(maxsize=32)
def _kernel_mass(n: int, std: float) -> Array:
    """Weight of the truncated Gaussian kernel that falls inside ``n`` frames, per frame (n,)."""
    return readonly(gaussian_filter1d(np.ones(n), std, mode="constant", truncate=KERNEL_TRUNCATE))


def _rotate_about(omega: Array, centre: Array, point: Array) -> Array:
    """``point`` rotated by rotation vectors ``omega`` about ``centre`` (all (F, 3))."""
    return centre + quat.rotate(quat.exp(omega), point - centre)


class _Posed(NamedTuple):
    """A motion with its forward kinematics (computed once, passed along)."""

    motion: Motion
    grot: Array  # (F, J, 4)
    gpos: Array  # (F, J, 3)


def _posed(motion: Motion) -> _Posed:
    return _Posed(motion, motion.global_rotations(), motion.global_positions())


@lru_cache(maxsize=128)
def _apply_layout(sets: LinkSets) -> dict[str, NDArray[np.int64]]:
    """Index arrays for :func:`_apply` (cached per link sets).

    ``tops``: non-root S2 tops; ``rigid`` and ``rigid_part``: the S2 joints
    and their parts; ``carried`` and ``carried_part``: the
    carried tops and their parts; ``below`` and ``below_slot``: every joint
    of a carried part and the index of its top in ``carried``.
    """
    rigid = np.flatnonzero((sets.part >= 0) & (sets.roles == 2))
    carried = np.array([u for u, _ in sets.carried], dtype=np.int64)
    below = np.flatnonzero(sets.carried_top >= 0)
    slot = {u: k for k, u in enumerate(carried.tolist())}
    out = {
        "tops": np.array([t for t in sets.s2_tops if t != 0], dtype=np.int64),
        "rigid": rigid,
        "rigid_part": sets.part[rigid],
        "carried": carried,
        "carried_part": np.array([k for _, k in sets.carried], dtype=np.int64),
        "below": below,
        "below_slot": np.array([slot[int(u)] for u in sets.carried_top[below]], dtype=np.int64),
    }
    return {k: readonly(v) for k, v in out.items()}


def _apply(posed: _Posed, sets: LinkSets, omega: Array, root_delta: Array | None, pivot: int = 0) -> _Posed:
    """Rotate every S2 part by the world rotation vectors ``omega`` (F, 3).

    S2 tops are pre-rotated in world space (expressed locally by conjugating
    with the parent's global rotation), carried tops are counter-rotated so
    their global orientation is unchanged.  The part holding the root turns
    about joint ``pivot`` (the travelling joint, :func:`_root_pivot`), which
    moves by ``root_delta`` (F, 3); joint 0's position and rotation are
    changed so that the part moves rigidly that way.  The new global
    transforms follow in closed form: an S2 part moves rigidly about its
    pivot, a carried part translates with its top joint, S1 stays.  All
    parts share the rotation, so each of these is one vectorised operation
    over all parts.

    When joint 0 is a static reference above the pivot (the pivot is the
    motion's :attr:`~mocaplab.motion.Motion.carrier_joint`), the static
    joints stay where they are and the pivot's own rotation and translation
    channels take the move, like :meth:`mocaplab.motion.Motion.transformed`.
    """
    motion, grot, gpos = posed
    lay = _apply_layout(sets)
    static = _static_above(motion, sets, pivot)
    parents = motion.skeleton.parents
    q = quat.exp(omega)
    # the shared rotation as matrices acting on row vectors: quaternions
    # g -> q g and vectors v -> q v, one batched matrix product each for
    # all joints of all parts (much cheaper than the component formulas)
    lq = quat.left_matrix(q).transpose(0, 2, 1)  # (F, 4, 4): g @ lq = q g
    rq = quat.to_matrix(q).transpose(0, 2, 1)  # (F, 3, 3): v @ rq = q v
    rot = np.array(motion.rotations, copy=True)
    root = motion.root_positions
    # pivot of each part, before and after the move
    pivots = gpos[:, list(sets.s2_tops)]  # (F, parts, 3)
    moved = pivots
    if sets.s2_tops[0] == 0:
        if static is None:
            rot[:, 0] = quat.mul(q, rot[:, 0])
        if pivot != 0:
            pivots = pivots.copy()
            pivots[:, 0] = gpos[:, pivot]
        if root_delta is not None or pivot != 0:
            moved = pivots.copy()
            if root_delta is not None:
                moved[:, 0] += root_delta
            # joint 0 turns about the pivot and moves with it (unless static)
            if pivot == 0 and root_delta is not None:
                root = root + root_delta
            elif static is None:
                root = moved[:, 0] + quat.rotate(q, gpos[:, 0] - pivots[:, 0])
    tops = lay["tops"]
    if tops.size:
        rot[:, tops] = quat.mul(quat.inv(grot[:, parents[tops]]), grot[:, tops] @ lq)
    new_grot = np.array(grot, copy=True)
    new_gpos = np.array(gpos, copy=True)
    rigid, part = lay["rigid"], lay["rigid_part"]
    new_grot[:, rigid] = grot[:, rigid] @ lq
    new_gpos[:, rigid] = moved[:, part] + (gpos[:, rigid] - pivots[:, part]) @ rq
    carried = lay["carried"]
    if carried.size:
        cp = lay["carried_part"]
        shift = moved[:, cp] + (gpos[:, carried] - pivots[:, cp]) @ rq - gpos[:, carried]
        new_gpos[:, lay["below"]] += shift[:, lay["below_slot"]]
        # inv(q) g: the transposed matrix
        rot[:, carried] = quat.mul(quat.inv(grot[:, parents[carried]]), grot[:, carried] @ lq.transpose(0, 2, 1))
    if static is not None:
        # the static chain keeps its transforms; the pivot's channels carry the move
        new_grot[:, static] = grot[:, static]
        new_gpos[:, static] = gpos[:, static]
        parent = int(parents[pivot])
        inv_parent = quat.inv(grot[:, parent])
        rot[:, pivot] = quat.mul(inv_parent, new_grot[:, pivot])
        tr = np.array(motion.translations, copy=True)
        tr[:, pivot] = quat.rotate(inv_parent, new_gpos[:, pivot] - gpos[:, parent])
        new = motion.replace(rotations=_owned(rot), translations=_owned(tr))
    elif root is motion.root_positions:
        new = motion.replace(rotations=_owned(rot))
    else:
        new = motion.replace(rotations=_owned(rot), root_positions=_owned(root))
    return _Posed(new, new_grot, new_gpos)


def _static_above(motion: Motion, sets: LinkSets, pivot: int) -> NDArray[np.int64] | None:
    """The static joints above ``pivot`` in the part holding the root, or None when joint 0 moves with it.

    They are returned when ``pivot`` is the motion's carrier joint below a
    static reference root and every other joint of that part hangs below
    ``pivot`` (a prop or a second chain on the static root would move with
    joint 0 otherwise).
    """
    if pivot == 0 or not sets.s2_tops or sets.s2_tops[0] != 0 or motion.carrier_joint != pivot:
        return None
    chain = []
    a = int(motion.skeleton.parents[pivot])
    while a >= 0:
        chain.append(a)
        a = int(motion.skeleton.parents[a])
    below = _subtree(motion.skeleton, pivot)
    part0 = np.flatnonzero(sets.part == 0)
    if not np.all(below[part0] | np.isin(part0, chain)):
        return None
    return np.array(sorted(chain), dtype=np.int64)


def _root_pivot(sets: LinkSets, path_joint: int) -> int:
    """The joint the S2 part holding the root turns about and carries along (see :func:`_apply`).

    The travelling joint (:attr:`mocaplab.motion.Motion.path_joint`, the
    pelvis) when it is a rotated joint of that part, else joint 0; so a
    static reference joint above the pelvis gives the same touch-up as a
    skeleton whose root is the pelvis.
    """
    if sets.s2_tops and sets.s2_tops[0] == 0 and sets.part[path_joint] == 0 and sets.roles[path_joint] == 2:
        return int(path_joint)
    return 0

