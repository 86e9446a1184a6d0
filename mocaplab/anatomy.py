"""Body geometry estimated from a skeleton: the reference pose, the body frame, end points and foot points.

A captured skeleton gives joint positions, and only sometimes the points a
body model needs beyond them: the top of the head, the far point of the
hand, the ball and tip of each foot, where a planted foot touches the
ground.  This module holds that geometry, measured once in a *reference
pose* of the skeleton and carried by the joints:

=============================  ===============================================
:func:`standing_pose`          the pose a body is measured in when the rest
                               pose does not stand (:class:`RestPoseWarning`)
:func:`foot_balls`             the ball of each foot without a toe joint, on
                               every frame (where such a foot pivots)
=============================  ===============================================

with the proportions that estimate missing points (:data:`HEAD_TOP`,
:data:`HAND`, :data:`TOE_TIP`, :data:`FOOT_TIP`, :data:`BALL`).

It is anatomy, not physics, and lives on the ground floor: it imports only
:mod:`mocaplab.motion`, :mod:`mocaplab.roles`, :mod:`mocaplab.quat` and
:mod:`mocaplab.kinematics`.  Two neighbours use it.  The point-mass body of
Shin, Kovar and Gleicher 2003, section 3.2 (:mod:`mocaplab.physics.body`),
places its link centres between these points and its support polygon
(section 3.3, the ZMP's) on the foot points; :mod:`mocaplab.contacts` labels
toe-off on feet without toe joints by :func:`foot_balls`.  The paper gives
none of this geometry: the choices below are this package's.  The body
model reaches the reference pose and the points through this module's
private helpers (``_reference``, ``_body_frame``, ``_head_top``,
``_knuckles``, ``_foot_points``, ``_support_points``).

The body's scale and facing
---------------------------
"Leg length" is the hip-to-knee plus knee-to-ankle distance in the
reference pose, averaged over both sides: the body's scale for the
estimated points.  The body faces the horizontal direction of "left hip
minus right hip" crossed with up (+Z when that vanishes).

Estimated end points
--------------------
The top of the head is the head joint's end site, else the mean of its
child joints (Daz: the eyes), else :data:`HEAD_TOP` leg lengths beyond the
head joint along the neck-to-head direction.  The far point of the hand is
the last joint of the longest chain of joints below the wrist (CMU
``LeftHandIndex1``, Daz ``lIndex2``), else the wrist's end site, else
:data:`HAND` forearm lengths beyond the wrist.  The ball of a foot is its
toe joint; the toe tip and, without a toe joint, the ball are estimated as
below.

Support-polygon points
----------------------
A planted foot touches the ground at a heel point behind the ankle and at
toe points (the ball and the toe tip).  The heel point lies ``heel``
metres behind the ankle, at the ankle's height, along the foot's
horizontal forward direction (ankle to ball; the body's facing direction
when that vanishes).  The toe tip is, in this order: the toe joint's end
site or the mean of its child joints (zero-length ones do not count), else
:data:`TOE_TIP` times the horizontal ankle-to-ball vector ahead of the
ball.  Without a toe joint the tip is the ankle's end site or child, else
:data:`FOOT_TIP` leg lengths ahead of and below the ankle, and the ball
lies :data:`BALL` of the way from the ankle to the tip.  ``foot_width``
spreads the ball and heel points sideways (plus and minus half the width
at the ball, a third at the heel).  A planted joint without foot geometry
contributes its own position.  On CMU BVH clips whose end sites have
been zeroed, the estimated tips lie within 8 mm of the captured ones
(tested).

Reference pose
--------------
Link centres and support points are measured in one pose of the skeleton
and expressed in their owners' frames: the centre ``c`` of a link owned by
joint ``o`` is stored as ``G_o^-1 (c - p_o)``, with ``G``, ``p`` the pose's
global rotations and positions.  A link of one bone does not depend on the
pose; a link across several joints does (the pelvis across the CMU
``LHipJoint`` helper, the head from the neck across ``Neck1`` and ``Head``
to the top of the head, the hand across the finger joints), and so do the
support points ("at the ankle's height", "horizontal" and "sideways" are
taken in that pose).

The pose is the **rest pose** (every local rotation the identity) when it
is a standing pose: the head well above the pelvis (the test of
:mod:`mocaplab.roles`: rising by more than 0.8 of their distance) and each
ankle below its hip by more than half the leg's length.  Files with the
rest rotations baked into the motion (bones laid along +X, as Maya/FBX
joint orients give) have a zig-zag rest pose that fails this; measured in
it, CMU 16_15 written that way gets its pelvis and head links off by 6-7 cm,
its centre of mass by 4 mm and its ZMP distance by up to 35 mm.  For those,
:meth:`~mocaplab.physics.Body.from_skeleton` given a Motion measures the body in
:func:`standing_pose` of the motion, with a :class:`RestPoseWarning`
(given a Skeleton alone it can only warn); ``pose=`` gives any pose, and
``pose="rest"`` the rest pose.  The standing pose is built in two steps:

* per joint, the (chordal) mean of the motion's local rotations, the
  pelvis' heading (the facing of the hips) taken off frame by frame first
  so that a turning clip has a mean: the feet stand as they do on the
  ground on average, and helper joints are as the motion holds them
  (exactly, for constant ones such as CMU ``LHipJoint``);
* then every joint *inside* a link's chain (``Neck1`` and ``Head`` in the
  head link, the finger joints in the hand, helpers within limbs) is
  turned, by the smallest turn, so that its bone continues the bone into
  it.  A rigid link gets the geometry of its segment held straight, as rest
  poses hold necks and fingers, not the clip's habitual bend: the captured
  CMU subjects hold the neck bent by 20-40 degrees from their rest pose,
  and the mean alone would move the head link by 2.5-5 cm and the centre
  of mass by 1.7-3.4 mm.

Both steps use only world positions and rotations up to a constant change
of each joint's frame, so two files of one clip that differ only in their
joints' rest frames get the same body, each in its own frames.  Against a
skeleton's own (standing) rest pose the standing pose differs where the
rest pose is arbitrary; on CMU 16_15 and 16_05 written with bones along +X
(``tests/test_physics_conventions.py``): centre of mass within 0.7 mm and
ZMP within 1 mm of the CMU original, the head link within 1 cm (the CMU
rest neck is not straight: its bones turn by some 18 degrees), support
points within 3 cm, because the CMU rest pose holds the legs splayed by 20
degrees and the feet rolled with them (15-25 degrees from a foot planted
flat), so that its heel and side points tilt with the foot where the
standing pose has them level.  ZMP distances agree within 1 mm on average
and 1 cm on the few frames where the ZMP lies off a heel or a toe's side.

Conventions are those of :mod:`mocaplab.motion`: metres, seconds, Y up,
ground y = 0.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from typing import Any, NamedTuple

import numpy as np
from numpy.typing import ArrayLike, NDArray

from . import quat
from ._warnings import warn
from .kinematics import fk
from .motion import Motion, Skeleton
from .roles import Roles, RolesError, _plausible, resolve_roles

__all__ = [
    "HEAD_TOP",
    "TOE_TIP",
    "FOOT_TIP",
    "BALL",
    "HAND",
    "RestPoseWarning",
    "standing_pose",
    "foot_balls",
]

Array = NDArray[np.float64]

#: Roles the default body model needs (legs first): the standing pose needs them all, the body frame the legs.
_NEEDED = tuple(f"{s}_{p}" for s in ("left", "right") for p in ("hip", "knee", "ankle")) + (
    "pelvis",
    "neck",
    "head",
) + tuple(f"{s}_{p}" for s in ("left", "right") for p in ("shoulder", "elbow", "wrist"))


# Points a skeleton may lack, estimated from its reference pose (see the module
# notes); the figures in brackets are those of the CMU BVH skeletons.
#: Top of the head above the head joint, in leg lengths (0.110-0.125).
HEAD_TOP = 0.115
#: Toe tip ahead of the ball, in horizontal ankle-to-ball distances (0.515-0.521).
TOE_TIP = 0.52
#: Toe tip of a foot without a toe joint: ahead of and below the ankle, in leg lengths (0.21-0.23, 0.03-0.05).
FOOT_TIP = (0.22, 0.04)
#: Ball of a foot without a toe joint, as the fraction of the way from the ankle to the toe tip.
BALL = 0.7
#: Far point of a hand without finger joints or end site, beyond the wrist in forearm lengths (0.64).
HAND = 0.64

_UP = np.array([0.0, 1.0, 0.0])


class _Pose(NamedTuple):
    """A reference pose in which link geometry is measured (joint 0 at the origin)."""

    joints: Array  # (J, 3) world positions
    ends: Array  # (E, 3) world positions of the end sites
    rotations: Array  # (J, 4) global rotations (identities in the rest pose)
    rest: bool  # whether this is the rest pose (local offsets need no rotation)


def _pose_points(skeleton: Skeleton, local: Array | None = None) -> _Pose:
    """Joint and end-site positions and joint rotations of a pose (local rotations (J, 4); None: the rest pose)."""
    e = skeleton.end_site_parents
    if local is None:  # sums of offsets (cheaper than forward kinematics for one pose)
        pos = np.zeros((skeleton.n_joints, 3))
        for j in range(1, skeleton.n_joints):
            pos[j] = pos[skeleton.parents[j]] + skeleton.offsets[j]
        return _Pose(pos, pos[e] + skeleton.end_site_offsets, quat.identity((skeleton.n_joints,)), True)
    grot, gpos = fk(np.asarray(local, dtype=float)[None], np.zeros((1, 3)), skeleton.offsets, skeleton.parents)
    g, pos = np.ascontiguousarray(grot[0]), np.ascontiguousarray(gpos[0])
    return _Pose(pos, pos[e] + quat.rotate(g[e], skeleton.end_site_offsets), g, False)


def _local(pose: _Pose, owner: int | NDArray[np.int64], world: Array) -> Array:
    """World vectors of a pose expressed in the frame of joint(s) ``owner``."""
    return world if pose.rest else quat.rotate(quat.inv(pose.rotations[owner]), world)


def _zero_length(skeleton: Skeleton) -> float:
    """Distances below this are zero (the tolerance of :mod:`mocaplab.roles`)."""
    lengths = np.linalg.norm(skeleton.offsets, axis=-1)
    return 1e-6 * max(float(lengths.max(initial=0.0)), 1e-12)


class RestPoseWarning(UserWarning):
    """The skeleton's rest pose is not a standing pose: the body is measured in another pose (or is off).

    Parameters
    ----------
    *args
        The message, as for any warning.

    Examples
    --------
    >>> from mocaplab.anatomy import RestPoseWarning
    >>> issubclass(RestPoseWarning, UserWarning)
    True
    """


def standing_pose(motion: Motion, *, roles: Mapping[str, Any] | None = None) -> Array:
    """A standing reference pose of a motion: local rotations, shape (J, 4).

    The pose :meth:`~mocaplab.physics.Body.from_skeleton` measures a body
    in when the skeleton's rest pose is not a standing pose (see the module notes,
    "Reference pose"):

    1. per joint, the mean of the motion's local rotations (the chordal
       mean: the principal eigenvector of ``sum q q^T``); the pelvis gets
       the mean of its global rotation with each frame's heading (the
       facing of the hips) taken off, the joints above it (a static
       reference root) the identity, so that a turning clip has a mean;
    2. every joint inside the chain of a link (the head's, the hand's,
       helpers within the pelvis and the limbs) turned by the smallest turn
       that makes its bone continue the bone into it; joints at their
       parent's place (zero-length helpers) keep the mean.

    Both steps depend only on world positions and on rotations up to a
    constant change of each joint's frame, so skeletons that differ only in
    their joints' rest frames get the same pose, each in its own frames.

    Parameters
    ----------
    motion : Motion
    roles : mapping of role names to joint names, optional
        Role overrides (:func:`mocaplab.roles.resolve_roles`).

    Returns
    -------
    ndarray, shape (J, 4)
        Unit quaternions ``(x, y, z, w)``, to pass as ``pose=``.

    Examples
    --------
    >>> import mocaplab as ml
    >>> walk = ml.cmu("16_15")
    >>> pose = ml.anatomy.standing_pose(walk)
    >>> pose.shape
    (31, 4)
    >>> round(ml.physics.Body.from_skeleton(walk, pose=pose).total_mass, 1)
    70.0
    """
    if not isinstance(motion, Motion):
        raise TypeError(f"Expected `motion` to be a Motion, got {type(motion).__name__}")
    sk = motion.skeleton
    r = resolve_roles(motion, roles)
    r.require(*_NEEDED, purpose="a standing pose of the motion (standing_pose)")
    pelvis = r.index("pelvis")
    q = np.array(motion.rotations, dtype=float, copy=True)
    gpos = motion.global_positions()
    across = gpos[:, r.index("left_hip")] - gpos[:, r.index("right_hip")]
    heading = np.arctan2(-across[:, 2], across[:, 0])  # of left x up = (-a_z, 0, a_x)
    q[:, pelvis] = quat.mul(quat.from_yaw(-heading), motion.global_rotations()[:, pelvis])
    above = int(sk.parents[pelvis])
    while above >= 0:
        q[:, above] = quat.identity()
        above = int(sk.parents[above])
    scatter = np.einsum("fji,fjk->jik", q, q)
    mean = quat.normalize(np.linalg.eigh(scatter)[1][..., -1])
    return _straightened(sk, r, mean)


def _link_chains(skeleton: Skeleton, roles: Roles, pose: _Pose) -> list[list[int | None]]:
    """The joint chains the default links span, each from the link's first joint to its far point.

    ``None`` at the end of the head's chain stands for the top of the head
    (the head joint's end site or children, see :func:`_beyond`).
    """
    def chain(a: int, b: int) -> list[int | None]:
        try:
            return list(skeleton.chain(a, b))
        except ValueError:
            return []

    pelvis, neck, head = roles.indices("pelvis", "neck", "head")
    chains = [chain(neck, head) + [None]]
    for side in ("left", "right"):
        hip, knee, ankle, shoulder, elbow, wrist = roles.indices(
            *(f"{side}_{p}" for p in ("hip", "knee", "ankle", "shoulder", "elbow", "wrist"))
        )
        chains += [chain(pelvis, hip), chain(hip, knee), chain(knee, ankle)]
        chains += [chain(shoulder, elbow), chain(elbow, wrist), chain(wrist, _far_joint(skeleton, pose, wrist)[0])]
        if f"{side}_toe" in roles:
            chains.append(chain(ankle, roles.index(f"{side}_toe")))
    return chains


def _straightened(skeleton: Skeleton, roles: Roles, local: Array) -> Array:
    """``local`` (J, 4) with every joint inside a link's chain turned so that its bone continues the bone into it.

    Joints at their parent's place (zero-length helpers such as CMU
    ``LHipJoint``) keep their rotation; so does a joint whose bone has no
    length.  The turn is the smallest one (about the axis across both
    bones), so the bone's twist is kept.
    """
    out = np.array(local, dtype=float, copy=True)
    eps = _zero_length(skeleton)
    for chain in _link_chains(skeleton, roles, _pose_points(skeleton, out)):
        for prev, j, nxt in zip(chain, chain[1:], chain[2:], strict=False):  # each joint with its neighbours
            if prev is None or j is None:
                continue
            pose = _pose_points(skeleton, out)
            far = _beyond(skeleton, pose, j) if nxt is None else pose.joints[nxt]
            if far is None:
                continue
            into, onward = pose.joints[j] - pose.joints[prev], far - pose.joints[j]
            if np.linalg.norm(into) <= eps or np.linalg.norm(onward) <= eps:
                continue
            turned = quat.mul(quat.between(onward, into), pose.rotations[j])
            out[j] = quat.normalize(quat.mul(quat.inv(pose.rotations[skeleton.parents[j]]), turned))
    return out


def _skeleton_of(source: Skeleton | Motion) -> Skeleton:
    sk = getattr(source, "skeleton", source)
    if not isinstance(sk, Skeleton):
        raise TypeError(f"Expected `skeleton` to be a Skeleton or Motion, got {type(source).__name__}")
    return sk


def _check_pose(pose: ArrayLike, skeleton: Skeleton) -> Array:
    q = np.asarray(pose, dtype=float)
    if q.shape != (skeleton.n_joints, 4) or not np.all(np.isfinite(q)):
        raise ValueError(
            f"Expected `pose` to be 'rest' or finite local rotations of shape ({skeleton.n_joints}, 4) "
            f"(e.g. motion.rotations[0]), got shape {q.shape}"
        )
    norm = np.linalg.norm(q, axis=-1, keepdims=True)
    if np.any(norm < 1e-6):
        raise ValueError("Expected `pose` to hold unit quaternions (x, y, z, w), got a zero quaternion")
    return q / norm


def _reference(source: Skeleton | Motion, roles: Mapping[str, Any] | None, pose: ArrayLike | str | None) -> _Pose:
    """The reference pose of :meth:`~mocaplab.physics.Body.from_skeleton` (see the module notes, "Reference pose")."""
    sk = _skeleton_of(source)
    if isinstance(pose, str):
        if pose != "rest":
            raise ValueError(f"Expected `pose` to be 'rest', local rotations ({sk.n_joints}, 4) or None, got {pose!r}")
        return _pose_points(sk)
    if pose is not None:
        return _pose_points(sk, _check_pose(pose, sk))
    rest = _pose_points(sk)
    try:
        r = resolve_roles(sk, roles)
    except RolesError:
        return rest  # what needs the roles says so
    why = _not_standing(r, rest)
    if why is None:
        return rest
    if not isinstance(source, Motion):
        warn(
            f"The rest pose of this skeleton is not a standing pose ({why}; bones laid along one axis, "
            "rest rotations baked into the motion?): link centres and support points measured in it are off. "
            "Give the motion (Body.from_skeleton(motion)) or a pose (pose=motion.rotations[k])",
            RestPoseWarning,
        )
        return rest
    standing = _pose_points(sk, standing_pose(source, roles=r))
    still = _not_standing(r, standing)
    warn(
        f"The rest pose of this skeleton is not a standing pose ({why}; bones laid along one axis, rest "
        "rotations baked into the motion?): link centres and support points are measured in a standing pose "
        "of the motion instead (mocaplab.physics.standing_pose: its mean pose, the chains inside links "
        "straight)" + ("" if still is None else f", which does not stand either ({still}): the body may be off")
        + ". Pass pose= to choose (pose='rest' keeps the rest pose)",
        RestPoseWarning,
    )
    return standing


def _not_standing(roles: Roles, pose: _Pose) -> str | None:
    """Why a pose is not a standing pose (None when it is): the head well above the pelvis, the feet well below the hips.

    The head test is that of :mod:`mocaplab.roles` (rise above the pelvis
    more than 0.8 of their distance); each ankle must lie below its hip by
    more than half of the leg's length (hip to knee to ankle).
    """
    j = pose.joints
    if "pelvis" not in roles or not ("head" in roles or "neck" in roles):
        return None  # nothing to judge by (the body model needs these roles and says so)
    pelvis = roles.index("pelvis")
    top = roles.index("head") if "head" in roles else roles.index("neck")
    if not _plausible(j[None], {"pelvis": pelvis, "head": top}):
        rise, span = j[top, 1] - j[pelvis, 1], float(np.linalg.norm(j[top] - j[pelvis]))
        return f"the head is {rise:.2f} m above the pelvis, {span:.2f} m from it"
    for side in ("left", "right"):
        if not all(f"{side}_{p}" in roles for p in ("hip", "knee", "ankle")):
            continue
        hip, knee, ankle = roles.indices(f"{side}_hip", f"{side}_knee", f"{side}_ankle")
        leg = float(np.linalg.norm(j[knee] - j[hip]) + np.linalg.norm(j[ankle] - j[knee]))
        drop = float(j[hip, 1] - j[ankle, 1])
        if not drop > 0.5 * leg:
            return f"the {side} ankle is {drop:.2f} m below its hip, whose leg is {leg:.2f} m long"
    return None


def _point(skeleton: Skeleton, pose: _Pose, spec: str) -> Array:
    joints, ends = pose.joints, pose.ends
    if spec.endswith(":end"):
        j = skeleton.index(spec[:-4])
        hits = np.flatnonzero(skeleton.end_site_parents == j)
        if hits.size == 0:
            raise ValueError(f"Joint {spec[:-4]!r} has no end site (point {spec!r})")
        return ends[hits[0]]
    return joints[skeleton.index(spec)]


def _beyond(skeleton: Skeleton, pose: _Pose, j: int) -> Array | None:
    """Where joint ``j``'s own bone ends: the mean of its end sites, else of its child joints.

    Only points away from the joint count (zero-length end sites and helper
    joints do not); None when there is none.
    """
    joints, ends = pose.joints, pose.ends
    eps = _zero_length(skeleton)
    for cands in (ends[skeleton.end_site_parents == j], joints[skeleton.children(j)]):
        cands = cands[np.linalg.norm(cands - joints[j], axis=-1) > eps]
        if len(cands):
            return np.asarray(cands.mean(axis=0))
    return None


def _unit(v: Array) -> Array | None:
    n = float(np.linalg.norm(v))
    return v / n if n > 1e-12 else None


class _Frame(NamedTuple):
    """Scale and directions of a skeleton's reference pose."""

    leg: float  # mean leg length, hip to knee plus knee to ankle
    forward: Array  # horizontal unit vector the body faces (left x up)


