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
neighbouring pose's change with a smoothstep between them (zero slope at the
knots keeps the tangents continuous).  The result is then written back into
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

Constraint layer
----------------
:class:`ConstraintLayer` is the final displacement layer of section 3: on
contact intervals (mapped through the pose timing), the end effector is
brought back to its original position by two-bone IK
(:func:`mocaplab.ik.two_bone_ik`), blended in and out over a short window
with :func:`mocaplab.refinement.blend_ramp`.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence
from typing import Any, Literal, Union

import numpy as np
from numpy.typing import ArrayLike, NDArray

from .. import quat
from ..motion import Motion, Skeleton
from .representation import (
    StaggeredMotion,
    _smoothstep,
    casteljau,
    locate,
    next_active,
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
    "edit_pose",
    "exaggerate",
    "apply_knot_deltas",
    "insert_pose",
    "delete_pose",
    "average_pose",
    "ConstraintLayer",
    "StaggeredEditor",
]

Array = NDArray[np.float64]
ReferencePose = Union[Literal["average", "previous", "next"], int, tuple[ArrayLike, ArrayLike]]  # noqa: UP007 (runtime alias, py3.10)


# ------------------------------------------------------------------ helpers
def _variables_mask(sm: StaggeredMotion, joints: Sequence[str] | None, *, default_root: bool = True) -> NDArray[np.bool_]:
    """Bool mask (V,) of the named variables (joint names and/or ``"root_position"``)."""
    V = sm.n_variables
    if joints is None:
        mask = np.ones(V, dtype=bool)
        mask[0] = default_root
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


def succession_depths(skeleton: Skeleton, joint: str | Sequence[str] | None = None) -> Array:
    """Depth ``d(i)`` of every control variable below the chosen joint(s), shape (V,).

    The rotation of a joint ``c`` in the subtree of a chosen joint ``j`` has
    depth ``depth(c) - depth(j)`` (the chosen joint's own rotation: 0); with
    several chosen joints the nearest chosen ancestor counts.  The root
    translation has depth 0 when the root is chosen.  Variables outside every
    chosen subtree get NaN (they are not retimed).  Default joint: the root.
    """
    names = [skeleton.names[0]] if joint is None else ([joint] if isinstance(joint, str) else list(joint))
    chosen = {skeleton.index(n) for n in names}
    J = skeleton.n_joints
    depth = skeleton.depth()
    out = np.full(J + 1, np.nan)
    for c in range(J):
        a = c
        while a >= 0 and a not in chosen:
            a = int(skeleton.parents[a])
        if a >= 0:
            out[1 + c] = float(depth[c] - depth[a])
    if 0 in chosen:
        out[0] = 0.0
    return out


