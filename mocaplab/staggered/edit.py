"""Editing staggered poses (Coleman et al. 2008, section 5).

Every function takes a :class:`~mocaplab.staggered.StaggeredMotion` and
returns a new one (the methods of that class call these).

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

Constraint layer
----------------
:class:`ConstraintLayer` is the final displacement layer of section 3: on
contact intervals (mapped through the pose timing), the feet (and any other
constrained end effector) are brought back to their original positions by
the package's one goal solver, :func:`mocaplab.goals.solve_goals`, with
:class:`~mocaplab.goals.Goal` weights blended in and out over a short
window by :func:`mocaplab.goals.blend_weights`.

Joints are never named here: the succession's default joint is the pelvis
and the constraint layer's joints are the feet of the skeleton's joint roles
(:mod:`mocaplab.roles`; every entry point that needs them accepts
``roles=``).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping, Sequence
from typing import Any, Literal, Union

import numpy as np
from numpy.typing import ArrayLike, NDArray

from .. import kinematics, quat
from .._warnings import warn
from ..displacement import blend_ramp
from ..motion import Motion, Skeleton
from ..roles import RolesError, resolve_roles
from ..undo import Undoable, UndoStack
from .representation import (
    StaggeredMotion,
    bezier,
    casteljau,
    locate,
    next_active,
    pose_time,
    pose_u,
    slerp_unit,
)

__all__ = [
    "ReferencePose",
    "set_refinements",
    "keep_knot_order",
    "retime",
    "succession",
    "succession_depths",
    "randomize",
    "limb_groups",
    "LIMBS",
    "edit_pose",
    "exaggerate",
    "apply_knot_deltas",
    "insert_pose",
    "delete_pose",
    "average_pose",
    "ConstraintLayer",
    "UnreachableTargetWarning",
    "constraint_joints",
    "default_joint",
    "EditorParams",
    "StaggeredEditor",
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
def keep_knot_order(sm: StaggeredMotion, refinements: ArrayLike, *, gap: float | None = None) -> Array:
    """Refinements nudged so every variable's refined knots stay ordered.

    Each refined knot is kept at least ``gap`` seconds (default one frame)
    after the previous knot of its variable and before the next one, by the
    smallest moves (a forward then a backward running max/min); the first and
    last knots do not move.  Used by the procedural timing tools so a slider
    can never produce crossing knots.

    Returns
    -------
    ndarray, shape (K, V)
    """
    r = np.array(refinements, dtype=float, copy=True)
    g = 1.0 / sm.fps if gap is None else float(gap)
    T = sm.times[:, None] + r
    T0 = np.array(T, copy=True)
    for i in range(sm.n_variables):
        idx = np.flatnonzero(sm.active[:, i])
        n = np.arange(idx.size) * g
        x = T[idx, i]
        # T_k >= T_{k-1} + g  <=>  z = T - k g is non-decreasing
        z = x - n
        z1 = np.maximum.accumulate(z)
        z1[-1] = z[-1]
        z2 = np.minimum.accumulate(z1[::-1])[::-1]
        z2[0] = z[0]
        T[idx, i] = np.where(z2 != z, z2 + n, x)
    moved = T != T0
    return np.where(sm.active, np.where(moved, T - sm.times[:, None], r), 0.0)


def set_refinements(sm: StaggeredMotion, refinements: ArrayLike) -> StaggeredMotion:
    """A copy with new refinements, shape (K, V) seconds.

    Raises ``ValueError`` if a variable's refined knots would cross; warns
    (:class:`~mocaplab.staggered.StaggeredTimingWarning`) when a knot is closer
    to a neighbouring pose than to its own.
    """
    r = np.asarray(refinements, dtype=float)
    if r.shape != sm.refinements.shape:
        raise ValueError(f"Expected `refinements` of shape {sm.refinements.shape}, got {r.shape}")
    if np.array_equal(r, sm.refinements):
        return sm
    out = _replace(sm, refinements=np.where(sm.active, r, 0.0))
    for cached in ("_ctrl", "_static"):  # values, tangents and displacements are unchanged by retiming
        if cached in sm.__dict__:
            object.__setattr__(out, cached, sm.__dict__[cached])
    out._inherit_raw(sm, np.any(r != sm.refinements, axis=0))
    out._warn_timing()
    return out


def retime(sm: StaggeredMotion, k: int, time: float) -> StaggeredMotion:
    """Move pose ``k`` (not the first) to ``time`` seconds, its refinements with it.

    Moving the last pose changes the duration.  Pose times must stay
    strictly increasing.
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
    Default joint: the pelvis (:func:`default_joint`, ``roles`` overriding).
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
        ``s = 0`` returns an identical motion.  Knots that would cross a
        neighbour of the same variable are stopped one frame short of it
        (:func:`keep_knot_order`).
    """
    if not np.isfinite(s):
        raise ValueError(f"Expected a finite `s` in seconds, got {s!r}")
    if not (np.isfinite(l) and l > 0):
        raise ValueError(f"Expected `l` > 0, got {l!r}")
    d = succession_depths(sm.skeleton, joint, translation_joints=sm.translation_joints, roles=roles)
    offset = np.where(np.isfinite(d), float(s) * np.power(np.nan_to_num(d), float(l)), 0.0)
    r = np.array(sm.refinements, copy=True)
    ks = _poses(sm, poses, interior=True)
    r[ks] += offset
    return set_refinements(sm, keep_knot_order(sm, r))


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
    tau : float >= 0
        Bound of the offsets, seconds.
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
    """
    if not (np.isfinite(tau) and tau >= 0):
        raise ValueError(f"Expected `tau` >= 0 seconds, got {tau!r}")
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
    then the noise layer, ``exp(d) exp(n)``.
    """
    t = np.array([sm.times[k]])
    k0, k1, tn = sm.locate(t)
    s_pos, s_rot = sm._spline_layers(k0, tn)
    d_pos, d_rot = sm._displacement_layers(k0 + tn * (k1 - k0))
    D = quat.mul(quat.exp(d_rot[0]), quat.exp(sm.noise_values(t)[0]))
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
            out[j] = quat.normalize(np.asarray(q, dtype=float).reshape(4))
            mask[j] = True
        return out, mask
    arr = np.asarray(rotations, dtype=float)
    if arr.shape != (J, 4):
        raise ValueError(f"Expected `rotations` of shape ({J}, 4) or a dict joint -> quaternion, got {arr.shape}")
    return quat.normalize(arr), np.ones(J, dtype=bool)


def _position_targets(
    sm: StaggeredMotion, root_position: ArrayLike | None, translations: Mapping[str, ArrayLike] | None
) -> tuple[Array, NDArray[np.bool_]]:
    """(P, 3) position targets and a (P,) mask from a root position and a ``{joint: (3,)}`` dict."""
    P = 1 + sm.n_translations
    out = np.zeros((P, 3))
    mask = np.zeros(P, dtype=bool)
    if root_position is not None:
        out[0] = np.asarray(root_position, dtype=float).reshape(3)
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
            out[p] = np.asarray(value, dtype=float).reshape(3)
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
    k : int
    root_position : array_like, shape (3,), optional
        New root translation (metres).
    rotations : array_like, shape (J, 4), or dict of joint name -> (4,), optional
        New local rotations; with a dict only the named joints change.
    translations : dict of joint name -> (3,), optional
        New local translations of joints with a translation variable
        (metres, parent frame).
    which : {"non-staggered", "true"}
        ``"non-staggered"``: the values are the new extreme values
        ``v_hat_{k,i}``; editing knots are offset by the same change.
        ``"true"``: the values are the new pose at ``t_k`` (editing knots);
        afterwards ``true_pose(k)`` returns exactly them and the extreme knots
        received the same change.

    Returns
    -------
    StaggeredMotion
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
    new_rot = quat.mul(rot, quat.exp(w_r * quat.log(rel)))
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
    from .fit import fit_rotation_tangents, fit_translation_tangents

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
    """
    t = float(time)
    K, V = sm.n_poses, sm.n_variables
    if not sm.times[0] < t < sm.times[-1] or np.any(np.isclose(sm.times, t, rtol=0.0, atol=1e-9)):
        raise ValueError(f"Expected `time` strictly inside ({sm.times[0]}, {sm.times[-1]}) and not on a pose, got {time!r}")
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
        sm, times=times, refinements=refinements, active=active, position_values=position_values,
        rotation_values=rotation_values, old_to_new=old_to_new, refit=refit, priorities=priorities,
    )


