"""Editing staggered poses (Coleman et al. 2008, section 5).

Every function takes a :class:`~mocaplab.staggered.StaggeredMotion` and
returns a new one (``ml.staggered.succession(sm, 0.02)``); the
representation itself has no editing methods, so this module sits above it
and nothing below imports it.  Setting refinements directly is
:func:`~mocaplab.staggered.representation.set_refinements` (with
:meth:`~mocaplab.staggered.StaggeredMotion.with_refinements`), which
every timing edit here ends with.

Geometric editing (section 5.1)
-------------------------------
A geometric edit gives some knots a change ``Delta_{k,i}``.  Following the
paper, the editing knot (at ``t_k``) and the extreme knot (at
``t_k + r_{k,i}``) of a variable get *equal* changes:

* :func:`edit_pose` with ``which="true"`` edits the true pose at ``t_k``
  (the editing knots): ``Delta`` is chosen so that the pose at ``t_k``
  becomes the requested one exactly, and the extreme knot gets the same
  change, ``v_hat = v (+) (v_hat^o (-) v^o)`` (Figure 6a);
* with ``which="non-staggered"`` it edits the extreme values directly
  (refinements collapsed, edited, restored) and the editing knots are offset
  by the same change (Figure 6b);
* :func:`exaggerate` edits values relative to a reference pose (a neighbour
  or the average): ``v_hat = v (+) w_r (v (-) v^r)``, where for rotations
  ``w_r`` scales the rotation (``exp(w_r log q)``), which is an extrapolation
  along the geodesic from ``v^r`` through ``v``.

The change is carried by a smooth *edit offset*: equal to ``Delta_k`` on the
stretch between pose ``k``'s editing knot and extreme knot, blended to the
neighbouring pose's change between them by the package's one blend ramp,
:func:`mocaplab.displacement.blend_ramp` (the C2 quintic: zero slope at the
knots keeps the tangents continuous, as section 3 asks, and zero curvature
there adds no acceleration jump; the paper names no particular ramp, so
nothing argues for a second, cubic one).  The result is then written back into
the representation: the knot values become ``v (+) Delta`` (the spline
tangents move with their knots) and the displacement maps are re-measured so
that the motion equals ``spline (+) offset (+) old displacement``; high
frequency detail is untouched and the editing knots are re-created at
``t_k``.  :func:`insert_pose` and :func:`delete_pose` refit the affected
splines and re-measure the displacements so the motion is unchanged.

Timing editing (section 5.2)
----------------------------
:func:`retime` moves a pose; :func:`succession` adds ``s d(i)^l`` to the
refinements, ``d(i)`` being the depth of variable ``i`` below a chosen joint;
:func:`randomize` adds seeded ``rand(-tau, tau)`` offsets.  Splines and
displacement maps live on normalised time, so they follow the knots; editing
knots are re-evaluated at ``t_k`` (Figure 6c).  A
:class:`~mocaplab.staggered.StaggeredTimingWarning` is issued when a refined
knot comes closer to a neighbouring pose than to its own, and a
``ValueError`` is raised when knots would cross.

Translation variables (a pelvis travelling below a static joint 0, the
translation channels of a skeleton with 6 channels per joint) are edited like
the root translation: added changes, the same edit offsets, the same timing.

Edits carry the contact constraint layer
(:mod:`~mocaplab.staggered.constraints`) along: it lives on the pose timing,
so a retimed pose carries its contacts (refinements leave them in place) and
inserting or deleting a pose re-expresses the layer on the new poses.
:mod:`~mocaplab.staggered.editor` puts an undoable editor on top of these
functions.

Longer than 800 lines because the module holds the whole of section 5: the
timing edits (about 250 lines) and the geometric ones (pose edits,
exaggeration, inserting and deleting poses) share the pose and variable
selection helpers, and a reader follows the paper's two subsections down one
file.

Joints are never named here: the succession's default joint is the pelvis
of the skeleton's joint roles (:mod:`mocaplab.roles`; every entry point that
needs it accepts ``roles=``).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping, Sequence
from typing import Any, Literal, Union

import numpy as np
from numpy.typing import ArrayLike, NDArray

from .. import kinematics, quat
from .._checks import quaternion, real
from ..displacement import blend_ramp
from ..ik import hinge_axes
from ..motion import Skeleton
from ..roles import RolesError, resolve_roles
from .fit import fit_rotation_tangents, fit_translation_tangents
from .representation import (
    StaggeredMotion,
    bezier,
    casteljau,
    locate,
    next_active,
    pose_time,
    pose_u,
    set_refinements,
    slerp_unit,
)

__all__ = [
    "ReferencePose",
    "keep_knot_order",
    "MIN_SEGMENT",
    "retime",
    "succession",
    "SUCCESSION_TAPER",
    "succession_depths",
    "randomize",
    "check_tau",
    "limb_groups",
    "LIMBS",
    "edit_pose",
    "exaggerate",
    "HINGE_FOLD_LIMIT",
    "apply_knot_deltas",
    "insert_pose",
    "delete_pose",
    "average_pose",
    "default_joint",
]

Array = NDArray[np.float64]
ReferencePose = Union[Literal["average", "previous", "next"], int, tuple[ArrayLike, ...]]  # noqa: UP007 (runtime alias, py3.10)


# ------------------------------------------------------------------ helpers
def _variables_mask(sm: StaggeredMotion, joints: Sequence[str] | None, *, rotations_only: bool = False) -> NDArray[np.bool_]:
    """Bool mask (V,) of the named variables (joint names, ``"root_position"``, ``"<joint>.position"``).

    ``joints=None``: every variable, or with ``rotations_only`` every joint rotation.
    """
    V = sm.n_variables
    if joints is None:
        mask = np.ones(V, dtype=bool)
        if rotations_only:
            mask[sm.position_columns] = False
        return mask
    if isinstance(joints, str):
        joints = [joints]
    mask = np.zeros(V, dtype=bool)
    for name in joints:
        mask[sm.variable_index(name)] = True
    return mask


def _poses(sm: StaggeredMotion, poses: Sequence[int] | None, *, interior: bool) -> NDArray[np.int64]:
    K = sm.n_poses
    if poses is None:
        return np.arange(1, K - 1) if interior else np.arange(K)
    out = np.array([sm._pose_index(int(k)) for k in np.atleast_1d(poses)], dtype=np.int64)
    return out


def _replace(sm: StaggeredMotion, **changes: Any) -> StaggeredMotion:
    return dataclasses.replace(sm, **changes)


# ------------------------------------------------------------- timing edits
MIN_SEGMENT = 1.0 / 3.0
"""Least share of its poses' gap a variable's segment keeps under a timing edit (:func:`keep_knot_order`).