def succession(
    sm: StaggeredMotion,
    s: float,
    l: float = 1.0,
    *,
    joint: str | Sequence[str] | None = None,
    poses: Sequence[int] | None = None,
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
        Joint(s) the depth is measured from (default the root): only
        variables in their subtrees move.
    poses : sequence of int, optional
        Poses to edit (default every interior pose; the first and last poses
        anchor the clip's ends).

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
    d = succession_depths(sm.skeleton, joint)
    offset = np.where(np.isfinite(d), float(s) * np.power(np.nan_to_num(d), float(l)), 0.0)
    r = np.array(sm.refinements, copy=True)
    ks = _poses(sm, poses, interior=True)
    r[ks] += offset
    return set_refinements(sm, keep_knot_order(sm, r))


def randomize(
    sm: StaggeredMotion,
    tau: float,
    *,
    joints: Sequence[str] | None = None,
    poses: Sequence[int] | None = None,
    seed: int | None = 0,
) -> StaggeredMotion:
    """Random timing: ``r_hat_{k,i} += rand(-tau, tau)`` on chosen joints (section 5.2).

    Parameters
    ----------
    tau : float >= 0
        Bound of the offsets, seconds.
    joints : sequence of str, optional
        Variables to affect (joint names, ``"root_position"``); default every
        joint rotation.
    poses : sequence of int, optional
        Default every interior pose.
    seed : int, optional
        Seed of :func:`numpy.random.default_rng` (same seed, same offsets).
    """
    if not (np.isfinite(tau) and tau >= 0):
        raise ValueError(f"Expected `tau` >= 0 seconds, got {tau!r}")
    mask = _variables_mask(sm, joints, default_root=False)
    ks = _poses(sm, poses, interior=True)
    rng = np.random.default_rng(seed)
    noise = rng.uniform(-tau, tau, size=(ks.size, sm.n_variables))
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
    knot of ``k1`` and its extreme knot (``r > 0``), smoothstep in between.
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
    return _smoothstep((tn - a) / np.maximum(b - a, 1e-12))


def apply_knot_deltas(
    sm: StaggeredMotion,
    root_delta: ArrayLike,
    rotation_delta: ArrayLike,
) -> StaggeredMotion:
    """Give knots the changes ``Delta`` and write them back (see the module notes).

    Parameters
    ----------
    root_delta : array_like, shape (K, 3)
        Translation changes of the root-position knots (added).
    rotation_delta : array_like, shape (K, J, 4)
        Rotation changes, composed as ``v (+) Delta = mul(v, Delta)``.

    Returns
    -------
    StaggeredMotion
        Values ``v (+) Delta``; the motion equals the old
        ``spline (+) offset (+) displacement`` on every displacement sample,
        where the offset is ``Delta_k`` between pose ``k``'s editing knot and
        extreme knot, smoothly blended between poses.
    """
    K, J = sm.n_poses, sm.n_joints
    dr = np.asarray(root_delta, dtype=float).reshape(K, 3)
    dq = quat.normalize(np.asarray(rotation_delta, dtype=float).reshape(K, J, 4))
    dq = np.where(dq[..., 3:4] < 0, -dq, dq)
    changed = np.zeros((K, J + 1), dtype=bool)
    changed[:, 0] = np.any(dr != 0.0, axis=-1)
    changed[:, 1:] = quat.angle(dq) > 0.0
    changed &= sm.active
    if not changed.any():
        return sm
    new_root_values = sm.root_values + np.where(changed[:, :1], dr, 0.0)
    new_rot_values = np.where(changed[:, 1:, None], quat.mul(sm.rotation_values, dq), sm.rotation_values)
    new = _replace(sm, root_values=new_root_values, rotation_values=new_rot_values)
    # re-measure the displacement samples of the affected segments only
    k0, k1, tn = _segments_of_u(sm.sample_u, sm.active)
    col = np.arange(J + 1)
    hit = changed[k0, col] | changed[k1, col]
    d_root = np.array(sm.root_displacement, copy=True)
    d_rot = np.array(sm.rotation_displacement, copy=True)
    h = _edit_offset_weight(sm, k0, k1, tn)
    rows = np.flatnonzero(hit[:, 0])
    if rows.size:
        sub = (k0[rows], k1[rows], tn[rows])
        old, _ = sm.spline_values(*sub)
        nw, _ = new.spline_values(*sub)
        hh = h[rows, :1]
        e = (1.0 - hh) * dr[k0[rows, 0]] + hh * dr[k1[rows, 0]]
        d_root[rows] = old + e + sm.root_displacement[rows] - nw
    rows, js = np.nonzero(hit[:, 1:])
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
    out = _replace(new, root_displacement=d_root, rotation_displacement=d_rot)
    out._inherit_raw(sm, changed.any(axis=0))
    return out


def _rotation_spline_at(sm: StaggeredMotion, k0: NDArray[Any], k1: NDArray[Any], j: NDArray[Any], tn: Array) -> Array:
    """Rotation spline of joint(s) ``j`` on segments starting at ``k0`` at ``tn`` (all shape (n,))."""
    _, ctrl, theta = sm.control_points()
    return casteljau(ctrl[k0, j], theta[k0, j], tn)


def _true_layers(sm: StaggeredMotion, k: int) -> tuple[Array, Array, Array, Array]:
    """Spline and displacement of every variable at ``t_k``: s_root, d_root, s_rot, D_rot."""
    k0, k1, tn = sm.locate(np.array([sm.times[k]]))
    s_root, s_rot = sm.spline_values(k0, k1, tn)
    d_root, d_rot = sm.displacement_values(k0 + tn * (k1 - k0))
    return s_root[0], d_root[0], s_rot[0], quat.exp(d_rot[0])


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


def edit_pose(
    sm: StaggeredMotion,
    k: int,
    *,
    root_position: ArrayLike | None = None,
    rotations: ArrayLike | dict[str, ArrayLike] | None = None,
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
    K, J = sm.n_poses, sm.n_joints
    dr = np.zeros((K, 3))
    dq = np.tile([0.0, 0.0, 0.0, 1.0], (K, J, 1))
    tq, tmask = _rotation_targets(sm, rotations)
    tmask &= sm.active[k, 1:]
    if which == "non-staggered":
        if root_position is not None and sm.active[k, 0]:
            dr[k] = np.asarray(root_position, dtype=float).reshape(3) - sm.root_values[k]
        dq[k] = np.where(tmask[:, None], quat.mul(quat.inv(sm.rotation_values[k]), tq), dq[k])
    else:
        s_root, d_root, s_rot, D_rot = _true_layers(sm, k)
        if root_position is not None and sm.active[k, 0]:
            dr[k] = np.asarray(root_position, dtype=float).reshape(3) - (s_root + d_root)
        # s (+) Delta (+) D = target  ->  Delta = inv(s) target inv(D)
        delta = quat.mul(quat.mul(quat.inv(s_rot), tq), quat.inv(D_rot))
        dq[k] = np.where(tmask[:, None], delta, dq[k])
    return apply_knot_deltas(sm, dr, dq)


def average_pose(sm: StaggeredMotion, *, which: Literal["true", "non-staggered"] = "non-staggered") -> tuple[Array, Array]:
    """Average pose over all poses: mean root (3,), rotation means (J, 4).

    Rotations are averaged as the dominant eigenvector of ``sum q q^T``
    (sign independent).
    """
    root, rot = _pose_values(sm, which)
    M = np.einsum("kji,kjl->jil", rot, rot)
    _, vecs = np.linalg.eigh(M)
    mean = vecs[..., -1]
    mean = np.where(np.sum(mean * rot[0], axis=-1, keepdims=True) < 0, -mean, mean)
    return root.mean(axis=0), quat.normalize(mean)


def _pose_values(sm: StaggeredMotion, which: str) -> tuple[Array, Array]:
    if which == "non-staggered":
        return np.asarray(sm.root_values), np.asarray(sm.rotation_values)
    if which == "true":
        root, rot = sm._compose(sm.times)
        return root, rot
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
    reference : "average", "previous", "next", int, or (root (3,), rotations (J, 4))
        The relative pose: the average pose (global exaggeration), the
        previous or next pose (local; the first/last pose uses its only
        neighbour), a pose index, or explicit values.
    poses : sequence of int, optional
        Poses to edit (default all).
    joints : sequence of str, optional
        Variables to edit (joint names, ``"root_position"``); default every
        joint rotation (not the root translation).
    which : {"non-staggered", "true"}
        Apply to the extreme values or to the true poses at ``t_k`` (see
        :func:`edit_pose`).

    Returns
    -------
    StaggeredMotion
    """
    if not np.isfinite(w_r):
        raise ValueError(f"Expected a finite `w_r`, got {w_r!r}")
    K, J = sm.n_poses, sm.n_joints
    root, rot = _pose_values(sm, which)
    ks = _poses(sm, poses, interior=False)
    mask = _variables_mask(sm, joints, default_root=False)
    if isinstance(reference, str):
        if reference == "average":
            r_root, r_rot = average_pose(sm, which=which)
            ref_root = np.broadcast_to(r_root, (K, 3))
            ref_rot = np.broadcast_to(r_rot, (K, J, 4))
        elif reference in ("previous", "next"):
            idx = np.arange(K) + (-1 if reference == "previous" else 1)
            idx = np.where(idx < 0, 1, np.where(idx >= K, K - 2, idx))
            ref_root, ref_rot = root[idx], rot[idx]
        else:
            raise ValueError(f"Expected `reference` 'average', 'previous', 'next', an int or values, got {reference!r}")
    elif isinstance(reference, (int, np.integer)):
        r = sm._pose_index(int(reference))
        ref_root = np.broadcast_to(root[r], (K, 3))
        ref_rot = np.broadcast_to(rot[r], (K, J, 4))
    else:
        given_root, given_rot = reference
        ref_root = np.broadcast_to(np.asarray(given_root, dtype=float), (K, 3))
        ref_rot = np.broadcast_to(quat.normalize(np.asarray(given_rot, dtype=float)), (K, J, 4))
    new_root = root + w_r * (root - ref_root)
    rel = quat.mul(quat.inv(ref_rot), rot)
    new_rot = quat.mul(rot, quat.exp(w_r * quat.log(rel)))
    out = sm
    if which == "non-staggered":
        sel = np.zeros((K, J + 1), dtype=bool)
        sel[ks] = mask
        sel &= sm.active
        dr = np.where(sel[:, :1], new_root - root, 0.0)
        dq = np.where(sel[:, 1:, None], quat.mul(quat.inv(rot), new_rot), quat.identity((K, J)))
        return apply_knot_deltas(sm, dr, dq)
    # true poses: one knot-change per pose, all computed on the unedited motion
    K_r = np.zeros((K, 3))
    K_q = np.tile([0.0, 0.0, 0.0, 1.0], (K, J, 1))
    for k in ks:
        s_root, d_root, s_rot, D_rot = _true_layers(sm, int(k))
        act = sm.active[k] & mask
        if act[0]:
            K_r[k] = new_root[k] - (s_root + d_root)
        delta = quat.mul(quat.mul(quat.inv(s_rot), new_rot[k]), quat.inv(D_rot))
        K_q[k] = np.where(act[1:, None], delta, K_q[k])
    out = apply_knot_deltas(sm, K_r, K_q)
    return out


# --------------------------------------------------- creating/deleting poses
def _restructure(
    sm: StaggeredMotion,
    *,
    times: Array,
    refinements: Array,
    active: NDArray[np.bool_],
    root_values: Array,
    rotation_values: Array,
    old_to_new: NDArray[np.int64],
    refit: NDArray[np.bool_],
    priorities: Array,
) -> StaggeredMotion:
    """Re-parameterise the displacement samples for a new pose structure,
    refit the splines of segments starting at ``refit`` (K_new, V) and
    re-measure displacements so the motion is unchanged on every sample."""
    from .fit import fit_rotation_tangents, fit_translation_tangents

    K, J = times.size, sm.n_joints
    V = J + 1
    # current sample times and values
    k0, k1, tn = _segments_of_u(sm.sample_u, sm.active)
    col = np.arange(V)
    T_old = sm.times[:, None] + sm.refinements
    tau = T_old[k0, col] + tn * (T_old[k1, col] - T_old[k0, col])  # (N, V)
    s_root, s_rot = sm.spline_values(k0, k1, tn)
    v_root = s_root + sm.root_displacement
    v_rot = quat.mul(s_rot, quat.exp(sm.rotation_displacement))
    # new segments
    n0, n1, ntn = locate(times, refinements, active, tau)
    same = (old_to_new[k0] == n0) & (old_to_new[k1] == n1) & ~refit[n0, col]
    ntn = np.where(same, tn, ntn)
    nxt = next_active(active)
    nxt_safe = np.where(nxt < 0, np.arange(K)[:, None], nxt)
    # carry old tangents, refit the marked segments
    root_t = np.zeros((K, 2, 3))
    rot_t = np.tile([0.0, 0.0, 0.0, 1.0], (K, J, 2, 1))
    keep = old_to_new >= 0
    root_t[old_to_new[keep]] = sm.root_tangents[keep]
    rot_t[old_to_new[keep]] = sm.rotation_tangents[keep]
    if refit[:, 0].any():
        a, b = fit_translation_tangents(n0[:, 0], ntn[:, 0], v_root, root_values, root_values[nxt_safe[:, 0]])
        root_t[refit[:, 0]] = np.stack([a, b], axis=1)[refit[:, 0]]
    if refit[:, 1:].any():
        for j in np.flatnonzero(refit[:, 1:].any(axis=0)):
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
        root_values=root_values,
        rotation_values=rotation_values,
        root_tangents=root_t,
        rotation_tangents=rot_t,
        sample_u=n0 + ntn * (n1 - n0),
        priorities=priorities,
    )
    ns_root, ns_rot = new.spline_values(n0, n1, ntn)
    return _replace(
        new,
        root_displacement=v_root - ns_root,
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
        ``"root_position"``); default every variable.

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
    mask = _variables_mask(sm, joints, default_root=True)
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
    root, rot = sm._compose(np.array([t]))
    old_to_new = np.arange(K) + (np.arange(K) >= pos)
    times = np.insert(sm.times, pos, t)
    refinements = np.insert(sm.refinements, pos, 0.0, axis=0)
    active = np.insert(sm.active, pos, mask, axis=0)
    # rotation knot in the hemisphere of its predecessor
    prev_rot = sm.rotation_values[pos - 1]
    q = np.where(np.sum(rot[0] * prev_rot, axis=-1, keepdims=True) < 0, -rot[0], rot[0])
    root_values = np.insert(sm.root_values, pos, root[0], axis=0)
    rotation_values = np.insert(sm.rotation_values, pos, q, axis=0)
    refit = np.zeros((K + 1, V), dtype=bool)
    for i in np.flatnonzero(mask):
        prev = np.flatnonzero(active[:pos, i])[-1]
        refit[prev, i] = True
        refit[pos, i] = True
    priorities = np.insert(sm.priorities, pos, np.nan)
    return _restructure(
        sm, times=times, refinements=refinements, active=active, root_values=root_values,
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
        root_values=np.delete(sm.root_values, k, axis=0),
        rotation_values=np.delete(sm.rotation_values, k, axis=0),
        old_to_new=old_to_new, refit=refit, priorities=np.delete(sm.priorities, k),
    )


# ------------------------------------------------------- constraint layer
@dataclasses.dataclass(frozen=True, eq=False)
class ConstraintLayer:
    """Contact constraints as the last displacement layer (section 3).

    Attributes
    ----------
    joints : tuple of str
        End effectors (ankles, wrists): each is the end of a two-bone limb
        (:func:`mocaplab.ik.limb_joints`).
    pose_u : ndarray, shape (N,)
        Position of each original frame in *pose-index units*
        (``k + (t - t_k) / (t_{k+1} - t_k)``, pose times only), so contact
        intervals and targets follow the poses when they are retimed.
    masks : ndarray of bool, shape (N, E)
        Contact state of each effector on the original frames.
    targets : ndarray, shape (N, E, 3)
        Original world positions of the effectors (the targets kept).
    window : float
        Seconds over which the IK solution is blended in and out.
    tolerance : float
        Position errors below this (metres) are left alone, so the layer is
        the identity on the unedited motion.
    """

    joints: tuple[str, ...]
    pose_u: Array
    masks: NDArray[np.bool_]
    targets: Array
    window: float = 0.1
    tolerance: float = 1e-6

    @classmethod
    def from_contacts(
        cls,
        motion: Motion,
        contacts: Any,
        times: Array,
        *,
        joints: Sequence[str] | None = None,
        window: float = 0.1,
    ) -> ConstraintLayer:
        """Build the layer from a clip, its Contacts and the pose times (seconds).

        Default joints: the contact joints that end a two-bone limb and
        are not toes (for CMU feet: LeftFoot, RightFoot).
        """
        from ..ik import limb_joints

        sk = motion.skeleton
        if joints is None:
            joints = []
            for name in contacts.joints:
                if "toe" in name.lower():
                    continue
                try:
                    limb_joints(sk, name)
                except ValueError:
                    continue
                joints.append(name)
        joints = tuple(joints)
        idx = [sk.index(n) for n in joints]
        masks = np.stack([contacts.of(n) for n in joints], axis=1) if joints else np.zeros((motion.n_frames, 0), bool)
        targets = motion.global_positions()[:, idx]
        return cls(
            joints=joints,
            pose_u=_pose_u(np.asarray(times, dtype=float), motion.times),
            masks=masks,
            targets=np.array(targets),
            window=float(window),
        )

    def weights_and_targets(self, sm: StaggeredMotion, t: Array) -> tuple[Array, Array]:
        """Blend weights (F, E) and targets (F, E, 3) at times ``t`` for ``sm``'s pose timing."""
        from ..refinement import blend_ramp

        u = _pose_u(sm.times, t)
        # time of every original frame under the current pose timing
        k = np.clip(np.floor(self.pose_u).astype(np.int64), 0, sm.n_poses - 2)
        frac = self.pose_u - k
        t_src = sm.times[k] + frac * (sm.times[k + 1] - sm.times[k])
        F, E = t.size, len(self.joints)
        w = np.zeros((F, E))
        tg = np.zeros((F, E, 3))
        for e in range(E):
            m = self.masks[:, e]
            inside = np.interp(u, self.pose_u, m.astype(float)) >= 0.5
            # distance in seconds to the nearest contact frame (under the current timing)
            if m.any():
                ct = t_src[m]
                pos = np.clip(np.searchsorted(ct, t), 1, ct.size - 1) if ct.size > 1 else np.zeros(t.size, int)
                dist = np.minimum(np.abs(t - ct[pos - 1 if ct.size > 1 else 0]), np.abs(t - ct[pos]))
                ramp = blend_ramp(1.0 - dist / max(self.window, 1e-9)) if self.window > 0 else (dist == 0).astype(float)
                w[:, e] = np.where(inside, 1.0, ramp)
            for d in range(3):
                tg[:, e, d] = np.interp(u, self.pose_u, self.targets[:, e, d])
        return w, tg

    def apply(self, sm: StaggeredMotion, motion: Motion, t: Array, *, staggered: bool = True) -> Motion:
        """Blend the two-bone IK solution toward the targets into ``motion``."""
        from ..ik import limb_joints, two_bone_ik

        if not self.joints:
            return motion
        w, tg = self.weights_and_targets(sm, t)
        rot = np.array(motion.rotations, copy=True)
        for e, name in enumerate(self.joints):
            gpos = Motion(motion.skeleton, rot, motion.root_positions, motion.fps).global_positions()
            j = motion.skeleton.index(name)
            err = np.linalg.norm(gpos[:, j] - tg[:, e], axis=-1)
            frames = np.flatnonzero((w[:, e] > 0) & (err > self.tolerance))
            if frames.size == 0:
                continue
            up, mid, _ = limb_joints(motion.skeleton, name)
            solved = two_bone_ik(rot[frames], motion.root_positions[frames], motion.skeleton, name, tg[frames, e])
            for jj in (up, mid):
                rot[frames, jj] = quat.slerp(rot[frames, jj], solved[:, jj], w[frames, e])
        return motion.replace(rotations=rot)


def _pose_u(times: Array, t: Array) -> NDArray[Any]:
    """Position of times ``t`` in pose-index units (clamped to the poses)."""
    k = np.clip(np.searchsorted(times, t, side="right") - 1, 0, times.size - 2)
    return k + np.clip((t - times[k]) / (times[k + 1] - times[k]), 0.0, 1.0)


# ------------------------------------------------------------ the editor
class StaggeredEditor:
    """Stateful core of the staggered-pose explorer (the widget forwards to it).

    Holds a clip, its :class:`~mocaplab.staggered.features.PoseAnalysis`
    (computed once), the culled base representation and the current
    timing and geometric edit parameters.  Every setter recomputes
    :attr:`current` from :attr:`base`, so edits never accumulate drift:
    ``base.exaggerate(w_r, joints=...)`` (against the average pose), then
    ``.succession(s, l, joint=...)``, then ``.randomize(tau, seed=...)``,
    each skipped when neutral.  A rejected edit keeps the previous
    :attr:`current` and explains why in :attr:`message`, as do timing
    warnings.

    Parameters
    ----------
    motion : Motion
    max_poses : int, optional
        Initial pose count (culling); default every candidate.
    joint : str
        Joint the succession depth is measured from.
    random_joints : sequence of str, optional
        Joints affected by random timing (default every joint).
    curve_joint : str
        Variable whose curves :meth:`curves` returns.
    **extract_options
        Passed to :func:`~mocaplab.staggered.extract`.
    """

    def __init__(
        self,
        motion: Motion,
        *,
        max_poses: int | None = None,
        joint: str | None = None,
        random_joints: Sequence[str] | None = None,
        curve_joint: str | None = None,
        **extract_options: Any,
    ) -> None:
        from .features import analyze
        from .fit import extract

        self.motion = motion
        self._extract = extract
        self._options = dict(extract_options)
        contacts = self._options.pop("contacts", "auto")
        self.analysis = analyze(motion, contacts=contacts)
        self.max_poses = None if max_poses is None else int(max_poses)
        self.joint = joint or motion.skeleton.names[0]
        self.random_joints = None if random_joints is None else tuple(random_joints)
        self.curve_joint = curve_joint or motion.skeleton.names[0]
        self.s = 0.0
        self.l = 1.0
        self.tau = 0.0
        self.seed = 0
        self.w_r = 0.0
        self.exaggerate_joints: tuple[str, ...] | None = None
        self.staggered = True
        self.selected = 0
        self.message = ""
        self.base = self._extract(motion, max_poses=self.max_poses, analysis=self.analysis, **self._options)
        self.current = self.base
        self._update()

    # ------------------------------------------------------------- setters
    @property
    def n_candidates(self) -> int:
        return int(self.analysis.candidates.size)

    def set_pose_count(self, n: int | None) -> None:
        """Cull to ``n`` poses (re-fits the representation)."""
        self.max_poses = None if n is None else int(n)
        self.base = self._extract(self.motion, max_poses=self.max_poses, analysis=self.analysis, **self._options)
        self.selected = min(self.selected, self.base.n_poses - 1)
        self._update()

    def set_succession(self, s: float | None = None, l: float | None = None, joint: str | None = None) -> None:
        """Set the succession offset ``s`` (seconds), exponent ``l`` and/or the depth joint."""
        if s is not None:
            self.s = float(s)
        if l is not None:
            self.l = float(l)
        if joint is not None:
            self.motion.skeleton.index(joint)
            self.joint = joint
        self._update()

    def set_random(self, tau: float | None = None, seed: int | None = None) -> None:
        """Set the random timing bound ``tau`` (seconds) and/or the seed."""
        if tau is not None:
            self.tau = float(tau)
        if seed is not None:
            self.seed = int(seed)
        self._update()

    def set_exaggeration(self, w_r: float, joints: Sequence[str] | None = None) -> None:
        """Relative exaggeration of every pose against the average pose."""
        self.w_r = float(w_r)
        if joints is not None:
            self.exaggerate_joints = tuple(joints)
        self._update()

    def set_staggered(self, on: bool) -> None:
        """Staggered (True) or non-staggered (refinements zeroed) playback."""
        self.staggered = bool(on)
        self._update()

    def select(self, k: int) -> None:
        """Select pose ``k`` (for the 3D overlay)."""
        self.selected = self.current._pose_index(int(k))

    def set_curve_joint(self, name: str) -> None:
        self.current.variable_index(name)
        self.curve_joint = name

    def _update(self) -> None:
        import warnings

        from .representation import StaggeredTimingWarning

        sm = self.base
        self.message = ""
        try:
            with warnings.catch_warnings(record=True) as caught:
                warnings.simplefilter("always", StaggeredTimingWarning)
                if self.w_r != 0.0:
                    sm = sm.exaggerate(self.w_r, joints=self.exaggerate_joints)
                if self.s != 0.0:
                    sm = sm.succession(self.s, self.l, joint=self.joint)
                if self.tau > 0.0:
                    sm = sm.randomize(self.tau, joints=self.random_joints, seed=self.seed)
            if caught:
                self.message = str(caught[-1].message)
        except ValueError as exc:
            self.message = f"edit rejected: {exc}"
            return
        self.current = sm

    # ------------------------------------------------------------- outputs
    @property
    def playback(self) -> StaggeredMotion:
        """The representation played: current, or with refinements zeroed."""
        return self.current if self.staggered else self.current.zero_refinements()

    def evaluate(self) -> Motion:
        """The dense motion being played."""
        return self.current.evaluate(staggered=self.staggered)

    def curves(self, name: str | None = None) -> dict[str, Array]:
        """Curves of one variable for plotting.

        Returns a dict with ``"t"`` (F,), ``"values"`` (F, 3) (root position
        in metres, or the rotation vector ``log(q)`` in radians), ``"pose_times"``
        (K,), ``"knot_times"`` (K,) and ``"knot_values"`` (K, 3) of the
        refined knots as played, and ``"original"`` (F0, 3) with ``"t0"`` of
        the source clip.
        """
        name = name or self.curve_joint
        sm = self.playback
        i = sm.variable_index(name)
        motion = self.evaluate()

        def series(m: Motion) -> Array:
            if i == 0:
                return np.asarray(m.root_positions)
            return quat.log(quat.unroll(m.rotations[:, i - 1], axis=0))

        act = sm.active[:, i]
        knots = (sm.times + sm.refinements[:, i])[act]
        vals = series(motion)
        return {
            "t": motion.times,
            "values": vals,
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