def delete_pose(sm: StaggeredMotion, k: int) -> StaggeredMotion:
    """Remove pose ``k`` (not the first or last); the motion is unchanged (section 5.1).

    The two segments around the pose merge; their spline is refitted and
    the displacement maps re-measured.
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
        sm, times=times, refinements=refinements, active=active,
        position_values=np.delete(sm.position_values, k, axis=0),
        rotation_values=np.delete(sm.rotation_values, k, axis=0),
        old_to_new=old_to_new, refit=refit, priorities=np.delete(sm.priorities, k),
    )


# ------------------------------------------------------- constraint layer
GoalKind = Literal["foot", "toe", "limb"]


def constraint_joints(
    skeleton: Skeleton, candidates: Sequence[str], *, roles: Mapping[str, Any] | None = None
) -> tuple[tuple[str, ...], tuple[GoalKind, ...]]:
    """The joints of ``candidates`` the constraint layer can hold, and how.

    From the joint roles (:func:`mocaplab.roles.resolve_roles`): an ankle
    is a ``"foot"`` goal (the leg's two-bone IK), a toe whose parent is an
    ankle a ``"toe"`` goal (the foot turns about the ankle), a wrist a
    ``"limb"`` goal (the arm's two-bone IK); other joints are left out.
    Returns the kept joint names (in the order of ``candidates``) and their
    kinds of :class:`~mocaplab.goals.Goal`.
    """
    r = resolve_roles(skeleton, roles)
    ankles = {r[f"{s}_ankle"] for s in ("left", "right") if f"{s}_ankle" in r}
    toes = {r[f"{s}_toe"] for s in ("left", "right") if f"{s}_toe" in r}
    wrists = {r[f"{s}_wrist"] for s in ("left", "right") if f"{s}_wrist" in r}
    names: list[str] = []
    kinds: list[GoalKind] = []
    for name in candidates:
        j = skeleton.index(name)
        parent = skeleton.names[int(skeleton.parents[j])] if j > 0 else None
        if name in ankles:
            kind: GoalKind | None = "foot"
        elif name in toes:
            kind = "toe" if parent in ankles else None
        elif name in wrists:
            kind = "limb"
        else:
            kind = None
        if kind is not None:
            names.append(name)
            kinds.append(kind)
    return tuple(names), tuple(kinds)


#: Seconds on each side over which the constraint layer's root lowering is
#: smoothed (``drop_window`` of :func:`mocaplab.goals.solve_goals`).
_DROP_WINDOW = 0.15
#: Fraction of a leg's length the layer's root lowering keeps a held leg
#: within (``reach`` of :func:`mocaplab.goals.solve_goals`).  Near full
#: extension the knee angle is very sensitive to the hip: at 0.99 the broad
#: jump 16_05 under a succession of 0.02 s snaps its knee to 167 degrees and
#: back at take-off (1,048 rad/s^2, the input 198); at 0.96, 529.
_REACH = 0.96
#: The straightest a held leg may stay (``max_reach`` of :func:`mocaplab.goals.solve_goals`): the
#: walk 16_15 with its legs exaggerated by 0.5 straightens a knee to 4 degrees where the toe still holds,
#: and a target brushing past that makes the held knee dip and return within 5 frames (peak knee
#: acceleration 779 rad/s^2 uncapped, 436 at 0.997, 345 at 0.995; the edit alone 230).  Lower caps
#: lower the root more often: the salsa 60_10 exaggerated by 0.3 goes from 1,970 to 2,122 (0.997) and
#: 2,251 (0.995).
_MAX_REACH = 0.997


def _frames_of(seconds: float, fps: float) -> int:
    """Whole frames covering ``seconds`` at ``fps`` (at least 1)."""
    return max(int(np.ceil(seconds * fps - 1e-9)), 1)


class UnreachableTargetWarning(UserWarning):
    """The constraint layer could not bring a joint to its target on some frames (an edit took it out of reach)."""


@dataclasses.dataclass(frozen=True, eq=False)
class ConstraintLayer:
    """Contact constraints as the last displacement layer (section 3).

    On the frames of a contact each constrained joint is held at its
    original world position by the one goal solver of the package,
    :func:`mocaplab.goals.solve_goals` (ankles by the leg's two-bone
    IK, toes by turning the foot about the ankle, wrists by the arm's
    two-bone IK), with weights that are 1 inside the contact and fall to 0
    over ``window`` seconds on each side
    (:func:`mocaplab.goals.blend_weights`).  The motion's translation
    channels take part in the forward kinematics and are passed through.

    * **Timing.**  A contact and its targets are laid on the original
      frames, which follow the pose timing (``pose_u``): retimed poses carry
      their contacts.  ``timing`` can instead make a joint's contacts follow
      the knots of a control variable, for instance its own rotation (the
      foot's own refinements, ``timing=layer.joints``), through the
      representation's displacement-sample positions
      (:attr:`StaggeredMotion.sample_u`).  Measured on the walk 16_15 under
      whole-body succession (``s`` = 0.01 and 0.02 s, ``l = 1``), following
      the feet's refinements made the solver change the motion *more*
      (mean 0.82 against 0.35 degrees, peak knee acceleration 609 against
      275 rad/s^2, the edit without the layer 178): the root is not
      delayed with the legs, so a delayed leg cannot hold a plant at any
      shifted time, and a later plant only adds to the correction.  Pose
      timing is the default.
    * **Bending direction.**  Every two-bone limb bends about the hinge its
      middle joint had in the *input* clip (``hinges``,
      :func:`mocaplab.ik.hinge_axes` on the source motion), so a knee never
      changes its bending direction relative to the input, however straight
      an edit makes it.
    * **Reach.**  Where a leg cannot reach, the solver lowers the root,
      smoothly and by at most 15 cm (``adjust_root``, on by default, as in
      Kovar et al. 2002's footskate cleanup): without it a leg snaps
      straight and back (the walk with its legs exaggerated by 0.5: peak
      knee acceleration 750 against 563 rad/s^2; whole-body succession
      ``s = 0.01``: 2,580 against 275, the edit alone 178).  Where a joint
      still misses its target (a held joint by more than
      ``reach_tolerance``, or a two-bone goal beyond the limb's reach), an
      :class:`UnreachableTargetWarning` names the frames.

    Attributes
    ----------
    joints : tuple of str
        Constrained joints (see :func:`constraint_joints`).
    pose_u : ndarray, shape (N,)
        Position of each original frame in *pose-index units*
        (:func:`~mocaplab.staggered.representation.pose_u` of the pose times),
        so contacts and targets follow the poses when they are retimed
        (inserting or deleting a pose updates it).
    masks : ndarray of bool, shape (N, E)
        Contact state of each joint on the original frames.
    targets : ndarray, shape (N, E, 3)
        Original world positions of the joints (the targets kept).
    speeds : ndarray, shape (N, E), optional
        Original world speeds of the joints (m/s); a goal's stiffness is
        ``1 / (speed + 0.05 m/s)`` as in :func:`mocaplab.goals.foot_goals`,
        so where an ankle and its toe cannot both hold (one of them blending
        in or out) the foot rolls about the stiller one.  Default zeros.
    window : float
        Seconds over which the solution is blended in and out.
    tolerance : float
        Frames where every constrained joint is within this distance of its
        target (metres) are left alone, so the layer is the identity on the
        unedited motion and outside the edited stretch (a contact with any
        such frame is solved whole).
    kinds : tuple of str, optional
        The :class:`~mocaplab.goals.Goal` kind of each joint
        (``"foot"``, ``"toe"`` or ``"limb"``); default from the joint roles
        (:func:`constraint_joints`).
    adjust_root : bool
        Let the solver lower the root where a leg cannot reach its target
        (:func:`~mocaplab.goals.solve_goals`); on by default (see
        "Reach").
    timing : tuple of (str or None), optional
        For each joint, the control variable whose knots its contacts
        follow, or None for the pose timing; default all None.
    hinges : ndarray, shape (E, 3), optional
        The hinge of each joint's limb (for a toe, its ankle's leg) in the
        middle joint's local frame; default estimated on the motion solved.
    reach_tolerance : float
        Metres; see "Reach" above.
    """

    joints: tuple[str, ...]
    pose_u: Array
    masks: NDArray[np.bool_]
    targets: Array
    speeds: Array = None  # type: ignore[assignment]  # None: zeros
    window: float = 0.1
    tolerance: float = 1e-6
    kinds: tuple[GoalKind, ...] = ()
    adjust_root: bool = True
    timing: tuple[str | None, ...] = ()
    hinges: Array | None = None
    reach_tolerance: float = 0.005

    def __post_init__(self) -> None:
        joints = tuple(str(n) for n in self.joints)
        E = len(joints)
        pose_u = np.asarray(self.pose_u, dtype=float).reshape(-1)
        N = pose_u.size
        masks = np.asarray(self.masks, dtype=bool)
        if masks.shape != (N, E):
            raise ValueError(f"Expected `masks` of shape ({N}, {E}), got {masks.shape}")
        targets = np.asarray(self.targets, dtype=float)
        if targets.shape != (N, E, 3):
            raise ValueError(f"Expected `targets` of shape ({N}, {E}, 3), got {targets.shape}")
        speeds = np.zeros((N, E)) if self.speeds is None else np.asarray(self.speeds, dtype=float)
        if speeds.shape != (N, E) or not np.all(np.isfinite(speeds)) or np.any(speeds < 0):
            raise ValueError(f"Expected finite `speeds` >= 0 of shape ({N}, {E}), got shape {speeds.shape}")
        kinds = tuple(self.kinds)
        if kinds and (len(kinds) != E or any(k not in ("foot", "toe", "limb") for k in kinds)):
            raise ValueError(f"Expected `kinds` of 'foot', 'toe' or 'limb', one per joint {joints}, got {kinds}")
        timing = tuple(None if v is None else str(v) for v in self.timing) or (None,) * E
        if len(timing) != E:
            raise ValueError(f"Expected `timing` with one variable name per joint {joints}, got {timing}")
        if not (np.isfinite(self.window) and self.window >= 0):
            raise ValueError(f"Expected `window` >= 0 seconds, got {self.window!r}")
        if not (np.isfinite(self.reach_tolerance) and self.reach_tolerance > 0):
            raise ValueError(f"Expected `reach_tolerance` > 0 metres, got {self.reach_tolerance!r}")
        for name, value in (("pose_u", pose_u), ("masks", masks), ("targets", targets), ("speeds", speeds)):
            value.flags.writeable = False
            object.__setattr__(self, name, value)
        if self.hinges is not None:
            hinges = np.array(self.hinges, dtype=float)
            if hinges.shape != (E, 3) or not np.all(np.isfinite(hinges)):
                raise ValueError(f"Expected finite `hinges` of shape ({E}, 3), got shape {hinges.shape}")
            hinges.flags.writeable = False
            object.__setattr__(self, "hinges", hinges)
        object.__setattr__(self, "joints", joints)
        object.__setattr__(self, "kinds", kinds)
        object.__setattr__(self, "timing", timing)
        object.__setattr__(self, "window", float(self.window))

    @classmethod
    def from_contacts(
        cls,
        motion: Motion,
        contacts: Any,
        times: Array,
        *,
        joints: Sequence[str] | None = None,
        window: float = 0.1,
        roles: Mapping[str, Any] | None = None,
        adjust_root: bool = True,
    ) -> ConstraintLayer:
        """Build the layer from a clip, its Contacts and the pose times (seconds).

        Default joints: the contact joints that are feet (ankles, toes) or
        wrists in the joint roles (:func:`constraint_joints`, ``roles``
        overriding); for CMU feet: LeftFoot, LeftToeBase, RightFoot,
        RightToeBase.  Given ``joints`` must be among them.  The hinges of
        their limbs are measured on ``motion`` (:func:`mocaplab.ik.hinge_axes`).
        """
        from ..ik import hinge_axes, limb_joints

        sk = motion.skeleton
        if contacts.n_frames != motion.n_frames:
            raise ValueError(
                f"Expected contacts over the motion's {motion.n_frames} frames, got {contacts.n_frames}"
            )
        names, kinds = constraint_joints(sk, tuple(contacts.joints) if joints is None else tuple(joints), roles=roles)
        if joints is not None and len(names) != len(tuple(joints)):
            bad = [n for n in joints if n not in names]
            raise ValueError(
                f"Expected `joints` that are ankles, toes (below an ankle) or wrists in the joint roles, got {bad}; "
                "name the roles with roles={...} or skeleton.with_roles(...)"
            )
        idx = [sk.index(n) for n in names]
        masks = np.stack([contacts.of(n) for n in names], axis=1) if names else np.zeros((motion.n_frames, 0), bool)
        grot, gpos = motion.global_rotations(), motion.global_positions()
        targets = np.array(gpos[:, idx])
        # the limb each goal bends: a toe's is its ankle's leg
        ends = [int(sk.parents[j]) if kind == "toe" else j for j, kind in zip(idx, kinds, strict=True)]
        limbs = [limb_joints(sk, e) for e in ends]
        return cls(
            joints=names,
            pose_u=pose_u(np.asarray(times, dtype=float), motion.times),
            masks=masks,
            targets=targets,
            speeds=np.linalg.norm(kinematics.velocities(targets, motion.fps), axis=-1),
            window=float(window),
            kinds=kinds,
            adjust_root=adjust_root,
            hinges=hinge_axes(grot, gpos, limbs) if limbs else np.zeros((0, 3)),
        )

    def frame_times(self, sm: StaggeredMotion, *, staggered: bool = True) -> Array:
        """Current time of every original frame for each joint, seconds, shape (N, E).

        Pose timing (``timing`` None): original frame ``n`` sits at
        ``pose_u[n]`` between ``sm``'s pose times.  A variable ``i``:
        frame ``n`` sits at ``sm.sample_u[n, i]`` along that variable's
        knots, and its time is found on ``sm``'s knots of it (pose times only
        with ``staggered=False``).
        """
        N = self.masks.shape[0]
        out = np.empty((N, len(self.joints)))
        on_poses = pose_time(sm.times, self.pose_u)
        for e, name in enumerate(self.timing):
            if name is None:
                out[:, e] = on_poses
                continue
            if sm.sample_u.shape[0] != N:
                raise ValueError(
                    f"The constraint layer covers {N} original frames, the representation's displacement maps "
                    f"{sm.sample_u.shape[0]}: build the layer from the clip the representation was extracted from"
                )
            i = sm.variable_index(name)
            act = np.flatnonzero(sm.active[:, i])
            T = sm.times[act] + (sm.refinements[act, i] if staggered else 0.0)
            u = sm.sample_u[:, i]
            s = np.clip(np.searchsorted(act, u, side="right") - 1, 0, act.size - 2)
            tn = (u - act[s]) / (act[s + 1] - act[s])
            out[:, e] = T[s] + tn * (T[s + 1] - T[s])
        return out

    def weights_and_targets(self, sm: StaggeredMotion, t: Array, *, staggered: bool = True) -> tuple[Array, Array]:
        """Blend weights (F, E) and targets (F, E, 3) at times ``t`` for ``sm``'s timing.

        The contact intervals, mapped onto ``sm``'s frames through each
        joint's timing (:meth:`frame_times`), are blended by
        :func:`mocaplab.goals.blend_weights` (weights between frames are
        interpolated); targets are interpolated between original frames.
        """
        from ..contacts import intervals_from_mask
        from ..goals import blend_weights

        t = np.asarray(t, dtype=float).reshape(-1)
        grid = np.arange(sm.n_frames) / sm.fps
        E = len(self.joints)
        window = int(round(self.window * sm.fps))
        w = np.zeros((t.size, E))
        tg = np.zeros((t.size, E, 3))
        n = np.arange(self.masks.shape[0], dtype=float)
        same = t.shape == grid.shape and np.array_equal(t, grid)
        for e, tau in enumerate(self.frame_times(sm, staggered=staggered).T):
            inside = np.interp(np.interp(grid, tau, n), n, self.masks[:, e].astype(float)) >= 0.5
            w_grid = blend_weights(grid.size, intervals_from_mask(inside), window=window)
            w[:, e] = w_grid if same else np.interp(t, grid, w_grid)
            at = np.interp(t, tau, n)
            tg[:, e] = np.stack([np.interp(at, n, self.targets[:, e, c]) for c in range(3)], axis=-1)
        return w, tg

    def _speeds_at(self, sm: StaggeredMotion, t: Array, staggered: bool) -> Array:
        n = np.arange(self.masks.shape[0], dtype=float)
        tau = self.frame_times(sm, staggered=staggered)
        return np.stack(
            [np.interp(np.interp(t, tau[:, e], n), n, self.speeds[:, e]) for e in range(len(self.joints))], axis=-1
        ).reshape(t.size, len(self.joints))

    def apply(self, sm: StaggeredMotion, motion: Motion, t: Array, *, staggered: bool = True) -> Motion:
        """Hold the constrained joints on their targets (:func:`mocaplab.goals.solve_goals`).

        Warns (:class:`UnreachableTargetWarning`) naming the frames where,
        by more than ``reach_tolerance``, a fully held joint misses its
        target or a two-bone goal's blended target lies beyond its limb's
        reach (:func:`mocaplab.ik.reach_residual`).
        """
        from ..contacts import intervals_from_mask
        from ..goals import Goal, solve_goals

        if not self.joints:
            return motion
        w, tg = self.weights_and_targets(sm, t, staggered=staggered)
        sk = motion.skeleton
        idx = [sk.index(n) for n in self.joints]
        pos = motion.global_positions()[:, idx]
        err = np.linalg.norm(pos - tg, axis=-1)
        need = np.any((w > 0) & (err > self.tolerance), axis=1)
        if not need.any():
            return motion
        # solve whole contacts (runs of positive weight), so the solver sees them without gaps, and
        # the frames around them the root lowering spreads over (a smooth lower envelope of its need,
        # which reaches zero within twice its half-width of the last frame a goal holds): cut short
        # at a contact's end, the pelvis would jump back up in one frame
        pad = 2 * _frames_of(_DROP_WINDOW, motion.fps) + 2 if self.adjust_root else 0
        on = np.zeros(w.shape[0], dtype=bool)
        for a, b in intervals_from_mask(np.any(w > 0, axis=1)):
            if need[a:b].any():
                on[max(a - pad, 0) : b + pad] = True
        frames = np.flatnonzero(on)
        kinds = self.kinds or constraint_joints(sk, self.joints)[1]
        if len(kinds) != len(self.joints):
            raise ValueError(f"Joints {self.joints} have no goal kind on this skeleton: pass `kinds`")
        tr = motion.translations
        sub = motion.replace(
            rotations=motion.rotations[frames],
            root_positions=motion.root_positions[frames],
            translations=None if tr is None else tr[frames],
        )
        stiffness = 1.0 / (self._speeds_at(sm, t[frames], staggered) + 0.05)
        goals = [
            Goal(name, tg[frames, e], w[frames, e], kind=kinds[e], stiffness=stiffness[:, e])
            for e, name in enumerate(self.joints)
        ]
        hinges: dict[str | int, Array] | None = None
        if self.hinges is not None:
            hinges = {}
            for e, (j, kind) in enumerate(zip(idx, kinds, strict=True)):
                end = int(sk.parents[j]) if kind == "toe" else j
                hinges.setdefault(end, self.hinges[e])
        solved = solve_goals(
            sub, goals, adjust_root=self.adjust_root, hinges=hinges, drop_window=_DROP_WINDOW, reach=_REACH,
            max_reach=_MAX_REACH,
        )
        # out of reach: a fully held joint misses its target, or a two-bone
        # goal's blended target lies beyond its limb (the limb went straight)
        from ..ik import limb_joints, reach_residual

        spos = solved.global_positions()
        wf = w[frames]
        miss = np.where(wf >= 1.0 - 1e-9, np.linalg.norm(spos[:, idx] - tg[frames], axis=-1), 0.0)  # (n, E)
        for e, (j, kind) in enumerate(zip(idx, kinds, strict=True)):
            if kind != "toe":
                u_, m_, _ = limb_joints(sk, j)
                want = pos[frames, e] + wf[:, e, None] * (tg[frames, e] - pos[frames, e])
                gap = reach_residual(spos[:, u_], spos[:, m_], spos[:, j], want)
                miss[:, e] = np.maximum(miss[:, e], np.where(wf[:, e] > 0, gap, 0.0))
        bad = miss > self.reach_tolerance
        if bad.any():
            rows = np.zeros(w.shape[0], dtype=bool)
            rows[frames[bad.any(axis=1)]] = True
            spans = ", ".join(f"{a}-{b - 1}" if b - a > 1 else f"{a}" for a, b in intervals_from_mask(rows))
            worst = np.unravel_index(int(np.argmax(miss)), miss.shape)
            warn(
                f"Constraint layer: targets out of reach on frames {spans} "
                f"({self.joints[worst[1]]!r} misses by up to {1000 * miss[worst]:.0f} mm): an edit moved the "
                "limb too far from where it was planted; undo part of the edit"
                + ("" if self.adjust_root else ", or let the solver lower the root (adjust_root=True)"),
                UnreachableTargetWarning,
            )
        rot = np.array(motion.rotations, copy=True)
        rot[frames] = solved.rotations
        if not self.adjust_root:
            return motion.replace(rotations=rot)
        root = np.array(motion.root_positions, copy=True)
        root[frames] = solved.root_positions
        if tr is None:
            return motion.replace(rotations=rot, root_positions=root)
        # the root lowering may sit on the pelvis's translation (below a static reference root)
        trans = np.array(tr, copy=True)
        trans[frames] = solved.translations
        return motion.replace(rotations=rot, root_positions=root, translations=trans)


# ------------------------------------------------------------ the editor
@dataclasses.dataclass(frozen=True)
class EditorParams:
    """Everything a :class:`StaggeredEditor` edit sets: one immutable record per undo state.

    :attr:`StaggeredEditor.current` is a function of this record (and the
    clip): the base representation culled to ``max_poses`` poses, then
    ``exaggerate(w_r, joints=exaggerate_joints)``,
    ``succession(s, l, joint=joint)`` and
    ``randomize(tau, seed=seed, by=random_by)``, each skipped when neutral;
    ``staggered`` chooses the playback, ``constraints`` whether the contact
    constraint layer holds the feet where they were planted, and
    ``selected`` the pose overlaid.
    """

    max_poses: int | None
    s: float = 0.0
    l: float = 1.0
    joint: str = ""
    tau: float = 0.0
    seed: int = 0
    random_by: Literal["variable", "limb"] = "variable"
    w_r: float = 0.0
    exaggerate_joints: tuple[str, ...] | None = None
    staggered: bool = True
    constraints: bool = True
    selected: int = 0


class StaggeredEditor(Undoable):
    """Stateful core of the staggered-pose explorer (the widget forwards to it).

    Holds a clip, its :class:`~mocaplab.staggered.features.PoseAnalysis`
    (computed once), the culled base representation and the current
    timing and geometric edit parameters (an :class:`EditorParams`
    record).  Every setter recomputes :attr:`current` from :attr:`base`, so
    edits never accumulate drift: ``base.exaggerate(w_r, joints=...)``
    (against the average pose), then ``.succession(s, l, joint=...)``, then
    ``.randomize(tau, seed=...)``, each skipped when neutral.  A rejected
    edit changes nothing (parameters, :attr:`current`, history) and
    explains why in :attr:`message`, as do timing warnings.

    History: every accepted change of the record is pushed on a
    :class:`mocaplab.undo.UndoStack`; :meth:`undo`, :meth:`redo` and
    :meth:`reset` (undoable) restore a record, and :attr:`current` is
    recomputed from the same base, so it is restored exactly (the base of a
    pose count is fitted once and kept).  Consecutive changes of one
    parameter (a slider dragged) merge into one undo step until
    :meth:`checkpoint`; a change that leaves the record as it was pushes
    nothing.

    Parameters
    ----------
    motion : Motion
    max_poses : int, optional
        Initial pose count (culling); default every candidate.
    joint : str, optional
        Joint the succession depth is measured from (default the pelvis,
        :func:`default_joint`).
    random_joints : sequence of str, optional
        Joints affected by random timing (default every joint).
    random_by : {"variable", "limb"}
        One random offset per variable (default) or per limb
        (:func:`randomize`).
    curve_joint : str, optional
        Variable whose curves :meth:`curves` returns (default the pelvis;
        a view setting, not part of the history).
    roles : mapping, optional
        Joint-role overrides (:func:`mocaplab.roles.resolve_roles`) for the
        defaults: the pelvis, the contact joints, the constraint layer.
    constraints : bool
        Play the contact constraint layer (feet held where the clip planted
        them; :class:`ConstraintLayer`): on by default, and
        :meth:`set_constraints` turns it off and on (an undoable edit).  The
        layer is built whenever the clip has contacts (``contacts`` of
        ``extract_options``, default ``"auto"``), so turning it on later
        costs nothing.
    **extract_options
        Passed to :func:`~mocaplab.staggered.extract`.

    Examples
    --------
    >>> ed = StaggeredEditor(walk, max_poses=8)          # doctest: +SKIP
    >>> ed.set_succession(s=0.02); ed.set_succession(s=0.04); ed.checkpoint()  # doctest: +SKIP
    >>> ed.undo(); ed.s                                  # doctest: +SKIP
    0.0
    """

    #: Bases (one per pose count) kept for undo without refitting.
    BASE_CACHE = 8

    def __init__(
        self,
        motion: Motion,
        *,
        max_poses: int | None = None,
        joint: str | None = None,
        random_joints: Sequence[str] | None = None,
        random_by: Literal["variable", "limb"] = "variable",
        curve_joint: str | None = None,
        roles: Mapping[str, Any] | None = None,
        constraints: bool = True,
        **extract_options: Any,
    ) -> None:
        from .features import analyze
        from .fit import extract

        if not isinstance(motion, Motion):
            raise TypeError(f"Expected `motion` to be a Motion, got {type(motion).__name__}")
        if roles is not None:
            # pinned on the skeleton: analysis, extraction and edits all see them
            motion = motion.replace(skeleton=motion.skeleton.with_roles(**dict(resolve_roles(motion, roles))))
        self.motion = motion
        self._extract = extract
        self._options = dict(extract_options)
        contacts = self._options.pop("contacts", "auto")
        self.analysis = analyze(motion, contacts=contacts)
        # the layer is built once with every base (it needs contacts); `constraints` only chooses whether it plays
        # (analyze has already warned when the clip has no contact to hold)
        found = self.analysis.contacts
        self._options["constraints"] = found is not None and bool(np.any(found.mask))
        self.random_joints = None if random_joints is None else tuple(random_joints)
        if random_by not in ("variable", "limb"):
            raise ValueError(f"Expected `random_by` in ('variable', 'limb'), got {random_by!r}")
        joint = joint or default_joint(motion.skeleton)
        motion.skeleton.index(joint)
        self.curve_joint = curve_joint or default_joint(motion.skeleton)
        self._bases: dict[int | None, StaggeredMotion] = {}
        self.message = ""
        params = EditorParams(
            max_poses=None if max_poses is None else int(max_poses),
            joint=joint,
            random_by=random_by,
            constraints=bool(constraints),
        )
        self._params = params
        if not self._apply(params):
            raise ValueError(f"Expected a clip the editor can represent: {self.message}")
        self.undo_stack: UndoStack[EditorParams] = UndoStack(self._params)

    # ------------------------------------------------------------ the record
    @property
    def params(self) -> EditorParams:
        """The current edit parameters (an immutable record; the undo state)."""
        return self._params

    @property
    def max_poses(self) -> int | None:
        """Pose count (None: every candidate)."""
        return self._params.max_poses

    @property
    def s(self) -> float:
        """Succession offset per level of depth, seconds."""
        return self._params.s

    @property
    def l(self) -> float:  # noqa: E743 (the paper's name)
        """Succession exponent."""
        return self._params.l

    @property
    def joint(self) -> str:
        """Joint the succession depth is measured from."""
        return self._params.joint

    @property
    def tau(self) -> float:
        """Bound of the random timing offsets, seconds."""
        return self._params.tau

    @property
    def seed(self) -> int:
        """Seed of the random timing."""
        return self._params.seed

    @property
    def random_by(self) -> Literal["variable", "limb"]:
        """Random offsets per 'variable' or per 'limb'."""
        return self._params.random_by

    @property
    def w_r(self) -> float:
        """Relative exaggeration against the average pose."""
        return self._params.w_r

    @property
    def exaggerate_joints(self) -> tuple[str, ...] | None:
        """Joints exaggerated (None: all)."""
        return self._params.exaggerate_joints

    @property
    def staggered(self) -> bool:
        """Staggered (True) or non-staggered playback."""
        return self._params.staggered

    @property
    def constraints(self) -> bool:
        """The contact constraint layer plays (feet planted; on by default)."""
        return self._params.constraints

    @property
    def selected(self) -> int:
        """The pose overlaid in 3D."""
        return self._params.selected

    def _base(self, max_poses: int | None) -> StaggeredMotion:
        """The representation culled to ``max_poses`` poses, fitted once per count."""
        base = self._bases.get(max_poses)
        if base is None:
            base = self._extract(self.motion, max_poses=max_poses, analysis=self.analysis, **self._options)
            if len(self._bases) >= self.BASE_CACHE:
                self._bases.pop(next(k for k in self._bases if k != self._params.max_poses))
            self._bases[max_poses] = base
        return base

    def _apply(self, params: EditorParams) -> bool:
        """Make ``params`` current (recomputing from its base); False, with :attr:`message`, if rejected."""
        import warnings

        from .representation import StaggeredTimingWarning

        base = self._base(params.max_poses)
        params = dataclasses.replace(params, selected=min(params.selected, base.n_poses - 1))
        sm = base
        message = ""
        try:
            with warnings.catch_warnings(record=True) as caught:
                warnings.simplefilter("always", StaggeredTimingWarning)
                if params.w_r != 0.0:
                    sm = sm.exaggerate(params.w_r, joints=params.exaggerate_joints)
                if params.s != 0.0:
                    sm = sm.succession(params.s, params.l, joint=params.joint)
                if params.tau > 0.0:
                    sm = sm.randomize(params.tau, joints=self.random_joints, seed=params.seed, by=params.random_by)
            if caught:
                message = str(caught[-1].message)
        except ValueError as exc:
            self.message = f"edit rejected: {exc}"
            return False
        self._params, self.base, self.current, self.message = params, base, sm, message
        return True

    def _edit(self, merge: str, **changes: Any) -> None:
        """Apply a change of the record and push it (merged with the last push of the same ``merge`` key)."""
        new = dataclasses.replace(self._params, **changes)
        if new == self._params:
            return
        if self._apply(new):
            self.undo_stack.push(self._params, merge=merge)

    def _restore(self, params: EditorParams) -> None:
        if not self._apply(params):  # pragma: no cover - every state in the history was accepted once
            raise RuntimeError(f"Could not restore an earlier edit: {self.message}")

    # ------------------------------------------------------------- history
    def _go(self, params: EditorParams) -> EditorParams:
        self._restore(params)
        return self._params

    def _here(self) -> EditorParams:
        return self._params

    def _at_start(self) -> bool:
        return self._params == self.undo_stack.initial

    # ------------------------------------------------------------- setters
    @property
    def n_candidates(self) -> int:
        return int(self.analysis.candidates.size)

    def set_pose_count(self, n: int | None) -> None:
        """Cull to ``n`` poses (fits the representation once per count)."""
        if n is not None and (isinstance(n, bool) or not isinstance(n, (int, np.integer))):
            raise TypeError(f"Expected `n` to be an int or None, got {type(n).__name__}")
        self._edit("max_poses", max_poses=None if n is None else int(n))

    def set_succession(self, s: float | None = None, l: float | None = None, joint: str | None = None) -> None:
        """Set the succession offset ``s`` (seconds), exponent ``l`` and/or the depth joint."""
        changes: dict[str, Any] = {}
        if s is not None:
            changes["s"] = float(s)
        if l is not None:
            changes["l"] = float(l)
        if joint is not None:
            self.motion.skeleton.index(joint)
            changes["joint"] = joint
        self._edit("succession:" + ",".join(sorted(changes)), **changes)

    def set_random(
        self, tau: float | None = None, seed: int | None = None, by: Literal["variable", "limb"] | None = None
    ) -> None:
        """Set the random timing bound ``tau`` (seconds), the seed and/or per variable or per limb."""
        changes: dict[str, Any] = {}
        if tau is not None:
            changes["tau"] = float(tau)
        if seed is not None:
            changes["seed"] = int(seed)
        if by is not None:
            if by not in ("variable", "limb"):
                raise ValueError(f"Expected `by` in ('variable', 'limb'), got {by!r}")
            changes["random_by"] = by
        self._edit("random:" + ",".join(sorted(changes)), **changes)

    def set_exaggeration(self, w_r: float, joints: Sequence[str] | None = None) -> None:
        """Relative exaggeration of every pose against the average pose."""
        changes: dict[str, Any] = {"w_r": float(w_r)}
        if joints is not None:
            changes["exaggerate_joints"] = tuple(joints)
        self._edit("exaggeration:" + ",".join(sorted(changes)), **changes)

    def set_staggered(self, on: bool) -> None:
        """Staggered (True) or non-staggered (refinements zeroed) playback."""
        self._edit("staggered", staggered=bool(on))

    def set_constraints(self, on: bool) -> None:
        """Play the contact constraint layer (True: feet held where the clip planted them) or not."""
        self._edit("constraints", constraints=bool(on))

    def select(self, k: int) -> None:
        """Select pose ``k`` (for the 3D overlay); successive selections are one undo step."""
        self._edit("select", selected=self.current._pose_index(int(k)))

    def set_curve_joint(self, name: str) -> None:
        """Choose the variable :meth:`curves` returns (a view setting: not recorded in the history)."""
        self.current.variable_index(name)
        self.curve_joint = name

    # ------------------------------------------------------------- outputs
    @property
    def playback(self) -> StaggeredMotion:
        """The representation played: current, or with refinements zeroed."""
        return self.current if self.staggered else self.current.zero_refinements()

    def evaluate(self) -> Motion:
        """The dense motion being played (with the constraint layer when :attr:`constraints`)."""
        return self.current.evaluate(staggered=self.staggered, constraints=self.constraints)

    def curves(self, name: str | None = None) -> dict[str, Any]:
        """Curves of one variable for plotting.

        Returns a dict with ``"t"`` (F,), ``"values"`` (F, 3) (a root
        position or joint translation in metres, or the rotation vector
        ``log(q)`` in radians), ``"kind"`` (``"translation"`` or
        ``"rotation"``), ``"pose_times"`` (K,), ``"knot_times"`` (K,) and
        ``"knot_values"`` (K, 3) of the refined knots as played, and
        ``"original"`` (F0, 3) with ``"t0"`` of the source clip.
        """
        name = name or self.curve_joint
        sm = self.playback
        i = sm.variable_index(name)
        motion = self.evaluate()
        J = sm.n_joints

        def series(m: Motion) -> Array:
            if i == 0:
                return np.asarray(m.root_positions)
            if i > J:  # a translation variable: the clip has translation channels
                return np.asarray(m.translations)[:, sm.translation_joints[i - J - 1]]
            return quat.log(quat.unroll(m.rotations[:, i - 1], axis=0))

        act = sm.active[:, i]
        knots = (sm.times + sm.refinements[:, i])[act]
        vals = series(motion)
        return {
            "t": motion.times,
            "values": vals,
            "kind": "translation" if sm.is_translation(i) else "rotation",
            "pose_times": np.asarray(sm.times),
            "knot_times": knots,
            "knot_values": np.stack([np.interp(knots, motion.times, vals[:, d]) for d in range(3)], axis=1),
            "t0": self.motion.times,
            "original": series(self.motion),
        }

    def pose_table(self) -> list[tuple[int, float, float, int]]:
        """Rows ``(k, t_k, priority w_k, number of refined knots)``."""
        sm = self.current
        ek = sm.editing_knots.sum(axis=1)
        return [(k, float(sm.times[k]), float(sm.priorities[k]), int(ek[k])) for k in range(sm.n_poses)]

    def overlay(self, k: int | None = None) -> tuple[Motion, Motion]:
        """(non-staggered pose, true pose at t_k) of the selected pose, one frame each (Figure 6)."""
        k = self.selected if k is None else int(k)
        return (self.current.pose_motion(k, which="non-staggered"), self.current.pose_motion(k, which="true"))