def _body_frame(roles: Roles, joints: Array) -> _Frame:
    def at(role: str) -> Array:
        return joints[roles.index(role)]

    leg = float(
        np.mean([
            np.linalg.norm(at(f"{s}_knee") - at(f"{s}_hip")) + np.linalg.norm(at(f"{s}_ankle") - at(f"{s}_knee"))
            for s in ("left", "right")
        ])
    )
    if not leg > 0:
        raise ValueError(f"Expected legs of positive length in the reference pose, got {leg!r}")
    forward = np.cross(at("left_hip") - at("right_hip"), _UP)
    forward[1] = 0.0
    unit = _unit(forward)
    return _Frame(leg, np.array([0.0, 0.0, 1.0]) if unit is None else unit)


def _far_joint(skeleton: Skeleton, pose: _Pose, wrist: int) -> tuple[int, float]:
    """The last joint of the longest chain of joints below the wrist, and that chain's length."""
    joints = pose.joints
    reach = {wrist: 0.0}
    for k in range(wrist + 1, skeleton.n_joints):  # parents come first
        p = int(skeleton.parents[k])
        if p in reach:
            reach[k] = reach[p] + float(np.linalg.norm(joints[k] - joints[p]))
    far = max(reach, key=lambda k: reach[k])
    return far, reach[far]


