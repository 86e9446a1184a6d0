"""Inverse kinematics: analytic two-bone limbs and damped least squares.

Two solvers, both vectorised over frames, both pure (they return new local
rotation arrays and never touch their inputs):

:func:`two_bone_ik`
    Closed-form IK for a three-joint limb ``upper -> middle -> end``
    (hip-knee-ankle, shoulder-elbow-wrist).  In three steps, each a rotation
    applied in world coordinates:

    1. bend the middle joint about the limb's current bending axis until the
       distance from the upper joint to the end joint equals the distance to
       the (reach-clamped) target (law of cosines);
    2. swing the upper joint by the shortest arc that points the limb at the
       target;
    3. twist the whole limb about the upper-joint -> target axis to set its
       swivel.  By default the limb keeps its swivel plane: the new bending
       plane (upper, middle, end) is the one containing the new axis whose
       normal is closest to the old plane's normal, so the knee or elbow
       stays on its side however close to the axis it is.  With a *pole*
       point the middle joint goes in the half plane through the axis and
       the pole instead.  Where that plane is undefined (a straight limb, a
       pole on the axis) the twist fades out smoothly and the shortest-arc
       swing alone sets the swivel.

    Unreachable targets are clamped to the limb's reach: the limb straightens
    and points at the target, with no NaN (angles come from ``arctan2`` and
    clipped cosines).  Optionally the end joint's *global* orientation is
    set (for a foot: keep it as it was before the leg moved).

:func:`dls_ik`
    Damped least squares (Levenberg-Marquardt style) for any set of chain
    joints (each a free 3-DOF rotation) and one or more end effectors,
    for example ``LowerBack .. RightForeArm`` to put the right hand on a
    target.  Each iteration solves, on every frame at once,
    ``dtheta = W J^T (J W J^T + lambda^2 I)^-1 e`` where ``J`` is the
    positional Jacobian with respect to world-axis rotations at each chain
    joint, ``W`` optional per-joint weights and ``e`` the position error.

Both take local rotations ``(F, J, 4)``, the root positions and the
:class:`~mocaplab.motion.Skeleton`; :func:`reach` is the Motion-level
convenience.  Conventions are those of :mod:`mocaplab.motion` (metres,
quaternions ``(x, y, z, w)``).

Examples
--------
>>> import numpy as np
>>> import mocaplab as ml
>>> walk = ml.cmu("16_15")
>>> ankle = walk.global_positions()[:, walk.skeleton.index("LeftFoot")]
>>> lifted = reach(walk, "LeftFoot", ankle + [0, 0.1, 0])
>>> bool(np.allclose(lifted.global_positions()[:, walk.skeleton.index("LeftFoot")], ankle + [0, 0.1, 0]))
True

Longer than 800 lines because analytic two-bone IK, its hinge, swivel and straight-limb rules, and damped least squares share the limb helpers and fades defined here.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from . import kinematics, quat
from ._warnings import warn
from .displacement import blend_ramp
from .motion import Motion, Skeleton

__all__ = [
    "UnreachableTargetWarning",
    "unreachable_message",
    "limb_joints",
    "two_bone_deltas",
    "two_bone_ik",
    "end_parent_rotations",
    "hinge_axes",
    "reach_residual",
    "aim_deltas",
    "dls_ik",
    "reach",
    "two_bone_locals",
]

Array = NDArray[np.float64]
JointRef = str | int

_TINY = 1e-9
# The swivel twist fades out smoothly where the plane it aligns is undefined:
# with the default pole, when the sine of the angle between the upper bone and
# the limb axis is below 0.02 (a limb within about 2 degrees of straight); with
# an explicit pole point, when the middle joint or the pole is within 0.15
# upper-bone lengths of the axis (no twist below 0.05).
_PLANE_FADE = (0.005, 0.02)
_POLE_FADE = (0.05, 0.15)
# Below this sine of its bend (about 0.06 to 0.23 degrees) a limb counts as
# straight, blended: its bend axis is rounding noise there.
_STRAIGHT_FADE = (1e-3, 4e-3)
# A limb counts as bent on its hinge's side by the cosine between its bend
# axis and the hinge, blended over this range (about 73 to 107 degrees).
_SIDE_FADE = (-0.3, 0.3)
# Below this sine of its bend (about 3 to 11.5 degrees) a limb with a hinge bends about the hinge, blended.
_HINGE_FADE = (0.05, 0.2)


def _ramp(x: Array, edges: tuple[float, float]) -> Array:
    """From 0 (x <= edges[0]) to 1 (x >= edges[1]) by :func:`~mocaplab.displacement.blend_ramp`."""
    return blend_ramp((x - edges[0]) / (edges[1] - edges[0]))


class UnreachableTargetWarning(UserWarning):
    """An IK target lay beyond its limb's reach on some frames: the limb went straight and missed it.

    Parameters
    ----------
    *args
        The message, as for any warning.

    Examples
    --------
    >>> from mocaplab.ik import UnreachableTargetWarning
    >>> issubclass(UnreachableTargetWarning, UserWarning)
    True
    """


def _frame_runs(frames: ArrayLike) -> str:
    """Frame indices as runs, ``"3-7, 12, 20-24"``."""
    f = np.unique(np.asarray(frames, dtype=np.int64))
    if f.size == 0:
        return "none"
    cut = np.flatnonzero(np.diff(f) > 1) + 1
    return ", ".join(f"{r[0]}" if r[0] == r[-1] else f"{r[0]}-{r[-1]}" for r in np.split(f, cut))


#: Targets missed by less than this (metres) are not reported.
UNREACHABLE_TOLERANCE = 1e-3


def unreachable_message(joint: str, residual: ArrayLike, *, tolerance: float = UNREACHABLE_TOLERANCE) -> str | None:
    """One line naming a joint, the frames where its target is out of reach and the largest miss, or None.

    ``residual`` (F,) is how far the target lies beyond reach on each frame
    (metres, :func:`reach_residual`); frames within ``tolerance`` count as
    reached.
    """
    r = np.asarray(residual, dtype=float)
    bad = np.flatnonzero(r > tolerance)
    if bad.size == 0:
        return None
    worst = int(bad[np.argmax(r[bad])])
    return (
        f"target of {joint!r} out of reach on frames {_frame_runs(bad)} ({bad.size} frames): "
        f"missed by up to {1000.0 * r[worst]:.0f} mm (frame {worst}); the limb is straightened toward it"
    )


# --------------------------------------------------------------------- helpers
def _unit(v: Array, *, eps: float = _TINY) -> tuple[Array, Array]:
    n = _norm(v)
    return v / np.maximum(n, eps)[..., None], n


# Small vector helpers over the last axis: the arrays of the IK kernels are
# small (a few legs on a few hundred frames), so numpy's per-call overhead
# dominates and these lean forms (no axis bookkeeping) are noticeably faster
# than np.cross / np.linalg.norm / np.sum(..., axis=-1).
def _dot(a: Array, b: Array) -> Array:
    return np.einsum("...i,...i->...", a, b)


def _norm(v: Array) -> Array:
    return np.sqrt(np.einsum("...i,...i->...", v, v))


def _axis_angle(axis: Array, angle: Array) -> Array:
    """Quaternions turning by ``angle`` (...,) about unit ``axis`` (..., 3)."""
    half = 0.5 * np.asarray(angle, dtype=float)
    out = np.empty(np.broadcast_shapes(axis.shape[:-1], half.shape) + (4,))
    out[..., :3] = axis * np.sin(half)[..., None]
    out[..., 3] = np.cos(half)
    return out


def _between_units(u: Array, v: Array) -> Array:
    """Shortest-arc quaternions turning unit vectors ``u`` onto unit vectors ``v``.

    :func:`mocaplab.quat.between` without normalising its (already unit)
    inputs; opposite vectors turn about an axis perpendicular to ``u``, the
    same axis as :func:`~mocaplab.quat.between` picks.
    """
    d = _dot(u, v)
    q = np.empty(np.broadcast_shapes(u.shape, v.shape)[:-1] + (4,))
    q[..., :3] = _cross(u, v)
    q[..., 3] = 1.0 + d
    opposite = (1.0 + d) < 1e-9
    if np.any(opposite):
        alt = _cross(u, np.array([1.0, 0.0, 0.0]))
        weak = _norm(alt) < 1e-6
        alt = np.where(weak[..., None], _cross(u, np.array([0.0, 0.0, 1.0])), alt)
        q[opposite] = np.concatenate([alt, np.zeros(alt.shape[:-1] + (1,))], axis=-1)[opposite]
    return q / _norm(q)[..., None]


def _cross(a: Array, b: Array) -> Array:
    ax, ay, az = a[..., 0], a[..., 1], a[..., 2]
    bx, by, bz = b[..., 0], b[..., 1], b[..., 2]
    out = np.empty(np.broadcast_shapes(a.shape, b.shape))
    out[..., 0] = ay * bz - az * by
    out[..., 1] = az * bx - ax * bz
    out[..., 2] = ax * by - ay * bx
    return out


def _per_frame(value: ArrayLike, n_frames: int, width: int, name: str) -> Array:
    """Broadcast ``(width,)`` or ``(F, width)`` to ``(F, width)`` with a clear error."""
    a = np.asarray(value, dtype=float)
    if a.shape == (width,):
        return np.broadcast_to(a, (n_frames, width))
    if a.shape == (n_frames, width):
        return a
    raise ValueError(f"Expected `{name}` of shape ({width},) or ({n_frames}, {width}), got {a.shape}")


def _check_rotations(rotations: ArrayLike, root_positions: ArrayLike, skeleton: Skeleton) -> tuple[Array, Array]:
    if not isinstance(skeleton, Skeleton):
        raise TypeError(f"Expected `skeleton` to be a Skeleton, got {type(skeleton).__name__}")
    rot = np.asarray(rotations, dtype=float)
    if rot.ndim != 3 or rot.shape[1:] != (skeleton.n_joints, 4):
        raise ValueError(f"Expected `rotations` of shape (F, {skeleton.n_joints}, 4), got {rot.shape}")
    root = np.asarray(root_positions, dtype=float)
    if root.shape != (rot.shape[0], 3):
        raise ValueError(f"Expected `root_positions` of shape ({rot.shape[0]}, 3), got {root.shape}")
    return rot, root


def limb_joints(skeleton: Skeleton, end: JointRef) -> tuple[int, int, int]:
    """The ``(upper, middle, end)`` joints of the limb ending at ``end``.

    When ``end`` is an ankle or a wrist of the skeleton's joint roles
    (:attr:`~mocaplab.motion.Skeleton.roles`), the limb is that side's
    hip, knee and ankle (shoulder, elbow and wrist), so helper joints in
    between (twist bones, zero-length offsets) are carried rigidly.
    Otherwise the middle joint is ``end``'s parent and the upper joint its
    grandparent: ``limb_joints(sk, "LeftFoot")`` gives LeftUpLeg, LeftLeg,
    LeftFoot on the CMU skeleton, ``"RightHand"`` gives RightArm,
    RightForeArm, RightHand.
    """
    e = skeleton.index(end, arg="end")
    roles = _roles_or_none(skeleton)
    if roles is not None:
        name = skeleton.names[e]
        for side in ("left", "right"):
            for parts in (("hip", "knee", "ankle"), ("shoulder", "elbow", "wrist")):
                keys = [f"{side}_{p}" for p in parts]
                if roles.get(keys[2]) == name and all(k in roles for k in keys):
                    u, m, _ = roles.indices(*keys)
                    return u, m, e
    m = int(skeleton.parents[e])
    u = int(skeleton.parents[m]) if m >= 0 else -1
    if m < 0 or u < 0:
        raise ValueError(f"Joint {skeleton.names[e]!r} needs a parent and a grandparent to be a limb end")
    return u, m, e


def _roles_or_none(skeleton: Skeleton) -> Any:
    from .roles import RolesError

    try:
        return skeleton.roles
    except RolesError:
        return None


# ------------------------------------------------------------ two-bone kernel
def two_bone_deltas(
    upper: ArrayLike,
    middle: ArrayLike,
    end: ArrayLike,
    target: ArrayLike,
    *,
    pole: ArrayLike | None = None,
    bend_axis: ArrayLike | None = None,
    hinge: ArrayLike | None = None,
    weight: ArrayLike | None = None,
) -> tuple[Array, Array]:
    """World-frame rotations that carry a two-bone limb's end to ``target``.

    Pure geometry on joint positions; every argument broadcasts over leading
    axes (one pose or all frames).

    Parameters
    ----------
    upper, middle, end : array_like, shape (..., 3)
        World positions of the three joints (hip, knee, ankle).
    target : array_like, shape (..., 3)
        Where the end joint should go.  Beyond the limb's reach (or closer
        than ``|l1 - l2|``) it is clamped: the limb points at it as far as
        it can.
    pole : array_like, shape (..., 3), optional
        A point fixing the swivel plane: the middle joint ends in the half
        plane through the upper-joint -> target axis and this point.
        Default: keep the current bending plane (its normal projected
        perpendicular to the new axis).
    bend_axis : array_like, shape (..., 3), optional
        World axis about which to bend the middle joint when the limb is
        exactly straight (the bending plane is then undefined).  Default: an
        axis perpendicular to the limb, chosen from the world axes.
    hinge : array_like, shape (..., 3), optional
        World direction of the middle joint's hinge (a knee's flexion axis,
        oriented so that a normal bend is a positive turn of the lower bone
        about it, from ``upper - middle`` toward ``end - middle``).  With it
        the limb never flips its bending direction: where the current pose
        bends the other way (a knee hyperextended by a fraction of a degree),
        the bend goes back through straight to the hinge's side instead of
        bending further backwards; a straight limb bends about it.
        :func:`hinge_axes` estimates it from a clip.  The solution is
        continuous through straight: within about 0.2 degrees of straight
        (where the current bend axis is rounding noise) the bend blends into
        one about the hinge; and a limb within about 3 degrees of straight
        (blended out by 11.5, and by ``weight``) bends in the hinge's plane,
        since a captured near-straight knee's own bend axis is noise.  The
        flexion a target adds to the limb's own leans onto the hinge's plane
        by its share of the new flexion (a knee bent 10 degrees about its own
        axis and asked for 40 bends three quarters of the way toward the
        hinge's plane), so the bending direction moves continuously as a
        straightening captured knee approaches that 3-to-11.5-degree band.
    weight : array_like, shape (...,), optional
        How firmly the goal holds, in [0, 1] (default 1), used with
        ``hinge``: a limb bent against its hinge is carried to the hinge's
        side only by this fraction (a weight-0 goal whose target is the
        current end position changes nothing; with weight 1 the end reaches
        the target on the hinge's side), so the correction fades in and out
        with a goal's blend weights instead of jumping.

    Returns
    -------
    upper_delta : ndarray, shape (..., 4)
        Rotation to pre-multiply onto the upper joint's global rotation.
    middle_delta : ndarray, shape (..., 4)
        Rotation about the middle joint to apply *before* ``upper_delta``:
        the middle joint's new global rotation is
        ``upper_delta * middle_delta * G_middle``.

    Notes
    -----
    Lengths come from the given positions, so the kernel works for any
    skeleton.  The bend changes the interior angle ``beta`` at the middle
    joint to ``arccos((l1^2 + l2^2 - d^2) / (2 l1 l2))`` about the axis
    ``(upper - middle) x (end - middle)``; angles use ``arctan2`` and clipped
    cosines so full extension is safe.
    """
    a = np.asarray(upper, dtype=float)
    b = np.asarray(middle, dtype=float)
    c = np.asarray(end, dtype=float)
    t = np.asarray(target, dtype=float)
    shape = np.broadcast_shapes(a.shape, b.shape, c.shape, t.shape)
    a, b, c, t = (np.broadcast_to(x, shape) for x in (a, b, c, t))
    p = None if pole is None else np.broadcast_to(np.asarray(pole, dtype=float), shape)

    u = a - b
    v = c - b
    l1 = _norm(u)
    l2 = _norm(v)
    reach_min = np.abs(l1 - l2)
    reach_max = l1 + l2
    d = np.clip(_norm(t - a), reach_min, reach_max)

    # step 1: bend the middle joint
    cross = _cross(u, v)
    sin_b = _norm(cross)
    beta = np.arctan2(sin_b, _dot(u, v))
    cos_new = (l1**2 + l2**2 - d**2) / np.maximum(2.0 * l1 * l2, _TINY)
    beta_new = np.arccos(np.clip(cos_new, -1.0, 1.0))
    sin_rel = sin_b / np.maximum(l1 * l2, _TINY)
    straight = sin_rel <= 1e-9
    axis = cross / np.where(straight, 1.0, sin_b)[..., None]  # unit where not straight
    # the new interior angle, as a flexion about the current bend axis
    # (flexion = pi - interior angle; negative: bent through straight to the
    # other side of that axis)
    flex = np.pi - beta
    flex_new = c_new = np.pi - beta_new
    if hinge is not None:
        h = np.broadcast_to(np.asarray(hinge, dtype=float), shape)
        if bend_axis is None:
            bend_axis = h
        hn, _ = _unit(h)
        # on the hinge's side (side = 1) the limb takes the flexion the
        # distance asks for; bent against it (side = 0) the flexion changes
        # by what the distance asks and, by the goal's weight, goes on to the
        # hinge's side of straight (about the current axis:
        # -(flex_new - 2 (1 - w) flex)), so a weight-0 goal on the current
        # end position changes nothing and the correction grows with the weight
        w = np.ones(shape[:-1]) if weight is None else np.broadcast_to(np.asarray(weight, dtype=float), shape[:-1])
        w = np.clip(w, 0.0, 1.0)
        # which side the current bend is on, blended where its axis is nearly
        # perpendicular to the hinge (a bend mostly sideways: a straight-ish
        # leg's abduction), so a bend axis swinging across the hinge's plane
        # straightens the limb and bends it back over a few frames instead of
        # flipping the middle joint to the other side in one
        side = np.where(straight, 1.0, _ramp(_dot(axis, hn), _SIDE_FADE))
        against = 2.0 * (1.0 - w) * flex - flex_new
    # the bend as a rotation vector about the current axis; within a fraction
    # of a degree of straight (where that axis is rounding noise) it blends
    # into a bend about the fallback axis (the hinge) from straight, which it
    # matches there, so the solution is continuous through straight
    near = _ramp(sin_rel, _STRAIGHT_FADE)
    fallback = None
    if np.any(near < 1.0):
        if bend_axis is not None:
            fallback = np.broadcast_to(np.asarray(bend_axis, dtype=float), shape)
            fallback = fallback - _dot(fallback, u)[..., None] * u / np.maximum(l1**2, _TINY)[..., None]
        else:
            # the world axis least aligned with the limb, made perpendicular to it
            pick = np.argmin(np.abs(u), axis=-1)
            fallback = _cross(u, np.eye(3)[pick])
        fallback, _ = _unit(fallback)

    def bend(flex_to: Array) -> Array:
        rotvec = axis * (flex - flex_to)[..., None]
        if fallback is not None:
            rotvec = near[..., None] * rotvec - ((1.0 - near) * c_new)[..., None] * fallback
        angle = _norm(rotvec)
        return _axis_angle(rotvec / np.maximum(angle, _TINY)[..., None], angle)

    middle_delta = bend(flex_new)
    if hinge is not None and np.any(side < 1.0):
        middle_delta = np.where((side <= 0.0)[..., None], bend(against), middle_delta)
        mixed = (side > 0.0) & (side < 1.0)
        if np.any(mixed):
            middle_delta[mixed] = _swivel_between(
                middle_delta[mixed], bend(against)[mixed], u[mixed], v[mixed], hn[mixed], side[mixed]
            )
    if hinge is not None:
        # a nearly straight limb bends about its hinge: its own bend axis is noise there (a knee captured 2
        # degrees from straight can swing its axis by 100 degrees in two frames, and a goal that bends it
        # to 8 degrees would swing the knee across with it).  Blended by how straight the limb is (fully
        # below about 3 degrees of flexion, not at all above about 11.5) and by the goal's weight, the
        # bending direction swivels about the upper bone toward the hinge's plane at the same flexion: the
        # limb is straightened, then bent to the new flexion about the hinge
        # and the flexion a goal adds to a limb's own is a flexion about the hinge: the added share of the new
        # flexion swivels toward the hinge's plane too (all of it from straight, none where the goal only
        # straightens the limb), so the bend a lowered root asks of a leg whose captured knee straightens
        # through 11 degrees in two frames (perfume/A_test at 40 fps) leans onto the hinge gradually instead
        # of swinging 37 degrees across as the straightness fade above runs out
        added = np.clip((flex_new - flex) / np.maximum(flex_new, _TINY), 0.0, 1.0) * side
        loose = np.maximum(1.0 - _ramp(sin_rel, _HINGE_FADE), added) * w
        if np.any(loose > 0.0):
            lax = loose > 0.0
            onto, _ = _unit(hn - _dot(hn, u)[..., None] * u / np.maximum(l1**2, _TINY)[..., None])
            straighten = quat.normalize(_axis_angle(axis, flex))  # (axis is not unit where straight: flex is 0)
            about = quat.mul(_axis_angle(onto, -flex_new), straighten)
            swung = np.array(middle_delta, copy=True)
            swung[lax] = _swivel_between(middle_delta[lax], about[lax], u[lax], v[lax], hn[lax], 1.0 - loose[lax])
            middle_delta = swung
    c1 = b + quat.rotate(middle_delta, v)

    # step 2: swing the limb toward the target (shortest arc)
    c1a = c1 - a
    from_dir, c1a_len = _unit(c1a)
    to_dir, to_len = _unit(t - a)
    to_dir = np.where((to_len > _TINY)[..., None], to_dir, from_dir)
    swing = _between_units(from_dir, to_dir)

    # step 3: twist about the upper -> target axis
    w = to_dir
    m2 = quat.rotate(swing, b - a)
    x = m2 - _dot(m2, w)[..., None] * w
    if pole is None:
        # keep the bending plane: make its normal the old normal projected
        # perpendicular to the new axis (the closest plane containing it);
        # the knee offset of a plane with unit normal n is w x n
        normal = _cross(b - a, c1a)
        n_len = _norm(normal)
        proj = normal - _dot(normal, w)[..., None] * w
        p_len = _norm(proj)
        y = _cross(w, proj)
        # sine of the angle between the upper bone and the limb axis, and how
        # far the old normal is from the new axis
        s_bend = n_len / np.maximum(l1 * c1a_len, _TINY)
        fade = _ramp(s_bend, _PLANE_FADE) * _ramp(p_len / np.maximum(n_len, _TINY), (0.1, 0.3))
    else:
        nx = _norm(x)
        y = (p - a) - _dot(p - a, w)[..., None] * w
        ny = _norm(y)
        # the pole's half plane is ill-defined when the middle joint or the
        # pole is near the axis: fade the twist out there
        fade = _ramp(np.minimum(nx, ny) / np.maximum(l1, _TINY), _POLE_FADE)
    gamma = np.arctan2(_dot(w, _cross(x, y)), _dot(x, y))
    gamma = gamma * fade
    twist = _axis_angle(w, gamma)
    return quat.normalize(quat.mul(twist, swing)), quat.normalize(middle_delta)


def _swivel_between(q1: Array, q0: Array, u: Array, v: Array, hinge: Array, side: Array) -> Array:
    """The middle joint's bend part way (``1 - side``) from bend ``q1`` to bend ``q0``, shape (N, 4).

    Both bends turn the lower bone ``v`` about the middle joint; the blend
    keeps the lower bone's angle to the upper bone ``u`` a mix of the two
    (the same angle, so the same reach, when they mirror each other) and
    swivels its bending direction about ``u`` from the one to the other
    through the hinge's side (``hinge x u``), never through the hinge's back.
    """
    un, _ = _unit(u)
    v1 = quat.rotate(q1, v)
    v0 = quat.rotate(q0, v)
    a1, a0 = _dot(v1, un), _dot(v0, un)
    p1 = v1 - a1[:, None] * un
    p0 = v0 - a0[:, None] * un
    psi = np.arctan2(_dot(un, _cross(p1, p0)), _dot(p1, p0))
    other = psi - np.where(psi >= 0.0, 2.0 * np.pi, -2.0 * np.pi)
    good = _cross(hinge, un)
    mid = quat.rotate(_axis_angle(un, 0.5 * psi), p1)
    mid_other = quat.rotate(_axis_angle(un, 0.5 * other), p1)
    psi = np.where(_dot(mid_other, good) > _dot(mid, good), other, psi)
    s = 1.0 - side
    direction, _ = _unit(quat.rotate(_axis_angle(un, s * psi), p1))
    radial = side * _norm(p1) + s * _norm(p0)
    along = side * a1 + s * a0
    target, _ = _unit(along[:, None] * un + radial[:, None] * direction)
    lower, _ = _unit(v)
    return _between_units(lower, target)


def aim_deltas(pivot: ArrayLike, tip: ArrayLike, target: ArrayLike, *, weight: ArrayLike | None = None) -> Array:
    """Shortest-arc world rotations about ``pivot`` turning ``tip`` toward ``target``.

    Used to rotate a foot about the ankle so the toe points at its plant.
    ``weight`` in [0, 1] (broadcast over leading axes) scales the rotation
    angle (0: identity).  Returns shape (..., 4).
    """
    pivot = np.asarray(pivot, dtype=float)
    f, _ = _unit(np.asarray(tip, dtype=float) - pivot)
    g, glen = _unit(np.asarray(target, dtype=float) - pivot)
    g = np.where((glen > _TINY)[..., None], g, f)
    q = _between_units(f, g)
    if weight is not None:
        q = quat.exp(quat.log(q) * np.asarray(weight, dtype=float)[..., None])
    return q


def hinge_axes(grot: Array, gpos: Array, limbs: Sequence[tuple[int, int, int]]) -> Array:
    """Each limb's middle-joint hinge in that joint's local frame, shape (K, 3).

    The bending axis ``(upper - middle) x (end - middle)`` of every frame,
    taken into the middle joint's local frame and summed over the clip (so
    frames bent well count most: the cross product's length is the sine of
    the bend), then normalised.  A knee or elbow bends about one such axis
    throughout a clip; frames bent the other way by noise do not flip it.
    A limb straight on every frame gets a zero vector (no preference).

    Parameters
    ----------
    grot, gpos : ndarray, shapes (F, J, 4) and (F, J, 3)
        Forward kinematics of the clip.
    limbs : sequence of (upper, middle, end) joint indices
    """
    out = np.zeros((len(limbs), 3))
    for k, (u, m, e) in enumerate(limbs):
        n = _cross(gpos[:, u] - gpos[:, m], gpos[:, e] - gpos[:, m])
        local = quat.rotate(quat.inv(grot[:, m]), n).sum(axis=0)
        length = float(np.linalg.norm(local))
        if length > _TINY:
            out[k] = local / length
    return out


def reach_residual(upper: ArrayLike, middle: ArrayLike, end: ArrayLike, target: ArrayLike) -> Array:
    """How far ``target`` lies outside a two-bone limb's reach, metres, shape (...,).

    Zero where the limb can reach it; else the distance by which it is
    beyond full extension (or closer to the upper joint than ``|l1 - l2|``).
    :func:`two_bone_ik` clamps such targets; this says by how much.
    """
    a, b, c, t = (np.asarray(x, dtype=float) for x in (upper, middle, end, target))
    l1, l2 = _norm(a - b), _norm(c - b)
    d = _norm(t - a)
    return np.maximum(d - (l1 + l2), 0.0) + np.maximum(np.abs(l1 - l2) - d, 0.0)


def two_bone_ik(
    rotations: ArrayLike,
    root_positions: ArrayLike,
    skeleton: Skeleton,
    end: JointRef,
    target: ArrayLike,
    *,
    joints: tuple[JointRef, JointRef, JointRef] | None = None,
    pole: ArrayLike | None = None,
    bend_axis: ArrayLike | None = None,
    end_rotation: ArrayLike | None = None,
    translations: ArrayLike | None = None,
    fk: tuple[Array, Array] | None = None,
    keep_bend: bool = True,
    return_residual: bool = False,
    warn_unreachable: bool = True,
    weight: ArrayLike | None = None,
) -> Any:
    """Analytic limb IK on every frame: new local rotations.

    Parameters
    ----------
    rotations : array_like, shape (F, J, 4)
        Local joint rotations.
    root_positions : array_like, shape (F, 3)
    skeleton : Skeleton
    end : str or int
        The limb's end joint (ankle, wrist); the limb is
        ``limb_joints(skeleton, end)`` unless ``joints`` is given.
    target : array_like, shape (3,) or (F, 3)
        World target of the end joint (clamped to the limb's reach).
    joints : (upper, middle, end), optional
        The three joints explicitly; ``middle`` must descend from ``upper``
        and ``end`` from ``middle`` (intermediate joints are carried
        rigidly).
    pole : array_like, shape (3,) or (F, 3), optional
        Swivel pole point (see :func:`two_bone_deltas`); default: the
        current bending plane is kept.
    bend_axis : array_like, shape (3,), optional
        Bending axis *in the middle joint's local frame*, used only when the
        limb is exactly straight (for CMU knees ``(1, 0, 0)``).
    end_rotation : array_like, shape (4,) or (F, 4), optional
        Global orientation for the end joint (e.g. its orientation before the
        IK, to keep a foot flat).  Default: the end joint's local rotation is
        unchanged, so it turns with the limb.
    translations : array_like, shape (F, J, 3), optional
        Animated local translations (see :class:`~mocaplab.motion.Motion`).
    fk : (global_rotations, global_positions), optional
        Precomputed forward kinematics of ``rotations`` (saves a pass when
        several independent limbs are solved on the same pose).
    keep_bend : bool
        Keep the limb's bending direction: the hinge is estimated from
        ``rotations`` over the whole clip (:func:`hinge_axes`), or is
        ``bend_axis`` when given, so a knee near straight never bends
        backwards.  ``False``: bend about the current bending plane of each
        frame, whatever its side.
    return_residual : bool
        Also return, per frame, how far the target is out of reach
        (:func:`reach_residual`, metres; 0 where it is reached).
    warn_unreachable : bool
        Warn (:class:`UnreachableTargetWarning`, once per call) naming the
        end joint, the frames where the target is beyond reach by more than
        1 mm and the largest miss.
    weight : array_like, shape () or (F,), optional
        The goal's weight per frame in [0, 1] (default 1): how far a limb
        bent against its hinge is carried to the hinge's side (see
        :func:`two_bone_deltas`).

    Returns
    -------
    ndarray, shape (F, J, 4)
        A new array of local rotations; only the upper and middle joints
        (and the end joint when ``end_rotation`` is given) differ from
        ``rotations``.  With ``return_residual``, ``(rotations, residual)``
        with ``residual`` of shape (F,).

    Examples
    --------
    >>> import numpy as np
    >>> from mocaplab.motion import Skeleton
    >>> sk = Skeleton(["hip", "knee", "ankle"], [-1, 0, 1], [[0, 0, 0], [0, -0.5, 0], [0, -0.5, 0]])
    >>> rot = np.tile([0.0, 0.0, 0.0, 1.0], (1, 3, 1))
    >>> new = two_bone_ik(rot, np.zeros((1, 3)), sk, "ankle", [0.3, -0.6, 0.2], bend_axis=[1, 0, 0])
    >>> from mocaplab.kinematics import fk
    >>> np.round(fk(new, np.zeros((1, 3)), sk.offsets, sk.parents)[1][0, 2], 6).tolist()
    [0.3, -0.6, 0.2]
    """
    rot, root = _check_rotations(rotations, root_positions, skeleton)
    n_frames = rot.shape[0]
    if joints is None:
        ju, jm, je = limb_joints(skeleton, end)
    else:
        if len(joints) != 3:
            raise ValueError(f"Expected `joints` as (upper, middle, end), got {joints!r}")
        ju, jm, je = (skeleton.index(j, arg="joints") for j in joints)
        skeleton.chain(ju, jm)
        skeleton.chain(jm, je)
    tgt = _per_frame(target, n_frames, 3, "target")
    if fk is None:
        tr = None if translations is None else np.asarray(translations, dtype=float)
        grot, gpos = kinematics.fk(rot, root, skeleton.offsets, skeleton.parents, translations=tr)
    else:
        grot, gpos = fk
    pole_w = None if pole is None else _per_frame(pole, n_frames, 3, "pole")
    axis_w = hinge_w = None
    if bend_axis is not None:
        axis_w = quat.rotate(grot[:, jm], np.asarray(bend_axis, dtype=float))
    if keep_bend:
        local = np.asarray(bend_axis, dtype=float) if bend_axis is not None else hinge_axes(grot, gpos, [(ju, jm, je)])[0]
        if np.any(local):
            hinge_w = quat.rotate(grot[:, jm], local)
    wgt = None if weight is None else np.broadcast_to(np.asarray(weight, dtype=float), (n_frames,))
    q_up, q_mid = two_bone_deltas(
        gpos[:, ju], gpos[:, jm], gpos[:, je], tgt, pole=pole_w, bend_axis=axis_w, hinge=hinge_w, weight=wgt
    )
    want = None if end_rotation is None else _per_frame(end_rotation, n_frames, 4, "end_rotation")
    out = two_bone_locals(rot, grot, skeleton.parents, (ju, jm, je), q_up, q_mid, want)
    if not (return_residual or warn_unreachable):
        return out
    residual = reach_residual(gpos[:, ju], gpos[:, jm], gpos[:, je], tgt)
    message = unreachable_message(skeleton.names[je], residual) if warn_unreachable else None
    if message is not None:
        warn(message, UnreachableTargetWarning)
    return (out, residual) if return_residual else out


def two_bone_locals(
    rot: Array,
    grot: Array,
    parents: NDArray[np.int64],
    joints: tuple[Any, Any, Any],
    q_up: Array,
    q_mid: Array,
    end_rotation: Array | None,
) -> Array:
    """New local rotations from the world deltas of :func:`two_bone_deltas`.

    ``joints`` are the (upper, middle, end) indices of one limb (ints; the
    deltas (F, 4), ``end_rotation`` (F, 4)) or of several limbs with no
    joint in common (int arrays (K,); deltas (F, K, 4), ``end_rotation``
    (F, K, 4)): each limb's rotations only depend on its own joints and
    their parents, so all limbs (and the upper and middle joints of each)
    are done in one vectorised pass.
    """
    single = np.ndim(joints[0]) == 0
    ju, jm, je = (np.atleast_1d(np.asarray(j, dtype=np.int64)) for j in joints)
    if single:
        q_up, q_mid = q_up[:, None], q_mid[:, None]
        end_rotation = None if end_rotation is None else end_rotation[:, None]
    out = np.array(rot, copy=True)
    # upper and middle joints together: a world rotation q on joint j becomes
    # a local one by conjugating with the parent's global rotation,
    # L' = inv(G_p) q G_p L
    j2 = np.concatenate([ju, jm])
    p2 = parents[j2]
    g_p = grot[:, p2]
    if np.any(p2 < 0):  # the upper joint is the root: no parent rotation
        g_p = np.where((p2 >= 0)[None, :, None], g_p, quat.identity())
    q2 = np.concatenate([q_up, q_mid], axis=1)
    out[:, j2] = quat.normalize(quat.mul(quat.mul(quat.mul(quat.inv(g_p), q2), g_p), rot[:, j2]))
    if end_rotation is not None:
        g_pe_new = end_parent_rotations(grot, parents, je, q_up, q_mid)
        out[:, je] = quat.normalize(quat.mul(quat.inv(g_pe_new), end_rotation))
    return out


def end_parent_rotations(grot: Array, parents: ArrayLike, end: ArrayLike, q_up: Array, q_mid: Array) -> Array:
    """Global rotation of a limb end's *parent* after a two-bone solve, shape (F, 4) or (F, K, 4).

    The end's parent is the middle joint itself (``hip -> knee -> ankle``)
    or a helper joint below it (``LeftLeg -> LeftLegRoll -> LeftFoot``, a
    twist bone); either way it is carried rigidly with the lower bone, so
    its new global rotation is ``q_up q_mid G_parent(end)``.  This is the
    one place that says which frame a limb end hangs from: use it wherever
    an end joint's local rotation is rebuilt from a wanted global one,
    never the middle joint's rotation in its place.

    Parameters
    ----------
    grot : ndarray, shape (F, J, 4)
        Global rotations before the solve.
    parents : array_like of int, shape (J,)
    end : int or array_like of int, shape (K,)
        The end joint(s).
    q_up, q_mid : ndarray, shape (F, 4) or (F, K, 4)
        The world deltas of :func:`two_bone_deltas` for those limbs.
    """
    pe = np.asarray(parents, dtype=np.int64)[np.asarray(end, dtype=np.int64)]
    return quat.mul(quat.mul(q_up, q_mid), grot[:, pe])


# ---------------------------------------------------------- damped least squares
def _skew(v: Array) -> Array:
    z = np.zeros(v.shape[:-1])
    return np.stack(
        [
            np.stack([z, -v[..., 2], v[..., 1]], axis=-1),
            np.stack([v[..., 2], z, -v[..., 0]], axis=-1),
            np.stack([-v[..., 1], v[..., 0], z], axis=-1),
        ],
        axis=-2,
    )


def dls_ik(
    rotations: ArrayLike,
    root_positions: ArrayLike,
    skeleton: Skeleton,
    chain: Sequence[JointRef],
    effectors: JointRef | Sequence[JointRef],
    targets: ArrayLike,
    *,
    damping: float = 1e-2,
    iterations: int = 30,
    tolerance: float = 1e-6,
    joint_weights: ArrayLike | None = None,
    translations: ArrayLike | None = None,
    max_step: float = 0.5,
) -> Array:
    """Damped least-squares IK for general chains, all frames at once.

    Parameters
    ----------
    rotations : array_like, shape (F, J, 4)
        Local joint rotations (the starting pose).
    root_positions : array_like, shape (F, 3)
    skeleton : Skeleton
    chain : sequence of str or int
        Joints free to rotate (3 DOF each), e.g. ``["LowerBack", "Spine",
        "Spine1", "RightShoulder", "RightArm", "RightForeArm"]``.  Including
        joint 0 rotates the root about its position.
    effectors : str or int, or sequence of them (M joints)
        Joints to place; each should descend from at least one chain joint.
    targets : array_like, shape (3,), (F, 3), (M, 3) or (F, M, 3)
        World targets of the effectors.
    damping : float
        ``lambda`` in metres: larger is steadier near singular poses and
        unreachable targets, smaller converges faster.
    iterations : int
        Maximum Gauss-Newton-like steps.
    tolerance : float
        Stop when every frame's largest effector error is below this (m).
    joint_weights : array_like, shape (len(chain),), optional
        Relative mobility of each chain joint (``W``); 0 freezes a joint.
    translations : array_like, shape (F, J, 3), optional
    max_step : float
        Largest rotation per joint per iteration (radians), for robustness.

    Returns
    -------
    ndarray, shape (F, J, 4)
        New local rotations; only the chain joints differ.

    Notes
    -----
    Column ``j`` of the Jacobian for effector ``e`` is ``omega x (p_e - p_j)``
    for a world-axis rotation ``omega`` at chain joint ``j`` (zero if ``e``
    does not descend from ``j``).  The step for joint ``j`` is applied as
    ``L_j <- exp(G_parent^-1 omega_j) L_j``.  Each iteration recomputes
    forward kinematics for the whole skeleton, vectorised over frames.
    """
    rot, root = _check_rotations(rotations, root_positions, skeleton)
    n_frames = rot.shape[0]
    chain_idx = [skeleton.index(j, arg="chain") for j in chain]
    if not chain_idx:
        raise ValueError("Expected at least one joint in `chain`, got none")
    if len(set(chain_idx)) != len(chain_idx):
        raise ValueError(f"Expected distinct joints in `chain`, got {list(chain)}")
    if isinstance(effectors, (str, int, np.integer)):
        eff_idx = [skeleton.index(effectors, arg="effectors")]
    else:
        eff_idx = [skeleton.index(e, arg="effectors") for e in effectors]
    m = len(eff_idx)
    tg = np.asarray(targets, dtype=float)
    if tg.shape == (n_frames, m, 3):
        pass
    elif m == 1 and tg.shape == (n_frames, 3):
        tg = tg[:, None, :]
    elif tg.shape in ((m, 3), (3,) if m == 1 else None):
        tg = np.broadcast_to(tg.reshape(1, m, 3), (n_frames, m, 3))
    else:
        raise ValueError(f"Expected `targets` of shape (3,), ({n_frames}, 3), ({m}, 3) or ({n_frames}, {m}, 3), got {tg.shape}")
    if joint_weights is None:
        wj = np.ones(len(chain_idx))
    else:
        wj = np.asarray(joint_weights, dtype=float)
        if wj.shape != (len(chain_idx),) or np.any(wj < 0):
            raise ValueError(f"Expected `joint_weights` of {len(chain_idx)} non-negative numbers, got {wj.shape}")
    if damping < 0 or iterations < 0:
        raise ValueError(f"Expected damping >= 0 and iterations >= 0, got {damping}, {iterations}")
    # which effectors each chain joint moves
    depends = np.zeros((m, len(chain_idx)))
    for a, e in enumerate(eff_idx):
        for b, j in enumerate(chain_idx):
            k = e
            while k >= 0 and k != j:
                k = int(skeleton.parents[k])
            depends[a, b] = float(k == j)
    if not np.all(depends.any(axis=1)):
        bad = [skeleton.names[e] for a, e in enumerate(eff_idx) if not depends[a].any()]
        raise ValueError(f"Effectors {bad} do not descend from any joint of `chain`")
    tr = None if translations is None else np.asarray(translations, dtype=float)
    out = np.array(rot, copy=True)
    w_cols = np.repeat(wj, 3)
    active = np.arange(n_frames)
    for step in range(iterations + 1):
        grot, gpos = kinematics.fk(
            out[active], root[active], skeleton.offsets, skeleton.parents,
            translations=None if tr is None else tr[active],
        )
        pe = gpos[:, eff_idx]  # (A, M, 3)
        err = tg[active] - pe
        worst = np.linalg.norm(err, axis=-1).max(axis=1)
        keep = worst > tolerance
        if not np.any(keep) or step == iterations:
            break
        active, grot, gpos, pe, err = active[keep], grot[keep], gpos[keep], pe[keep], err[keep]
        pj = gpos[:, chain_idx]  # (A, N, 3)
        # J[a, e, :, j, :] = skew(p_j - p_e) (maps omega_j to dp_e)
        lever = pj[:, None, :, :] - pe[:, :, None, :]  # (A, M, N, 3)
        jac = _skew(lever) * depends[None, :, :, None, None]  # (A, M, N, 3, 3)
        jac = np.transpose(jac, (0, 1, 3, 2, 4)).reshape(len(active), 3 * m, 3 * len(chain_idx))
        jw = jac * w_cols
        jjt = jw @ np.swapaxes(jac, 1, 2) + (damping**2) * np.eye(3 * m)
        y = np.linalg.solve(jjt, err.reshape(len(active), 3 * m, 1))
        dtheta = (np.swapaxes(jw, 1, 2) @ y)[..., 0].reshape(len(active), len(chain_idx), 3)
        ang = np.linalg.norm(dtheta, axis=-1, keepdims=True)
        dtheta = dtheta * np.minimum(1.0, max_step / np.maximum(ang, _TINY))
        for b, j in enumerate(chain_idx):
            if wj[b] == 0.0:
                continue
            p = skeleton.parents[j]
            local_axis = dtheta[:, b] if p < 0 else quat.rotate(quat.inv(grot[:, p]), dtheta[:, b])
            out[active, j] = quat.normalize(quat.mul(quat.exp(local_axis), out[active, j]))
    return out


# --------------------------------------------------------------- Motion level
def reach(
    motion: Motion,
    joint: JointRef,
    target: ArrayLike,
    *,
    chain: Sequence[JointRef] | None = None,
    pole: ArrayLike | None = None,
    keep_orientation: bool = True,
    **dls_options: Any,
) -> Motion:
    """Motion-level IK: a new Motion whose ``joint`` reaches ``target``.

    Parameters
    ----------
    motion : Motion
    joint : str or int
        The end effector (a foot, a hand).
    target : array_like, shape (3,) or (F, 3)
        World target on every frame.
    chain : sequence of joints, optional
        Use :func:`dls_ik` on these joints instead of the analytic two-bone
        limb ``limb_joints(skeleton, joint)``.
    pole : array_like, optional
        Swivel pole for the two-bone solver.
    keep_orientation : bool
        Two-bone solver only: keep the end joint's global orientation.
    **dls_options
        Passed to :func:`dls_ik` (``damping``, ``iterations``, ...).
    """
    if not isinstance(motion, Motion):
        raise TypeError(f"Expected `motion` to be a Motion, got {type(motion).__name__}")
    sk = motion.skeleton
    if chain is not None:
        new = dls_ik(
            motion.rotations, motion.root_positions, sk, chain, joint, target,
            translations=motion.translations, **dls_options,
        )
    else:
        if dls_options:
            raise TypeError(f"Options {sorted(dls_options)} apply only with `chain` (damped least squares)")
        j = sk.index(joint)
        grot = motion.global_rotations()
        new = two_bone_ik(
            motion.rotations, motion.root_positions, sk, j, target, pole=pole,
            end_rotation=grot[:, j] if keep_orientation else None,
            fk=(grot, motion.global_positions()),
        )
    return motion.replace(rotations=new)