The extraction keeps consecutive knots of a variable a third of their
poses' gap apart (:func:`~mocaplab.staggered.features.timing_refinements`);
the procedural timing tools stop pushed knots there too."""


def keep_knot_order(
    sm: StaggeredMotion, refinements: ArrayLike, *, gap: float | None = None, fraction: float = MIN_SEGMENT
) -> Array:
    """Refinements nudged so every variable's refined knots stay ordered, each segment keeping some length.

    Each refined knot is kept after the previous knot of its variable and
    before the next one by at least ``fraction`` of their poses' gap (or by
    their gap in ``sm``, when that is already smaller), and never less than
    ``gap`` seconds, by the smallest moves (a forward then a backward running
    max/min); the first and last knots do not move.  Used by the procedural
    timing tools so a slider can never produce crossing knots, nor squeeze a
    segment (and the motion in it) into a few frames: a strong whole-body
    succession (``s = 0.03``, ``l = 2``) on the walk 16_15 pressed the last
    segment of 22 joints into one frame (a 60-fold speed-up there).

    Parameters
    ----------
    sm : StaggeredMotion
        Gives the pose times, which variables each pose controls and the
        current knots.
    refinements : array_like, shape (K, V)
        Proposed refinements, seconds.
    gap : float, optional
        Smallest time between two knots of a variable, seconds; default ``1 / sm.fps``.
    fraction : float, default :data:`MIN_SEGMENT`
        Least share of the poses' gap between two consecutive knots of a
        variable, in [0, 1) (0: only ``gap``).

    Returns
    -------
    ndarray, shape (K, V)

    Examples
    --------
    Pushing pose 2's root knot past pose 3 pushes pose 3's knot on, a third
    of their poses' gap after it:

    >>> import mocaplab as ml
    >>> sm = ml.staggered.extract(ml.cmu("16_15").resample(30)[:60])
    >>> r = sm.refinements.copy()
    >>> r[2, 0] = 0.5
    >>> kept = ml.staggered.keep_knot_order(sm, r)
    >>> knots = sm.times + kept[:, 0]
    >>> round(float((knots[3] - knots[2]) / (sm.times[3] - sm.times[2])), 6)
    0.333333
    >>> kept = ml.staggered.keep_knot_order(sm, r, fraction=0.0)   # only one frame apart
    >>> round(float(sm.times[3] + kept[3, 0] - sm.times[2] - kept[2, 0]) * sm.fps, 6)
    1.0
    """
    r = np.array(refinements, dtype=float, copy=True)
    g = 1.0 / sm.fps if gap is None else float(gap)
    fraction = real(fraction, "fraction", low=0.0, high=1.0, high_open=True)
    T = sm.times[:, None] + r
    T0 = np.array(T, copy=True)
    now = sm.times[:, None] + sm.refinements
    for i in range(sm.n_variables):
        idx = np.flatnonzero(sm.active[:, i])
        # the least gap before each knot: a share of the poses' gap, at most the current one, at least `gap`
        need = np.maximum(g, np.minimum(fraction * np.diff(sm.times[idx]), np.diff(now[idx, i])))
        n = np.concatenate([[0.0], np.cumsum(need)])
        x = T[idx, i]
        # T_m >= T_{m-1} + need_m  <=>  z = T - n is non-decreasing
        z = x - n
        z1 = np.maximum.accumulate(z)
        z1[-1] = z[-1]
        z2 = np.minimum.accumulate(z1[::-1])[::-1]
        z2[0] = z[0]
        T[idx, i] = np.where(z2 != z, z2 + n, x)
    moved = T != T0
    return np.where(sm.active, np.where(moved, T - sm.times[:, None], r), 0.0)


def retime(sm: StaggeredMotion, k: int, time: float) -> StaggeredMotion:
    """Move pose ``k`` (not the first) to ``time`` seconds, its refinements with it.

    Moving the last pose changes the duration.  Pose times must stay
    strictly increasing.

    Parameters
    ----------
    sm : StaggeredMotion
    k : int
        Pose index, 1 to ``K - 1``.
    time : float
        New pose time ``t_k``, seconds, between the times of poses ``k - 1`` and ``k + 1``.

    Returns
    -------
    StaggeredMotion

    Raises
    ------
    ValueError
        For the first pose, or a time that leaves the pose times out of order.

    Examples
    --------
    >>> import mocaplab as ml
    >>> sm = ml.staggered.extract(ml.cmu("16_15").resample(30)[:60])
    >>> sm.times.round(3).tolist()
    [0.0, 0.533, 0.9, 1.1, 1.667, 1.967]
    >>> ml.staggered.retime(sm, 2, 1.0).times.round(3).tolist()
    [0.0, 0.533, 1.0, 1.1, 1.667, 1.967]
    """
    k = sm._pose_index(k)
    if k == 0:
        raise ValueError("Expected `k` >= 1: the first pose stays at time 0")
    times = np.array(sm.times, copy=True)
    times[k] = float(time)
    if not np.all(np.diff(times) > 0):
        lo = times[k - 1]
        hi = times[k + 1] if k + 1 < sm.n_poses else np.inf
        raise ValueError(f"Expected `time` strictly between {lo:.4f} and {hi:.4f} s for pose {k}, got {time!r}")
    out = _replace(sm, times=times)
    out._warn_timing()
    return out


def default_joint(skeleton: Skeleton, roles: Mapping[str, Any] | None = None) -> str:
    """The joint the succession depth is measured from by default: the pelvis.

    The ``pelvis`` role (:func:`mocaplab.roles.resolve_roles`, ``roles``
    overriding), which is joint 0 on most skeletons but not below a static
    reference joint; joint 0 when the skeleton has no pelvis role.

    Parameters
    ----------
    skeleton : Skeleton
    roles : mapping, optional
        Joint-role overrides (``{"pelvis": "Hips"}``).

    Returns
    -------
    str
        The joint's name.

    Examples
    --------
    >>> import mocaplab as ml
    >>> ml.staggered.default_joint(ml.cmu("16_15").skeleton)
    'Hips'
    """
    try:
        pelvis = resolve_roles(skeleton, roles).get("pelvis")
    except RolesError:
        pelvis = None
    return str(pelvis) if pelvis is not None else skeleton.names[0]


def succession_depths(
    skeleton: Skeleton,
    joint: str | Sequence[str] | None = None,
    *,
    translation_joints: Sequence[int] = (),
    roles: Mapping[str, Any] | None = None,
) -> Array:
    """Depth ``d(i)`` of every control variable below the chosen joint(s), shape (V,).

    The rotation of a joint ``c`` in the subtree of a chosen joint ``j`` has
    depth ``depth(c) - depth(j)`` (the chosen joint's own rotation: 0); with
    several chosen joints the nearest chosen ancestor counts.  A joint's
    translation (the root translation for joint 0, the translation
    variables for ``translation_joints``) has the depth of its rotation.
    Variables outside every chosen subtree get NaN (they are not retimed).

    Parameters
    ----------
    skeleton : Skeleton
    joint : str or sequence of str, optional
        The chosen joint(s); default the pelvis (:func:`default_joint`, ``roles`` overriding).
    translation_joints : sequence of int, default ()
        Joints with a translation variable (``StaggeredMotion.translation_joints``).
    roles : mapping, optional
        Joint-role overrides (:func:`mocaplab.roles.resolve_roles`).

    Returns
    -------
    ndarray, shape (V,)
        Depths in the order of :func:`~mocaplab.staggered.variable_names`, NaN outside the subtrees.

    Examples
    --------
    >>> import mocaplab as ml
    >>> sk = ml.cmu("16_15").skeleton
    >>> d = ml.staggered.succession_depths(sk, "LeftShoulder")
    >>> names = ml.staggered.variable_names(sk)
    >>> [(names[i], int(d[i])) for i in range(len(d)) if d[i] == d[i]][:4]
    [('LeftShoulder', 0), ('LeftArm', 1), ('LeftForeArm', 2), ('LeftHand', 3)]
    """
    if joint is None:
        joint = default_joint(skeleton, roles)
    names = [joint] if isinstance(joint, str) else list(joint)
    chosen = {skeleton.index(n) for n in names}
    J = skeleton.n_joints
    depth = skeleton.depth()
    rot = np.full(J, np.nan)
    for c in range(J):
        a = c
        while a >= 0 and a not in chosen:
            a = int(skeleton.parents[a])
        if a >= 0:
            rot[c] = float(depth[c] - depth[a])
    return np.concatenate([rot[:1], rot, rot[np.asarray(translation_joints, dtype=np.int64)]])


def succession(
    sm: StaggeredMotion,
    s: float,
    l: float = 1.0,
    *,
    joint: str | Sequence[str] | None = None,
    poses: Sequence[int] | None = None,
    roles: Mapping[str, Any] | None = None,
) -> StaggeredMotion:
    """Nonlinear succession: ``r_hat_{k,i} = r_{k,i} + s d(i)^l`` (section 5.2).

    Parameters
    ----------
    sm : StaggeredMotion
    s : float
        Base timing offset per level of depth, seconds (positive: the
        extremities follow; negative: they lead).
    l : float > 0
        Nonlinearity (1 is Neff and Fiume's linear succession; larger values
        loosen the extremities).
    joint : str or sequence of str, optional
        Joint(s) the depth is measured from (default the pelvis, see
        :func:`default_joint`): only variables in their subtrees move.
    poses : sequence of int, optional
        Poses to edit (default every interior pose; the first and last poses
        anchor the clip's ends).
    roles : mapping, optional
        Joint-role overrides for the default joint
        (:func:`mocaplab.roles.resolve_roles`).

    Returns
    -------
    StaggeredMotion
        ``s = 0`` returns an identical motion.  Within
        :data:`SUCCESSION_TAPER` offsets of the clip's end (its start for a
        negative ``s``) a knot moves by a third of the time left, so no
        knot piles up against the last pose.  Knots that would cross a
        neighbour of the same variable, or come nearer it than a third of
        their poses' gap, are stopped there (:func:`keep_knot_order`), so
        every segment keeps a third of its length.

    Examples
    --------
    The left hand is three levels below the left shoulder, so with ``s = 0.03``
    and ``l = 2`` its knots come ``0.03 * 3**2 = 0.27`` s later (the last
    two, within three offsets of the clip's end, by a third of the time left):

    >>> import mocaplab as ml
    >>> sm = ml.staggered.extract(ml.cmu("16_15").resample(30)[:60])
    >>> hand = ml.staggered.variable_names(sm.skeleton).index("LeftHand")
    >>> late = ml.staggered.succession(sm, 0.03, 2.0, joint="LeftShoulder")
    >>> (late.refinements - sm.refinements)[1:-1, hand].round(3).tolist()
    [0.27, 0.27, 0.256, 0.111]
    """
    if not np.isfinite(s):
        raise ValueError(f"Expected a finite `s` in seconds, got {s!r}")
    if not (np.isfinite(l) and l > 0):
        raise ValueError(f"Expected `l` > 0, got {l!r}")
    d = succession_depths(sm.skeleton, joint, translation_joints=sm.translation_joints, roles=roles)
    offset = np.where(np.isfinite(d), float(s) * np.power(np.nan_to_num(d), float(l)), 0.0)
    r = np.array(sm.refinements, copy=True)
    ks = _poses(sm, poses, interior=True)
    # toward the end the knots move to (the last pose for a delay, the first for a lead), which stays, the offset
    # tapers: within SUCCESSION_TAPER offsets of it a knot moves by that share of the time left
    knots = sm.times[:, None] + sm.refinements
    room = np.where(offset > 0.0, knots[-1] - knots, knots - knots[0])
    share = np.clip(room / np.maximum(SUCCESSION_TAPER * np.abs(offset), 1e-12), 0.0, 1.0)
    r[ks] += (offset * share)[ks]
    return set_refinements(sm, keep_knot_order(sm, r))


SUCCESSION_TAPER = 3.0
"""How many offsets before the clip's end a succession starts to taper (:func:`succession`).

The last pose anchors the clip's end, so the knots a succession delays pile
up before it: stopped a third of their gap short (:func:`keep_knot_order`),
the last segment of a variable ran three times as fast.  Within this many
offsets of the end a knot is delayed by a third of the time left instead,
so the last stretch of each variable plays at 1.5 times its speed, spread
over its segments: the 24 fps walk of bvhtoolbox (walk01) under a
succession of 0.02 s ended on its left hand's last one-frame segment at
35 rad/s^2 (input 6), now 10; motionmachine's animation ended on its
right forearm at 427 rad/s^2 (input 86), now 107.  Leads taper toward
the clip's start alike."""

LIMBS = ("trunk", "left_leg", "right_leg", "left_arm", "right_arm")
"""The groups of :func:`limb_groups`, in the order of their ids."""


def limb_groups(
    skeleton: Skeleton, *, translation_joints: Sequence[int] = (), roles: Mapping[str, Any] | None = None
) -> NDArray[np.int64]:
    """The limb of every control variable, as an index into :data:`LIMBS`, shape (V,).

    A leg is the subtree of its hip, an arm the subtree of its clavicle (of
    its shoulder when there is no clavicle), from the joint roles
    (:func:`mocaplab.roles.resolve_roles`, ``roles`` overriding); everything
    else (the root translation, the pelvis, the spine, the head) is the
    trunk.  A translation variable belongs to its joint's limb.

    Parameters
    ----------
    skeleton : Skeleton
    translation_joints : sequence of int, default ()
        Joints with a translation variable (``StaggeredMotion.translation_joints``).
    roles : mapping, optional
        Joint-role overrides.

    Returns
    -------
    ndarray of int, shape (V,)
        Indices into ``LIMBS = ("trunk", "left_leg", "right_leg", "left_arm", "right_arm")``,
        in the order of :func:`~mocaplab.staggered.variable_names`.

    Examples
    --------
    >>> import mocaplab as ml
    >>> from mocaplab.staggered.edit import LIMBS
    >>> sk = ml.cmu("16_15").skeleton
    >>> limb = ml.staggered.limb_groups(sk)
    >>> names = ml.staggered.variable_names(sk)
    >>> LIMBS[limb[names.index("LeftLeg")]], LIMBS[limb[names.index("RightHand")]], LIMBS[limb[0]]
    ('left_leg', 'right_arm', 'trunk')
    """
    r = resolve_roles(skeleton, roles)
    J = skeleton.n_joints
    top = np.zeros(J, dtype=np.int64)
    for g, (side, part) in enumerate((("left", "leg"), ("right", "leg"), ("left", "arm"), ("right", "arm")), start=1):
        keys = (f"{side}_hip",) if part == "leg" else (f"{side}_clavicle", f"{side}_shoulder")
        name = next((r[k] for k in keys if k in r), None)
        if name is not None:
            top[skeleton.index(name)] = g
    group = np.zeros(J, dtype=np.int64)
    for j in range(J):  # parents come first: a joint inherits its parent's limb unless it starts one
        group[j] = top[j] if top[j] else (group[int(skeleton.parents[j])] if j > 0 else 0)
    return np.concatenate([[0], group, group[np.asarray(translation_joints, dtype=np.int64)]]).astype(np.int64)


def check_tau(sm: StaggeredMotion, tau: Any) -> float:
    """The random timing bound ``tau``: seconds, from 0 to the clip's duration (TypeError/ValueError naming it).

    An offset longer than the clip moves no knot further (knots keep their
    order inside it), and a bound near the float range would overflow the
    random draw.
    """
    return real(tau, "tau", low=0.0, high=sm.duration, unit="seconds (at most the clip's duration)")


def randomize(
    sm: StaggeredMotion,
    tau: float,
    *,
    joints: Sequence[str] | None = None,
    poses: Sequence[int] | None = None,
    seed: int | None = 0,
    by: Literal["variable", "limb"] = "variable",
    roles: Mapping[str, Any] | None = None,
) -> StaggeredMotion:
    """Random timing: ``r_hat_{k,i} += rand(-tau, tau)`` on chosen joints (section 5.2).

    Parameters
    ----------
    sm : StaggeredMotion
    tau : float
        Bound of the offsets, seconds, from 0 to the clip's duration
        (:func:`check_tau`).
    joints : sequence of str, optional
        Variables to affect (joint names, ``"root_position"``,
        ``"<joint>.position"``); default every joint rotation.
    poses : sequence of int, optional
        Default every interior pose.
    seed : int, optional
        Seed of :func:`numpy.random.default_rng` (same seed, same offsets).
    by : {"variable", "limb"}
        One offset per pose and variable (default), or per pose and limb
        (:func:`limb_groups`: the legs, the arms, the trunk), shared by the
        limb's chosen variables.  The paper introduces random offsets "for
        modeling asymmetric timing among different limbs": per limb, an arm
        keeps its own coordination and is retimed against the other limbs
        as a whole.
    roles : mapping, optional
        Joint-role overrides for the limbs (``by="limb"``).

    Returns
    -------
    StaggeredMotion
        Knots that would cross a neighbour, or come nearer it than a third of
        their poses' gap, are stopped there (:func:`keep_knot_order`).

    Examples
    --------
    >>> import numpy as np
    >>> import mocaplab as ml
    >>> sm = ml.staggered.extract(ml.cmu("16_15").resample(30)[:60])
    >>> a = ml.staggered.randomize(sm, 0.05, seed=1)
    >>> bool(np.abs(a.refinements - sm.refinements).max() <= 0.05)
    True
    >>> bool(np.array_equal(a.refinements, ml.staggered.randomize(sm, 0.05, seed=1).refinements))
    True
    """
    tau = check_tau(sm, tau)
    if by not in ("variable", "limb"):
        raise ValueError(f"Expected `by` in ('variable', 'limb'), got {by!r}")
    mask = _variables_mask(sm, joints, rotations_only=True)
    ks = _poses(sm, poses, interior=True)
    rng = np.random.default_rng(seed)
    if by == "variable":
        noise = rng.uniform(-tau, tau, size=(ks.size, sm.n_variables))
    else:
        group = limb_groups(sm.skeleton, translation_joints=sm.translation_joints, roles=roles)
        noise = rng.uniform(-tau, tau, size=(ks.size, len(LIMBS)))[:, group]
    r = np.array(sm.refinements, copy=True)
    r[ks] += np.where(mask, noise, 0.0)
    return set_refinements(sm, keep_knot_order(sm, r))


# ---------------------------------------------------------- geometric edits
def _segments_of_u(u: Array, active: NDArray[np.bool_]) -> tuple[NDArray[np.int64], NDArray[np.int64], Array]:
    """Segment bounds and normalised time of displacement samples ``u`` (N, V)."""
    N, V = u.shape
    k0 = np.empty((N, V), dtype=np.int64)
    k1 = np.empty((N, V), dtype=np.int64)
    for i in range(V):
        idx = np.flatnonzero(active[:, i])
        s = np.clip(np.searchsorted(idx, u[:, i], side="right") - 1, 0, idx.size - 2)
        k0[:, i], k1[:, i] = idx[s], idx[s + 1]
    tn = np.clip((u - k0) / (k1 - k0), 0.0, 1.0)
    return k0, k1, tn


def _edit_offset_weight(sm: StaggeredMotion, k0: NDArray[Any], k1: NDArray[Any], tn: Array) -> Array:
    """Blend weight h in [0, 1] of the edit offset (0: Delta_k0, 1: Delta_k1).

    Flat (h = 0) between the extreme knot of ``k0`` and its editing knot when
    that lies inside the segment (``r < 0``), flat (h = 1) between the editing
    knot of ``k1`` and its extreme knot (``r > 0``), :func:`~mocaplab.displacement.blend_ramp` in between.
    """
    V = sm.n_variables
    col = np.arange(V)
    r0 = sm.refinements[k0, col]
    r1 = sm.refinements[k1, col]
    T0 = sm.times[k0] + r0
    T1 = sm.times[k1] + r1
    span = T1 - T0
    a = np.where(r0 < 0, -r0 / span, 0.0)
    b = np.where(r1 > 0, (sm.times[k1] - T0) / span, 1.0)
    return blend_ramp((tn - a) / np.maximum(b - a, 1e-12))


def apply_knot_deltas(
    sm: StaggeredMotion,
    root_delta: ArrayLike,
    rotation_delta: ArrayLike,
    translation_delta: ArrayLike | None = None,
) -> StaggeredMotion:
    """Give knots the changes ``Delta`` and write them back (see the module notes).

    Parameters
    ----------
    sm : StaggeredMotion
    root_delta : array_like, shape (K, 3)
        Translation changes of the root-position knots (added).
    rotation_delta : array_like, shape (K, J, 4)
        Rotation changes, composed as ``v (+) Delta = mul(v, Delta)``.
    translation_delta : array_like, shape (K, T, 3), optional
        Changes of the translation variables' knots (added); default none.

    Returns
    -------
    StaggeredMotion
        Values ``v (+) Delta``; the motion equals the old
        ``spline (+) offset (+) displacement`` on every displacement sample,
        where the offset is ``Delta_k`` between pose ``k``'s editing knot and
        extreme knot, smoothly blended between poses.

    Examples
    --------
    Raise pose 3's root knot by 10 cm and leave every rotation alone:

    >>> import numpy as np
    >>> import mocaplab as ml
    >>> sm = ml.staggered.extract(ml.cmu("16_15").resample(30)[:60])
    >>> K, J = sm.rotation_values.shape[:2]
    >>> lift = np.zeros((K, 3))
    >>> lift[3, 1] = 0.1
    >>> up = ml.staggered.apply_knot_deltas(sm, lift, np.tile([0.0, 0.0, 0.0, 1.0], (K, J, 1)))
    >>> (up.root_values[3] - sm.root_values[3]).round(6).tolist()
    [0.0, 0.1, 0.0]
    """
    K, J, T = sm.n_poses, sm.n_joints, sm.n_translations
    V = sm.n_variables
    pc = sm.position_columns
    dr = np.asarray(root_delta, dtype=float).reshape(K, 3)
    dt = np.zeros((K, T, 3)) if translation_delta is None else np.asarray(translation_delta, dtype=float)
    if dt.shape != (K, T, 3):
        raise ValueError(f"Expected `translation_delta` of shape ({K}, {T}, 3), got {dt.shape}")
    dp = np.concatenate([dr[:, None], dt], axis=1)  # (K, P, 3)
    dq = quat.normalize(np.asarray(rotation_delta, dtype=float).reshape(K, J, 4))
    dq = np.where(dq[..., 3:4] < 0, -dq, dq)
    changed = np.zeros((K, V), dtype=bool)
    changed[:, pc] = np.any(dp != 0.0, axis=-1)
    changed[:, 1 : J + 1] = quat.angle(dq) > 0.0
    changed &= sm.active
    if not changed.any():
        return sm
    new_pos_values = sm.position_values + np.where(changed[:, pc, None], dp, 0.0)
    new_rot_values = np.where(changed[:, 1 : J + 1, None], quat.mul(sm.rotation_values, dq), sm.rotation_values)
    new = _replace(
        sm,
        root_values=new_pos_values[:, 0],
        translation_values=new_pos_values[:, 1:],
        rotation_values=new_rot_values,
    )
    # re-measure the displacement samples of the affected segments only
    k0, k1, tn = _segments_of_u(sm.sample_u, sm.active)
    col = np.arange(V)
    hit = changed[k0, col] | changed[k1, col]
    d_pos = sm.position_displacement  # a fresh array
    d_rot = np.array(sm.rotation_displacement, copy=True)
    h = _edit_offset_weight(sm, k0, k1, tn)
    rows, ps = np.nonzero(hit[:, pc])
    if rows.size:
        c = pc[ps]
        kk0, kk1, tt = k0[rows, c], k1[rows, c], tn[rows, c]
        old = _position_spline_at(sm, kk0, ps, tt)
        nw = _position_spline_at(new, kk0, ps, tt)
        hh = h[rows, c][:, None]
        e = (1.0 - hh) * dp[kk0, ps] + hh * dp[kk1, ps]
        d_pos[rows, ps] = old + e + d_pos[rows, ps] - nw
    rows, js = np.nonzero(hit[:, 1 : J + 1])
    if rows.size:
        # evaluate only the affected (sample, joint) pairs
        kk0 = k0[rows, 1 + js]
        kk1 = k1[rows, 1 + js]
        tt = tn[rows, 1 + js]
        old = _rotation_spline_at(sm, kk0, kk1, js, tt)
        nw = _rotation_spline_at(new, kk0, kk1, js, tt)
        e = slerp_unit(dq[kk0, js], dq[kk1, js], h[rows, 1 + js])
        v = quat.mul(quat.mul(old, e), quat.exp(sm.rotation_displacement[rows, js]))
        d_rot[rows, js] = quat.log(quat.mul(quat.inv(nw), v))
    out = _replace(
        new,
        root_displacement=d_pos[:, 0],
        translation_displacement=d_pos[:, 1:],
        rotation_displacement=d_rot,
    )
    out._inherit_raw(sm, changed.any(axis=0))
    return out


def _position_spline_at(sm: StaggeredMotion, k0: NDArray[Any], p: NDArray[Any], tn: Array) -> Array:
    """Spline of position variable(s) ``p`` (0: the root) on segments starting at ``k0`` at ``tn`` (all (n,))."""
    C = sm.control_points_all()[0][k0, p]  # (n, 4, 3)
    return bezier(C[:, 0], C[:, 1], C[:, 2], C[:, 3], tn)


def _rotation_spline_at(sm: StaggeredMotion, k0: NDArray[Any], k1: NDArray[Any], j: NDArray[Any], tn: Array) -> Array:
    """Rotation spline of joint(s) ``j`` on segments starting at ``k0`` at ``tn`` (all shape (n,))."""
    _, ctrl, theta = sm.control_points_all()
    return casteljau(ctrl[k0, j], theta[k0, j], tn)


def _true_layers(sm: StaggeredMotion, k: int) -> tuple[Array, Array, Array, Array]:
    """Spline and displacement of every variable at ``t_k``: s_pos (P, 3), d_pos (P, 3), s_rot, D_rot (J, 4).

    ``D_rot`` is everything composed after the spline: the displacement
    then the sharp and noise layers, ``exp(d) exp(h) exp(n)``.
    """
    t = np.array([sm.times[k]])
    k0, k1, tn = sm.locate(t)
    s_pos, s_rot = sm._spline_layers(k0, tn)
    u = k0 + tn * (k1 - k0)
    d_pos, d_rot = sm._displacement_layers(u)
    h = sm.sharp_values(u[:, 1 : sm.n_joints + 1])
    D = quat.mul(quat.mul(quat.exp(d_rot[0]), quat.exp(h[0])), quat.exp(sm.noise_values(t)[0]))
    return s_pos[0], d_pos[0], s_rot[0], D


def _rotation_targets(sm: StaggeredMotion, rotations: Any) -> tuple[Array, NDArray[np.bool_]]:
    """(J, 4) targets and a (J,) mask from an array or a ``{joint: quaternion}`` dict."""
    J = sm.n_joints
    out = np.tile([0.0, 0.0, 0.0, 1.0], (J, 1))
    mask = np.zeros(J, dtype=bool)
    if rotations is None:
        return out, mask
    if isinstance(rotations, dict):
        for name, q in rotations.items():
            j = sm.skeleton.index(name)
            out[j] = quaternion(q, f"rotations[{name!r}]")
            mask[j] = True
        return out, mask
    arr = np.asarray(rotations, dtype=float)
    if arr.shape != (J, 4):
        raise ValueError(f"Expected `rotations` of shape ({J}, 4) or a dict joint -> quaternion, got {arr.shape}")
    for j in range(J):
        out[j] = quaternion(arr[j], f"rotations[{j}]", of=f"(joint {sm.skeleton.names[j]!r})")
    return out, np.ones(J, dtype=bool)


def _point(value: Any, name: str) -> Array:
    """A finite (3,) position in metres, or ValueError naming ``name``."""
    arr = np.asarray(value, dtype=float)
    if arr.shape != (3,) or not np.all(np.isfinite(arr)):
        raise ValueError(f"Expected `{name}` to be a finite (x, y, z) position in metres, got {value!r}")
    return arr


def _position_targets(
    sm: StaggeredMotion, root_position: ArrayLike | None, translations: Mapping[str, ArrayLike] | None
) -> tuple[Array, NDArray[np.bool_]]:
    """(P, 3) position targets and a (P,) mask from a root position and a ``{joint: (3,)}`` dict."""
    P = 1 + sm.n_translations
    out = np.zeros((P, 3))
    mask = np.zeros(P, dtype=bool)
    if root_position is not None:
        out[0] = _point(root_position, "root_position")
        mask[0] = True
    if translations is not None:
        if not isinstance(translations, Mapping):
            raise TypeError(
                f"Expected `translations` as a dict joint name -> (3,) translation, got {type(translations).__name__}"
            )
        for name, value in translations.items():
            j = sm.skeleton.index(name)
            if j not in sm.translation_joints:
                have = [sm.skeleton.names[i] for i in sm.translation_joints]
                raise ValueError(
                    f"Expected `translations` keys among the joints with a translation variable {have}, got {name!r}"
                )
            p = 1 + sm.translation_joints.index(j)
            out[p] = _point(value, f"translations[{name!r}]")
            mask[p] = True
    return out, mask


def edit_pose(
    sm: StaggeredMotion,
    k: int,
    *,
    root_position: ArrayLike | None = None,
    rotations: ArrayLike | dict[str, ArrayLike] | None = None,
    translations: Mapping[str, ArrayLike] | None = None,
    which: Literal["true", "non-staggered"] = "non-staggered",
) -> StaggeredMotion:
    """Give pose ``k`` new values (section 5.1).

    Parameters
    ----------
    sm : StaggeredMotion
    k : int
        Pose index.
    root_position : array_like, shape (3,), optional
        New root translation (metres).
    rotations : array_like, shape (J, 4), or dict of joint name -> (4,), optional
        New local rotations; with a dict only the named joints change.  Each
        a finite quaternion ``(x, y, z, w)`` of non-zero length (normalised
        here); NaN or a zero quaternion is a ValueError naming the joint.
    translations : dict of joint name -> (3,), optional
        New local translations of joints with a translation variable
        (metres, parent frame).
    which : {"non-staggered", "true"}
        ``"non-staggered"``: the values are the new extreme values
        ``v_hat_{k,i}``; editing knots are offset by the same change.
        ``"true"``: the values are the new pose at ``t_k`` (editing knots);
        afterwards ``true_pose(k)`` returns them (to rounding, a few ulps) and
        the extreme knots received the same change.

    Returns
    -------
    StaggeredMotion

    Examples
    --------
    >>> import mocaplab as ml
    >>> sm = ml.staggered.extract(ml.cmu("16_15").resample(30)[:60])
    >>> up = ml.staggered.edit_pose(sm, 2, root_position=sm.root_values[2] + [0, 0.1, 0])
    >>> (up.root_values[2] - sm.root_values[2]).round(6).tolist()
    [0.0, 0.1, 0.0]
    >>> true = ml.staggered.edit_pose(sm, 2, root_position=[0.0, 1.0, 0.0], which="true")
    >>> true.true_pose(2)[0].round(12).tolist()
    [0.0, 1.0, 0.0]
    """
    if which not in ("true", "non-staggered"):
        raise ValueError(f"Expected `which` in ('true', 'non-staggered'), got {which!r}")
    k = sm._pose_index(k)
    K, J, P = sm.n_poses, sm.n_joints, 1 + sm.n_translations
    pc = sm.position_columns
    dp = np.zeros((K, P, 3))
    dq = np.tile([0.0, 0.0, 0.0, 1.0], (K, J, 1))
    tq, tmask = _rotation_targets(sm, rotations)
    tmask &= sm.active[k, 1 : J + 1]
    tp, pmask = _position_targets(sm, root_position, translations)
    pmask &= sm.active[k, pc]
    if which == "non-staggered":
        dp[k] = np.where(pmask[:, None], tp - sm.position_values[k], 0.0)
        dq[k] = np.where(tmask[:, None], quat.mul(quat.inv(sm.rotation_values[k]), tq), dq[k])
    else:
        s_pos, d_pos, s_rot, D_rot = _true_layers(sm, k)
        dp[k] = np.where(pmask[:, None], tp - (s_pos + d_pos), 0.0)
        # s (+) Delta (+) D = target  ->  Delta = inv(s) target inv(D)
        delta = quat.mul(quat.mul(quat.inv(s_rot), tq), quat.inv(D_rot))
        dq[k] = np.where(tmask[:, None], delta, dq[k])
    return apply_knot_deltas(sm, dp[:, 0], dq, dp[:, 1:])


def average_pose(sm: StaggeredMotion, *, which: Literal["true", "non-staggered"] = "non-staggered") -> tuple[Array, Array]:
    """Average pose over all poses: mean root (3,), rotation means (J, 4).

    Rotations are averaged as the dominant eigenvector of ``sum q q^T``
    (sign independent).  (Translation variables average like the root.)

    Parameters
    ----------
    sm : StaggeredMotion
    which : {"non-staggered", "true"}
        Average the extreme values (default) or the true poses at ``t_k``.

    Returns
    -------
    root : ndarray, shape (3,)
        Mean root translation, metres.
    rotations : ndarray, shape (J, 4)
        Unit mean rotation of each joint.

    Examples
    --------
    >>> import numpy as np
    >>> import mocaplab as ml
    >>> sm = ml.staggered.extract(ml.cmu("16_15").resample(30)[:60])
    >>> root, rotations = ml.staggered.average_pose(sm)
    >>> root.shape, rotations.shape
    ((3,), (31, 4))
    >>> bool(np.allclose(np.linalg.norm(rotations, axis=-1), 1.0))
    True
    """
    pos, rot = _average_pose(sm, which)
    return pos[0], rot


def _average_pose(sm: StaggeredMotion, which: str) -> tuple[Array, Array]:
    """Average pose: positions (P, 3), rotations (J, 4)."""
    pos, rot = _pose_values(sm, which)
    M = np.einsum("kji,kjl->jil", rot, rot)
    _, vecs = np.linalg.eigh(M)
    mean = vecs[..., -1]
    mean = np.where(np.sum(mean * rot[0], axis=-1, keepdims=True) < 0, -mean, mean)
    return pos.mean(axis=0), quat.normalize(mean)


def _pose_values(sm: StaggeredMotion, which: str) -> tuple[Array, Array]:
    """Values of every pose: positions (K, P, 3), rotations (K, J, 4)."""
    if which == "non-staggered":
        return sm.position_values, np.asarray(sm.rotation_values)
    if which == "true":
        return sm._compose(sm.times)
    raise ValueError(f"Expected `which` in ('true', 'non-staggered'), got {which!r}")


def exaggerate(
    sm: StaggeredMotion,
    w_r: float,
    *,
    reference: ReferencePose = "average",
    poses: Sequence[int] | None = None,
    joints: Sequence[str] | None = None,
    which: Literal["true", "non-staggered"] = "non-staggered",
) -> StaggeredMotion:
    """Relative pose editing ``v_hat = v (+) w_r (v (-) v^r)`` (section 5.1).

    Parameters
    ----------
    sm : StaggeredMotion
    w_r : float
        Degree of offset (0: no change; positive exaggerates away from the
        reference, negative moves toward it, -1 reaches it).
    reference : "average", "previous", "next", int, or (root (3,), rotations (J, 4)[, translations (T, 3)])
        The relative pose: the average pose (global exaggeration), the
        previous or next pose (local; the first/last pose uses its only
        neighbour), a pose index, or explicit values (the translation
        variables' reference is needed only if they are edited).
    poses : sequence of int, optional
        Poses to edit (default all).
    joints : sequence of str, optional
        Variables to edit (joint names, ``"root_position"``,
        ``"<joint>.position"``); default every joint rotation (not the
        translations).
    which : {"non-staggered", "true"}
        Apply to the extreme values or to the true poses at ``t_k`` (see
        :func:`edit_pose`).

    Returns
    -------
    StaggeredMotion

    Examples
    --------
    ``w_r = -1`` moves pose 3 all the way to its reference, pose 0:

    >>> import numpy as np
    >>> import mocaplab as ml
    >>> sm = ml.staggered.extract(ml.cmu("16_15").resample(30)[:60])
    >>> same = ml.staggered.exaggerate(sm, -1.0, reference=0, poses=[3])
    >>> bool(np.allclose(same.rotation_values[3], sm.rotation_values[0]))
    True
    """
    if not np.isfinite(w_r):
        raise ValueError(f"Expected a finite `w_r`, got {w_r!r}")
    K, J, P = sm.n_poses, sm.n_joints, 1 + sm.n_translations
    pc = sm.position_columns
    pos, rot = _pose_values(sm, which)
    ks = _poses(sm, poses, interior=False)
    mask = _variables_mask(sm, joints, rotations_only=True)
    if isinstance(reference, str):
        if reference == "average":
            r_pos, r_rot = _average_pose(sm, which)
            ref_pos = np.broadcast_to(r_pos, (K, P, 3))
            ref_rot = np.broadcast_to(r_rot, (K, J, 4))
        elif reference in ("previous", "next"):
            idx = np.arange(K) + (-1 if reference == "previous" else 1)
            idx = np.where(idx < 0, 1, np.where(idx >= K, K - 2, idx))
            ref_pos, ref_rot = pos[idx], rot[idx]
        else:
            raise ValueError(f"Expected `reference` 'average', 'previous', 'next', an int or values, got {reference!r}")
    elif isinstance(reference, (int, np.integer)):
        r = sm._pose_index(int(reference))
        ref_pos = np.broadcast_to(pos[r], (K, P, 3))
        ref_rot = np.broadcast_to(rot[r], (K, J, 4))
    else:
        given = tuple(reference)
        if len(given) not in (2, 3):
            raise ValueError(
                "Expected `reference` values as (root (3,), rotations (J, 4)) or "
                f"(root, rotations, translations (T, 3)), got {len(given)} items"
            )
        given_tr = np.asarray(given[2], dtype=float) if len(given) == 3 else pos.mean(axis=0)[1:]
        if len(given) == 2 and mask[pc[1:]].any():
            raise ValueError(
                "Expected `reference` with translations (root, rotations, translations (T, 3)) "
                "to exaggerate translation variables, got (root, rotations)"
            )
        r_pos = np.concatenate([np.asarray(given[0], dtype=float).reshape(1, 3), given_tr.reshape(-1, 3)])
        if r_pos.shape != (P, 3):
            raise ValueError(f"Expected reference translations of shape ({P - 1}, 3), got {given_tr.shape}")
        ref_pos = np.broadcast_to(r_pos, (K, P, 3))
        ref_rot = np.broadcast_to(quat.normalize(np.asarray(given[1], dtype=float)), (K, J, 4))
    new_pos = pos + w_r * (pos - ref_pos)
    rel = quat.mul(quat.inv(ref_rot), rot)
    new_rot = _keep_hinges(sm, pos, rot, quat.mul(rot, quat.exp(w_r * quat.log(rel))))
    sel = np.zeros((K, sm.n_variables), dtype=bool)
    sel[ks] = mask
    sel &= sm.active
    if which == "non-staggered":
        dp = np.where(sel[:, pc, None], new_pos - pos, 0.0)
        dq = np.where(sel[:, 1 : J + 1, None], quat.mul(quat.inv(rot), new_rot), quat.identity((K, J)))
        return apply_knot_deltas(sm, dp[:, 0], dq, dp[:, 1:])
    # true poses: one knot-change per pose, all computed on the unedited motion
    K_p = np.zeros((K, P, 3))
    K_q = np.tile([0.0, 0.0, 0.0, 1.0], (K, J, 1))
    for k in ks:
        s_pos, d_pos, s_rot, D_rot = _true_layers(sm, int(k))
        act = sel[k]
        K_p[k] = np.where(act[pc, None], new_pos[k] - (s_pos + d_pos), 0.0)
        delta = quat.mul(quat.mul(quat.inv(s_rot), new_rot[k]), quat.inv(D_rot))
        K_q[k] = np.where(act[1 : J + 1, None], delta, K_q[k])
    return apply_knot_deltas(sm, K_p[:, 0], K_q, K_p[:, 1:])


#: The most a knee or elbow folds, degrees of bend (0 straight): an exaggeration that would fold a hinge
#: further (past about 150 degrees the forearm or the shin passes through its upper bone, and past 180 the
#: limb bends the other way) or straighten it past its straightest pose is shortened (:func:`_keep_hinges`).
HINGE_FOLD_LIMIT = 150.0


def _hinge_limbs(skeleton: Skeleton) -> list[tuple[int, int, int]]:
    """``(upper, middle, end)`` joints of the knees and elbows the skeleton's roles give."""
    try:
        roles = resolve_roles(skeleton)
    except RolesError:
        return []
    out = []
    for side in ("left", "right"):
        for limb in ("leg", "arm"):
            try:
                u, m, e = (skeleton.index(n) for n in roles.limb(side, limb))
            except RolesError:
                continue
            out.append((u, m, e))
    return out


def _pose_fk(sm: StaggeredMotion, pos: Array, rot: Array) -> tuple[Array, Array]:
    """Forward kinematics of poses (N, P, 3) and (N, J, 4), the root at the origin."""
    translations = sm._translations(pos[:, 1:])
    return kinematics.fk(
        rot, np.zeros((rot.shape[0], 3)), sm.skeleton.offsets, sm.skeleton.parents, translations=translations
    )


def _signed_bends(fk: tuple[Array, Array], limbs: Sequence[tuple[int, int, int]], axes: Array) -> Array:
    """Bend of each limb's hinge in degrees (0 straight), negative when bent against ``axes``, shape (N, L)."""
    grot, gpos = fk
    out = np.zeros((gpos.shape[0], len(limbs)))
    for i, (u, m, e) in enumerate(limbs):
        a, b = gpos[:, u] - gpos[:, m], gpos[:, e] - gpos[:, m]
        n = np.cross(a, b)
        bend = 180.0 - np.degrees(np.arctan2(np.linalg.norm(n, axis=-1), np.einsum("ni,ni->n", a, b)))
        side = quat.rotate(quat.inv(grot[:, m]), n) @ axes[i]
        out[:, i] = np.where(side < 0.0, -bend, bend)
    return out


def _keep_hinges(sm: StaggeredMotion, pos: Array, rot: Array, new_rot: Array, *, steps: int = 20) -> Array:
    """``new_rot`` (K, J, 4) with each knee and elbow kept within its poses' range of bends.

    An extrapolated rotation (:func:`exaggerate`) can fold a hinge past
    :data:`HINGE_FOLD_LIMIT` or straighten it past its straightest pose in
    ``rot``, where it bends the other way.  On such a pose the change of the
    joints between the limb's upper and end joint (the middle joint and any
    twist joints) is shortened along its own geodesic, by bisection, to the
    largest fraction that keeps the bend within
    ``[min(0, straightest), max(HINGE_FOLD_LIMIT, most folded)]``, the bend
    signed against the hinge axis of the unedited poses
    (:func:`mocaplab.ik.hinge_axes`).  Other joints are left as asked.
    """
    limbs = _hinge_limbs(sm.skeleton)
    if not limbs or rot.shape[0] < 2:
        return new_rot
    fk = _pose_fk(sm, pos, rot)
    axes = hinge_axes(*fk, limbs)
    before = _signed_bends(fk, limbs, axes)
    asked = _signed_bends(_pose_fk(sm, pos, new_rot), limbs, axes)  # a limb's joints move no other limb's bend
    out = new_rot.copy()
    parents = sm.skeleton.parents
    for i, (u, _, e) in enumerate(limbs):
        lo, hi = min(0.0, before[:, i].min()), max(HINGE_FOLD_LIMIT, before[:, i].max())
        bad = np.flatnonzero(~_within(asked[:, i], lo, hi))
        if not np.any(axes[i]) or not bad.size:
            continue  # straight on every pose (no hinge to keep), or every pose within its range
        path = []
        j = int(parents[e])
        while j not in (u, -1):
            path.append(j)
            j = int(parents[j])
        if j != u:
            continue
        chain = np.array(path, dtype=np.int64)
        step = quat.log(quat.mul(quat.inv(rot[np.ix_(bad, chain)]), out[np.ix_(bad, chain)]))
        low, high = np.zeros(bad.size), np.ones(bad.size)  # the fraction kept: low is within the range
        trial = out[bad].copy()
        for _ in range(steps):
            mid = 0.5 * (low + high)
            trial[:, chain] = quat.mul(rot[np.ix_(bad, chain)], quat.exp(mid[:, None, None] * step))
            bend = _signed_bends(_pose_fk(sm, pos[bad], trial), limbs[i : i + 1], axes[i : i + 1])[:, 0]
            ok = _within(bend, lo, hi)
            low, high = np.where(ok, mid, low), np.where(ok, high, mid)
        out[np.ix_(bad, chain)] = quat.mul(rot[np.ix_(bad, chain)], quat.exp(low[:, None, None] * step))
    return out


def _within(bend: Array, lo: float, hi: float) -> NDArray[np.bool_]:
    return (bend >= lo - 1e-6) & (bend <= hi + 1e-6)


# --------------------------------------------------- creating/deleting poses
def _restructure(
    sm: StaggeredMotion,
    *,
    times: Array,
    refinements: Array,
    active: NDArray[np.bool_],
    position_values: Array,
    rotation_values: Array,
    old_to_new: NDArray[np.int64],
    refit: NDArray[np.bool_],
    priorities: Array,
) -> StaggeredMotion:
    """Re-parameterise the displacement samples for a new pose structure,
    refit the splines of segments starting at ``refit`` (K_new, V) and
    re-measure displacements so the motion is unchanged on every sample.

    ``position_values`` (K_new, P, 3) and ``rotation_values`` (K_new, J, 4)
    are the new knot values."""
    K, J = times.size, sm.n_joints
    V = sm.n_variables
    P = 1 + sm.n_translations
    pc = sm.position_columns
    # current sample times and values
    k0, k1, tn = _segments_of_u(sm.sample_u, sm.active)
    col = np.arange(V)
    T_old = sm.times[:, None] + sm.refinements
    tau = T_old[k0, col] + tn * (T_old[k1, col] - T_old[k0, col])  # (N, V)
    s_pos, s_rot = sm._spline_layers(k0, tn)
    v_pos = s_pos + sm.position_displacement
    v_rot = quat.mul(s_rot, quat.exp(sm.rotation_displacement))
    # new segments
    n0, n1, ntn = locate(times, refinements, active, tau)
    same = (old_to_new[k0] == n0) & (old_to_new[k1] == n1) & ~refit[n0, col]
    ntn = np.where(same, tn, ntn)
    nxt = next_active(active)
    nxt_safe = np.where(nxt < 0, np.arange(K)[:, None], nxt)
    # carry old tangents, refit the marked segments
    pos_t = np.zeros((K, P, 2, 3))
    rot_t = np.tile([0.0, 0.0, 0.0, 1.0], (K, J, 2, 1))
    keep = old_to_new >= 0
    pos_t[old_to_new[keep]] = np.concatenate([sm.root_tangents[:, None], sm.translation_tangents], axis=1)[keep]
    rot_t[old_to_new[keep]] = sm.rotation_tangents[keep]
    for p in np.flatnonzero(refit[:, pc].any(axis=0)):
        c = pc[p]
        a, b = fit_translation_tangents(
            n0[:, c], ntn[:, c], v_pos[:, p], position_values[:, p], position_values[nxt_safe[:, c], p]
        )
        rows = refit[:, c]
        pos_t[rows, p] = np.stack([a, b], axis=1)[rows]
    for j in np.flatnonzero(refit[:, 1 : J + 1].any(axis=0)):
        q1 = rotation_values[:, j]
        q4 = rotation_values[nxt_safe[:, 1 + j], j]
        qs = v_rot[:, j]
        qs = np.where(np.sum(qs * q1[n0[:, 1 + j]], axis=-1, keepdims=True) < 0, -qs, qs)
        al, be, _ = fit_rotation_tangents(n0[:, 1 + j], ntn[:, 1 + j], qs, q1, q4)
        rows = refit[:, 1 + j]
        rot_t[rows, j, 0] = al[rows]
        rot_t[rows, j, 1] = be[rows]
    new = _replace(
        sm,
        times=times,
        refinements=refinements,
        active=active,
        root_values=position_values[:, 0],
        translation_values=position_values[:, 1:],
        rotation_values=rotation_values,
        root_tangents=pos_t[:, 0],
        translation_tangents=pos_t[:, 1:],
        rotation_tangents=rot_t,
        sample_u=n0 + ntn * (n1 - n0),
        priorities=priorities,
        # the noise and constraint layers stay where they are in time: new pose-index positions
        noise_u=None if sm.noise_u is None else pose_u(times, pose_time(sm.times, sm.noise_u)),
        constraints=None
        if sm.constraints is None
        else dataclasses.replace(sm.constraints, pose_u=pose_u(times, pose_time(sm.times, sm.constraints.pose_u))),
    )
    ns_pos, ns_rot = new._spline_layers(n0, ntn)
    d_pos = v_pos - ns_pos
    return _replace(
        new,
        root_displacement=d_pos[:, 0],
        translation_displacement=d_pos[:, 1:],
        rotation_displacement=quat.log(quat.mul(quat.inv(ns_rot), v_rot)),
    )


def insert_pose(sm: StaggeredMotion, time: float, *, joints: Sequence[str] | None = None) -> StaggeredMotion:
    """Create a pose at ``time`` with zero refinements (section 5.1).

    Parameters
    ----------
    sm : StaggeredMotion
    time : float
        Seconds, strictly between two poses and between the refined knots
        of every variable it controls.
    joints : sequence of str, optional
        A partial pose controlling only these variables (joint names,
        ``"root_position"``, ``"<joint>.position"``); default every variable.

    Returns
    -------
    StaggeredMotion
        The new knots take the current values at ``time``; the splines of the
        split segments are refitted and the displacement maps re-measured,
        so the motion is unchanged.

    Examples
    --------
    >>> import numpy as np
    >>> import mocaplab as ml
    >>> sm = ml.staggered.extract(ml.cmu("16_15").resample(30)[:60])
    >>> more = ml.staggered.insert_pose(sm, 0.7)
    >>> more.n_poses - sm.n_poses
    1
    >>> bool(np.allclose(more.evaluate().global_positions(), sm.evaluate().global_positions()))
    True
    """
    t = float(time)
    K, V = sm.n_poses, sm.n_variables
    if not sm.times[0] < t < sm.times[-1] or np.any(np.isclose(sm.times, t, rtol=0.0, atol=1e-9)):
        raise ValueError(
            f"Expected `time` strictly inside ({sm.times[0]}, {sm.times[-1]}) and not on a pose, got {time!r}"
        )
    mask = _variables_mask(sm, joints)
    pos = int(np.searchsorted(sm.times, t))
    T = sm.times[:, None] + sm.refinements
    for i in np.flatnonzero(mask):
        act = np.flatnonzero(sm.active[:, i])
        before, after = T[act[act < pos], i], T[act[act >= pos], i]
        if not (before.max() < t < after.min()):
            raise ValueError(
                f"A knot of {sm.variables[i]!r} at {t:.4f} s would cross its refined neighbours "
                f"({before.max():.4f}, {after.min():.4f}) s: choose another time or fewer `joints`"
            )
    p_now, rot = sm._compose(np.array([t]), noise=False)  # the knot is a value of the retimed layers
    old_to_new = np.arange(K) + (np.arange(K) >= pos)
    times = np.insert(sm.times, pos, t)
    refinements = np.insert(sm.refinements, pos, 0.0, axis=0)
    active = np.insert(sm.active, pos, mask, axis=0)
    # rotation knot in the hemisphere of its predecessor
    prev_rot = sm.rotation_values[pos - 1]
    q = np.where(np.sum(rot[0] * prev_rot, axis=-1, keepdims=True) < 0, -rot[0], rot[0])
    position_values = np.insert(sm.position_values, pos, p_now[0], axis=0)
    rotation_values = np.insert(sm.rotation_values, pos, q, axis=0)
    refit = np.zeros((K + 1, V), dtype=bool)
    for i in np.flatnonzero(mask):
        prev = np.flatnonzero(active[:pos, i])[-1]
        refit[prev, i] = True
        refit[pos, i] = True
    priorities = np.insert(sm.priorities, pos, np.nan)
    return _restructure(
        sm,
        times=times,
        refinements=refinements,
        active=active,
        position_values=position_values,
        rotation_values=rotation_values,
        old_to_new=old_to_new,
        refit=refit,
        priorities=priorities,
    )


def delete_pose(sm: StaggeredMotion, k: int) -> StaggeredMotion:
    """Remove pose ``k`` (not the first or last); the motion is unchanged (section 5.1).

    The two segments around the pose merge; their spline is refitted and
    the displacement maps re-measured.

    Parameters
    ----------
    sm : StaggeredMotion
    k : int
        Pose index, 1 to ``K - 2``.

    Returns
    -------
    StaggeredMotion
        With ``K - 1`` poses.

    Examples
    --------
    >>> import numpy as np
    >>> import mocaplab as ml
    >>> sm = ml.staggered.extract(ml.cmu("16_15").resample(30)[:60])
    >>> fewer = ml.staggered.delete_pose(sm, 2)
    >>> fewer.n_poses, sm.n_poses
    (5, 6)
    >>> bool(np.allclose(fewer.evaluate().global_positions(), sm.evaluate().global_positions()))
    True
    """
    k = sm._pose_index(k)
    K, V = sm.n_poses, sm.n_variables
    if k in (0, K - 1):
        raise ValueError(f"Expected an interior pose index in [1, {K - 2}], got {k}: the ends are needed")
    if K <= 2:
        raise ValueError("Cannot delete a pose of a two-pose representation")
    old_to_new = np.arange(K) - (np.arange(K) > k)
    old_to_new[k] = -1
    times = np.delete(sm.times, k)
    refinements = np.delete(sm.refinements, k, axis=0)
    active = np.delete(sm.active, k, axis=0)
    refit = np.zeros((K - 1, V), dtype=bool)
    for i in np.flatnonzero(sm.active[k]):
        prev = np.flatnonzero(active[:k, i])[-1]
        refit[prev, i] = True
    return _restructure(
        sm,
        times=times,
        refinements=refinements,
        active=active,
        position_values=np.delete(sm.position_values, k, axis=0),
        rotation_values=np.delete(sm.rotation_values, k, axis=0),
        old_to_new=old_to_new,
        refit=refit,
        priorities=np.delete(sm.priorities, k),
    )