def _knuckles(skeleton: Skeleton, pose: _Pose, wrist: int, elbow: int) -> Array:
    """Far point of the hand: the last joint of the longest chain of joints below the wrist.

    Else the wrist's end site, else :data:`HAND` forearm lengths beyond the wrist.
    """
    joints = pose.joints
    far, reach = _far_joint(skeleton, pose, wrist)
    if reach > _zero_length(skeleton):
        return np.asarray(joints[far])
    tip = _beyond(skeleton, pose, wrist)
    return tip if tip is not None else joints[wrist] + HAND * (joints[wrist] - joints[elbow])


def _head_top(skeleton: Skeleton, roles: Roles, pose: _Pose, frame: _Frame) -> Array:
    """The top of the head: the head joint's end site or children, else :data:`HEAD_TOP` leg lengths beyond it."""
    joints = pose.joints
    neck, head = roles.index("neck"), roles.index("head")
    top = _beyond(skeleton, pose, head)
    if top is None:
        up = _unit(joints[head] - joints[neck])
        if up is None:
            up = _unit(joints[neck] - joints[roles.index("pelvis")])
        top = joints[head] + HEAD_TOP * frame.leg * (_UP if up is None else up)
    return top


def _foot_points(
    skeleton: Skeleton,
    pose: _Pose,
    ankle: int,
    toe: int | None,
    tip: Array | None,
    frame: _Frame | Callable[[], _Frame],
) -> tuple[Array, Array, Array]:
    """Ankle, ball and toe tip of one foot in the reference pose (see the module notes).

    ``tip`` overrides the toe tip; ``frame`` (or a function giving it) is
    needed only when a point must be estimated.
    """
    joints = pose.joints
    pa = joints[ankle]
    if toe is not None:
        ball = joints[toe]
        if tip is None:
            tip = _beyond(skeleton, pose, toe)
        if tip is None:
            tip = ball + TOE_TIP * (ball - pa) * [1.0, 0.0, 1.0]
        return pa, ball, tip
    if tip is None:
        tip = _beyond(skeleton, pose, ankle)
        if tip is not None:
            # an end site at the ball (where a toe joint was dropped) would cut the
            # foot short: the tip reaches at least the estimated toe tip's distance ahead
            f = frame() if callable(frame) else frame
            ahead = (tip - pa) * [1.0, 0.0, 1.0]
            reach = float(np.linalg.norm(ahead))
            if reach < FOOT_TIP[0] * f.leg:
                unit = ahead / reach if reach > 0 else f.forward
                tip = tip + (FOOT_TIP[0] * f.leg - reach) * unit
    if tip is None:
        f = frame() if callable(frame) else frame
        tip = pa + f.leg * (FOOT_TIP[0] * f.forward - FOOT_TIP[1] * _UP)
    return pa, pa + BALL * (tip - pa), tip


class _SupportPoints(NamedTuple):
    """Support-polygon points of the feet, each carried by a joint (the fields of the same name of a Body)."""

    point_joints: tuple[str, ...]  # (P,) contact joint each point belongs to
    point_owners: NDArray[np.int64]  # (P,) joint index that carries it
    point_offsets: Array  # (P, 3) in the owner's frame
    point_heights: Array  # (P,) above the foot's lowest point in the reference pose (toe-less feet), else NaN


def _support_points(
    skeleton: Skeleton,
    pose: _Pose,
    feet: Sequence[tuple[str, str | None] | tuple[str, str | None, str | None]],
    roles: Mapping[str, Any] | None,
    foot_width: float,
    heel: float,
) -> _SupportPoints:
    """Heel, ball and toe-tip points of each foot (ankle, toe joint or None[, toe-tip point]), see the module notes."""

    def frame() -> _Frame:
        r = resolve_roles(skeleton, roles)
        r.require(*_NEEDED[:6], purpose="estimating the toe tips of feet without toe joints or end sites")
        return _body_frame(r, pose.joints)

    pj: list[str] = []
    po: list[int] = []
    pof: list[Array] = []
    heights: list[float] = []
    for foot in feet:
        ankle, toe = foot[0], foot[1]
        tip_spec = foot[2] if len(foot) > 2 else None
        ja = skeleton.index(ankle)
        jt = None if toe is None else skeleton.index(toe)
        given = None if tip_spec is None else _point(skeleton, pose, tip_spec)
        pa, ball, ptip = _foot_points(skeleton, pose, ja, jt, given, frame)
        fwd = (ball - pa) * [1.0, 0.0, 1.0]
        unit = _unit(fwd)
        fwd = unit if unit is not None else frame().forward
        side = np.cross(_UP, fwd)
        heel_pt = pa - heel * fwd
        hw = foot_width / 3.0
        for s in (-hw, hw) if hw > 0 else (0.0,):
            pj.append(ankle)
            po.append(ja)
            pof.append(heel_pt + s * side - pa)
        owner = ja if jt is None else jt
        base = pose.joints[owner]
        bw = foot_width / 2.0
        for s in (-bw, bw) if bw > 0 else (0.0,):
            pj.append(skeleton.names[owner])
            po.append(owner)
            pof.append(ball + s * side - base)
        pj.append(skeleton.names[owner])
        po.append(owner)
        pof.append(ptip - base)
        # a foot without a toe joint rolls over its heel and toe points, all the ankle's
        ys = np.array([base[1] + o[1] for o in pof[len(heights):]])
        heights.extend(ys - ys.min() if jt is None else np.full(len(ys), np.nan))
    point_owners = np.array(po, dtype=np.int64)
    return _SupportPoints(
        tuple(pj), point_owners, _local(pose, point_owners, np.array(pof).reshape(-1, 3)), np.array(heights)
    )


def foot_balls(motion: Motion, *, roles: Mapping[str, Any] | None = None) -> dict[str, Array]:
    """World positions of the ball of each foot that has no toe joint.

    The ball is where such a foot pivots at toe-off; it lies :data:`BALL` of
    the way from the ankle to the toe tip (the ankle's end site, else
    estimated from the leg's length and the body's facing, see the module
    notes), measured in the body's reference pose and carried by the ankle.

    Parameters
    ----------
    motion : Motion
    roles : mapping, optional
        Joint-role overrides (:func:`mocaplab.roles.resolve_roles`).

    Returns
    -------
    dict of str to ndarray, shape (F, 3)
        Keyed by ankle joint name; empty when every foot has a toe joint.

    Raises
    ------
    RolesError
        When a ball must be estimated and the legs' hip, knee and ankle
        roles are not all found.

    Examples
    --------
    Every foot of the CMU skeleton has a toe joint, so nothing is estimated:

    >>> import mocaplab as ml
    >>> ml.anatomy.foot_balls(ml.cmu("16_15"))
    {}

    A file of your own whose feet end at the ankle:

    >>> walk = ml.load("walk01.bvh")          # a foot without toe joints   # doctest: +SKIP
    >>> sorted(ml.anatomy.foot_balls(walk))                                # doctest: +SKIP
    ['LeftFoot', 'RightFoot']
    """
    sk = motion.skeleton
    r = resolve_roles(sk, roles)
    ankles = [ankle for ankle, toe in r.feet() if toe is None]
    if not ankles:
        return {}
    pose = _reference(motion, r, None)

    def frame() -> _Frame:
        r.require(*_NEEDED[:6], purpose="estimating the toe tips of feet without toe joints or end sites")
        return _body_frame(r, pose.joints)

    grot, gpos = motion.global_rotations(), motion.global_positions()
    out = {}
    for ankle in ankles:
        ja = sk.index(ankle)
        pa, ball, _ = _foot_points(sk, pose, ja, None, None, frame)
        offset = _local(pose, ja, ball - pa)
        out[ankle] = gpos[:, ja] + quat.rotate(grot[:, ja], offset)
    return out
