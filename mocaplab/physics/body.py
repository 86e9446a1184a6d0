"""A point-mass body model: link masses, centre of mass and momenta.

Shin, Kovar and Gleicher 2003 model each link of the skeleton as a single
point mass at the link's centre (section 3.2).  A :class:`Body` holds, for
every link, the joint it is rigidly attached to (its *owner*), the link
centre in the owner's local frame and the link mass.  Link centres on every
frame are then one vectorised expression over the clip's forward
kinematics: ``gpos[:, owner] + rotate(grot[:, owner], offset)``.

Default masses
--------------
Segment masses are the male percentages of **de Leva (1996)**, "Adjustments
to Zatsiorsky-Seluyanov's segment inertia parameters", *Journal of
Biomechanics* 29(9):1223-1230 (:data:`DE_LEVA_MALE`, percent of body mass):
head and neck 6.94, upper trunk 15.96, middle trunk 16.33, lower trunk 11.17,
upper arm 2.71, forearm 1.62, hand 0.61, thigh 14.16, shank 4.33, foot 1.37
(summing to 100 over both sides).  The paper fits the masses to reference
clips (:func:`mocaplab.physics.fit_masses`); the table is the initial guess.

Mapping onto skeletons (choices made here, the paper gives none)
---------------------------------------------------------------
:meth:`Body.from_skeleton` maps the segments onto any humanoid skeleton
through its joint roles (:mod:`mocaplab.roles`: pelvis, spine, neck, head,
hips, knees, ankles, toes, shoulders, elbows, wrists), never through joint
names.  A link is rigidly attached to one joint (its owner); its centre is
the midpoint of two points of the reference pose (normally the rest pose,
see "Reference pose" below), expressed in the owner's frame:

* **lower trunk** (link ``pelvis``): owned by the pelvis, centred between
  the pelvis and the midpoint of the two hip joints (de Leva puts it 61 %
  of the way from the navel down to the hip joints);
* **middle and upper trunk**: over the bones of the chain from the first
  spine joint to the neck (from the pelvis to the neck when the spine role
  is empty; bones of zero length, helper joints, skipped).  The last bone
  (the one ending at the neck) is the upper trunk (``upper_trunk``); the
  middle trunk is shared equally by the bones below it (``middle_trunk``,
  or ``middle_trunk_1`` ... ``middle_trunk_k``), each link owned by its
  bone's lower joint.  A chain of a single bone carries both, the middle
  trunk centred at a quarter of it and the upper trunk at three quarters.
  Equal shares rather than shares by length: vertebral bones of captured
  skeletons are of about equal length (CMU BVH: LowerBack-Spine and
  Spine-Spine1, 12.1 cm each, halves of the middle trunk); CMU BVH thus gets
  two middle-trunk links and Spine1-Neck as the upper trunk, Daz one
  (abdomen-chest) and chest-neck;
* **head and neck** (``head``): from the neck joint to the top of the head,
  which is the head joint's end site, else the mean of its child joints
  (Daz: the eyes), else :data:`HEAD_TOP` leg lengths beyond the head joint
  along the neck-to-head direction; owned by the last joint of the
  neck-to-head chain that lies at or below the link centre (CMU ``Neck1``,
  Daz ``head``);
* **arms**: upper arm from the shoulder to the elbow, forearm from the
  elbow to the wrist, hand from the wrist to its far point: the last joint
  of the longest chain of joints below the wrist (CMU ``LeftHandIndex1``,
  Daz ``lIndex2``), else the wrist's end site, else :data:`HAND` forearm
  lengths beyond the wrist;
* **legs**: thigh from the hip to the knee, shank from the knee to the
  ankle, foot from the ankle to the toe (the ball of the foot), or, when
  there is no toe joint, to the toe tip below;
* clavicles, helper joints, fingers and eyes carry no mass of their own.

"Leg length" is the hip-to-knee plus knee-to-ankle distance in the
reference pose, averaged over both sides: the body's scale for the
estimated points.

Support-polygon points
---------------------
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
:meth:`Body.from_skeleton` given a Motion measures the body in
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
ground y = 0, kilograms.
"""

from __future__ import annotations

import dataclasses
import itertools
from collections.abc import Callable, Mapping, Sequence
from functools import lru_cache
from types import MappingProxyType
from typing import Any, Literal, NamedTuple

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy import sparse
from scipy.ndimage import gaussian_filter1d

from .. import quat
from .._warnings import warn
from ..kinematics import fk
from ..motion import Motion, Skeleton, readonly
from ..roles import Roles, RolesError, _plausible, mirror_name, resolve_roles

__all__ = [
    "DE_LEVA_MALE",
    "DEFAULT_TOTAL_MASS",
    "GRAVITY",
    "HEAD_TOP",
    "TOE_TIP",
    "FOOT_TIP",
    "BALL",
    "HAND",
    "Body",
    "LinkSpec",
    "RestPoseWarning",
    "standing_pose",
    "link_positions",
    "center_of_mass",
    "linear_momentum",
    "angular_momentum",
    "smoothed_derivatives",
    "paper_width",
]

Array = NDArray[np.float64]

#: Roles the default body model needs (legs first).
_NEEDED = tuple(f"{s}_{p}" for s in ("left", "right") for p in ("hip", "knee", "ankle")) + (
    "pelvis",
    "neck",
    "head",
) + tuple(f"{s}_{p}" for s in ("left", "right") for p in ("shoulder", "elbow", "wrist"))

#: Gravity vector, metres per second squared (Y up).
GRAVITY = np.array([0.0, -9.81, 0.0])

#: Default body mass in kilograms (the ZMP and the touch-up do not depend on it).
DEFAULT_TOTAL_MASS = 70.0

#: de Leva (1996) male segment masses, percent of body mass (one side for limbs).
DE_LEVA_MALE: Mapping[str, float] = MappingProxyType({
    "head_neck": 6.94,
    "upper_trunk": 15.96,
    "middle_trunk": 16.33,
    "lower_trunk": 11.17,
    "upper_arm": 2.71,
    "forearm": 1.62,
    "hand": 0.61,
    "thigh": 14.16,
    "shank": 4.33,
    "foot": 1.37,
})


@dataclasses.dataclass(frozen=True)
class LinkSpec:
    """How one link maps onto a skeleton, by joint names.

    Parameters
    ----------
    name : str
        Link name (``"left_thigh"``).
    segment : str
        Key of the anthropometric table (``"thigh"``).
    share : float
        Fraction of the segment's mass carried by this link (1, or 0.5 when a
        segment is split over two bones).
    owner : str
        Joint the link moves with.
    a, b : tuple of str
        Two skeleton points whose midpoint in the reference pose is the link centre; each
        point is the mean of the named joints, ``"Joint:end"`` naming the end
        site of ``Joint``.
    """

    name: str
    segment: str
    share: float
    owner: str
    a: tuple[str, ...]
    b: tuple[str, ...]


class _Link(NamedTuple):
    """One link of a body being built: its centre is a point of the reference pose."""

    name: str
    segment: str
    share: float
    owner: int
    centre: Array


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
    """The skeleton's rest pose is not a standing pose: the body is measured in another pose (or is off)."""


def standing_pose(motion: Motion, *, roles: Mapping[str, Any] | None = None) -> Array:
    """A standing reference pose of a motion: local rotations, shape (J, 4).

    The pose :meth:`Body.from_skeleton` measures a body in when the
    skeleton's rest pose is not a standing pose (see the module notes,
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
    >>> from mocaplab.data import cmu                                  # doctest: +SKIP
    >>> walk = cmu("16_15")                                             # doctest: +SKIP
    >>> body = Body.from_skeleton(walk, pose=standing_pose(walk))       # doctest: +SKIP
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
    """The reference pose of :meth:`Body.from_skeleton` (see the module notes)."""
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


def _trunk_links(skeleton: Skeleton, roles: Roles, joints: Array) -> list[_Link]:
    """Middle and upper trunk over the bones from the first spine joint (else the pelvis) to the neck."""
    chain = roles.spine_indices() + [roles.index("neck")]
    if len(chain) == 1:
        chain = [roles.index("pelvis")] + chain
    eps = _zero_length(skeleton)
    bones = [(a, b) for a, b in itertools.pairwise(chain) if np.linalg.norm(joints[b] - joints[a]) > eps]
    if not bones:
        raise ValueError(
            f"Expected a trunk of positive length from the pelvis {roles['pelvis']!r} to the neck {roles['neck']!r}, "
            "got none; give the neck with roles={'neck': ...}"
        )
    if len(bones) == 1:
        (a, b), = bones
        pa, pb = joints[a], joints[b]
        return [
            _Link("middle_trunk", "middle_trunk", 1.0, a, pa + 0.25 * (pb - pa)),
            _Link("upper_trunk", "upper_trunk", 1.0, a, pa + 0.75 * (pb - pa)),
        ]
    middle = bones[:-1]
    names = ["middle_trunk"] if len(middle) == 1 else [f"middle_trunk_{k + 1}" for k in range(len(middle))]
    links = [
        _Link(name, "middle_trunk", 1.0 / len(middle), a, 0.5 * (joints[a] + joints[b]))
        for name, (a, b) in zip(names, middle, strict=True)
    ]
    a, b = bones[-1]
    return links + [_Link("upper_trunk", "upper_trunk", 1.0, a, 0.5 * (joints[a] + joints[b]))]


def _head_link(skeleton: Skeleton, roles: Roles, pose: _Pose, frame: _Frame) -> _Link:
    """Head and neck from the neck to the top of the head, owned by the chain joint below its centre."""
    joints = pose.joints
    neck, head = roles.index("neck"), roles.index("head")
    top = _beyond(skeleton, pose, head)
    if top is None:
        up = _unit(joints[head] - joints[neck])
        if up is None:
            up = _unit(joints[neck] - joints[roles.index("pelvis")])
        top = joints[head] + HEAD_TOP * frame.leg * (_UP if up is None else up)
    a = joints[neck]
    chain = skeleton.chain(neck, head) if head != neck else [neck]
    span = top - a
    along = [float((joints[j] - a) @ span / max(float(span @ span), 1e-24)) for j in chain]
    owner = [j for j, t in zip(chain, along, strict=True) if t <= 0.5][-1]
    return _Link("head", "head_neck", 1.0, int(owner), 0.5 * (a + top))


def _limb_links(skeleton: Skeleton, roles: Roles, pose: _Pose, frame: _Frame) -> list[_Link]:
    joints = pose.joints
    links = []
    for side in ("left", "right"):
        shoulder, elbow, wrist = roles.indices(*(f"{side}_{p}" for p in ("shoulder", "elbow", "wrist")))
        hip, knee, ankle = roles.indices(*(f"{side}_{p}" for p in ("hip", "knee", "ankle")))
        toe = roles.get(f"{side}_toe")
        _, ball, tip = _foot_points(skeleton, pose, ankle, None if toe is None else skeleton.index(toe), None, frame)
        links += [
            _Link(f"{side}_upper_arm", "upper_arm", 1.0, shoulder, 0.5 * (joints[shoulder] + joints[elbow])),
            _Link(f"{side}_forearm", "forearm", 1.0, elbow, 0.5 * (joints[elbow] + joints[wrist])),
            _Link(f"{side}_hand", "hand", 1.0, wrist, 0.5 * (joints[wrist] + _knuckles(skeleton, pose, wrist, elbow))),
            _Link(f"{side}_thigh", "thigh", 1.0, hip, 0.5 * (joints[hip] + joints[knee])),
            _Link(f"{side}_shank", "shank", 1.0, knee, 0.5 * (joints[knee] + joints[ankle])),
            _Link(f"{side}_foot", "foot", 1.0, ankle, 0.5 * (joints[ankle] + (ball if toe is not None else tip))),
        ]
    return links


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


@dataclasses.dataclass(frozen=True, eq=False)
class Body:
    """Point masses attached to the joints of a skeleton.

    Parameters
    ----------
    joint_names : tuple of str
        Names of the skeleton's joints (checked against motions).
    link_names : tuple of str, length L
    owners : array_like of int, shape (L,)
        Joint index each link moves with.
    offsets : array_like, shape (L, 3)
        Link centre in the owner's local frame, metres.
    masses : array_like, shape (L,)
        Link masses, kilograms, all > 0.
    point_joints : tuple of str, length P
        For each support-polygon point, the contact joint it belongs to
        (the ankle for heel points, the toe for toe points: ``"LeftFoot"`` and
        ``"LeftToeBase"`` on the CMU skeleton).
    point_owners : array_like of int, shape (P,)
    point_offsets : array_like, shape (P, 3)
        Support point in its owner's local frame.
    point_heights : array_like, shape (P,), optional
        Height of each support point above its foot's lowest point in the
        reference pose, metres, for feet without a toe joint (their heel and
        toe points all belong to the ankle); NaN elsewhere.  The support
        polygon leaves out a lifted heel or toe of such a foot
        (:func:`mocaplab.physics.balance`).

    Use :meth:`from_skeleton` to build one from any humanoid skeleton (by its joint roles).
    Its arrays are copies, read-only for good (views of read-only owners).

    Examples
    --------
    >>> from mocaplab.data import cmu          # doctest: +SKIP
    >>> body = Body.from_skeleton(cmu("16_15").skeleton)   # doctest: +SKIP
    >>> round(body.total_mass, 1)               # doctest: +SKIP
    70.0
    """

    joint_names: tuple[str, ...]
    link_names: tuple[str, ...]
    owners: NDArray[np.int64]
    offsets: Array
    masses: Array
    point_joints: tuple[str, ...] = ()
    point_owners: NDArray[np.int64] = dataclasses.field(default_factory=lambda: np.zeros(0, dtype=np.int64))
    point_offsets: Array = dataclasses.field(default_factory=lambda: np.zeros((0, 3)))
    point_heights: Array | None = None

    def __post_init__(self) -> None:
        jn = tuple(str(n) for n in self.joint_names)
        ln = tuple(str(n) for n in self.link_names)
        n_links = len(ln)
        owners = np.asarray(self.owners, dtype=np.int64).reshape(-1)
        offsets = np.asarray(self.offsets, dtype=float)
        masses = np.asarray(self.masses, dtype=float).reshape(-1)
        if n_links == 0:
            raise ValueError("Expected at least one link in `link_names`, got none")
        if owners.shape != (n_links,) or np.any((owners < 0) | (owners >= len(jn))):
            raise ValueError(f"Expected `owners` of {n_links} joint indices in [0, {len(jn)}), got {owners}")
        if offsets.shape != (n_links, 3) or not np.all(np.isfinite(offsets)):
            raise ValueError(f"Expected finite `offsets` of shape ({n_links}, 3), got {offsets.shape}")
        if masses.shape != (n_links,) or not np.all(np.isfinite(masses)) or np.any(masses <= 0):
            raise ValueError(f"Expected {n_links} positive finite `masses`, got {masses}")
        pj = tuple(str(n) for n in self.point_joints)
        po = np.asarray(self.point_owners, dtype=np.int64).reshape(-1)
        pof = np.asarray(self.point_offsets, dtype=float).reshape(-1, 3)
        if po.shape != (len(pj),) or pof.shape != (len(pj), 3):
            raise ValueError(
                f"Expected `point_owners` ({len(pj)},) and `point_offsets` ({len(pj)}, 3), got {po.shape} and {pof.shape}"
            )
        ph = np.full(len(pj), np.nan) if self.point_heights is None else np.asarray(self.point_heights, dtype=float).reshape(-1)
        if ph.shape != (len(pj),):
            raise ValueError(f"Expected `point_heights` of shape ({len(pj)},), got {ph.shape}")
        object.__setattr__(self, "point_heights", readonly(np.array(ph, copy=True)))
        for name, arr in (("owners", owners), ("offsets", offsets), ("masses", masses), ("point_owners", po), ("point_offsets", pof)):
            object.__setattr__(self, name, readonly(np.array(arr, copy=True)))
        object.__setattr__(self, "joint_names", jn)
        object.__setattr__(self, "link_names", ln)
        object.__setattr__(self, "point_joints", pj)

    # ---------------------------------------------------------- builders
    @classmethod
    def from_skeleton(
        cls,
        skeleton: Skeleton | Motion,
        *,
        roles: Mapping[str, Any] | None = None,
        total_mass: float = DEFAULT_TOTAL_MASS,
        table: Mapping[str, float] = DE_LEVA_MALE,
        foot_width: float = 0.09,
        heel: float = 0.05,
        pose: ArrayLike | Literal["rest"] | None = None,
    ) -> Body:
        """The default body of any humanoid skeleton, mapped from its joint roles.

        Parameters
        ----------
        skeleton : Skeleton or Motion
            A Motion also gives the reference pose when the skeleton's rest
            pose is not a standing pose (see ``pose``).
        roles : mapping of role names to joint names, optional
            Overrides of the inferred joint roles
            (:func:`mocaplab.roles.resolve_roles`).
        total_mass : float
            Body mass in kilograms; the table's percentages are scaled to it.
        table : mapping of str to float
            Segment masses in percent (default :data:`DE_LEVA_MALE`).
        foot_width : float
            Width of the foot's support outline in metres (0 gives the
            heel-to-toe line of the paper's description).
        heel : float
            How far the heel point lies behind the ankle, metres.
        pose : array_like, shape (J, 4), "rest" or None
            The pose in which link centres and support points are measured
            (see the module notes, "Reference pose"): local rotations (for
            instance ``motion.rotations[k]``), or ``"rest"`` for the rest
            pose.  Default: the rest pose when it is a standing pose; else,
            when a Motion is given, :func:`standing_pose` of the motion,
            with a :class:`RestPoseWarning` (a Skeleton alone keeps its rest
            pose, with a warning that says how to do better).

        Returns
        -------
        Body
            Links ``pelvis``, ``middle_trunk`` (or ``middle_trunk_1`` ...
            ``middle_trunk_k``), ``upper_trunk``, ``head``, and per side
            ``upper_arm``, ``forearm``, ``hand``, ``thigh``, ``shank``,
            ``foot`` (``left_thigh`` ...); heel and toe support points.

        Raises
        ------
        RolesError
            When the skeleton lacks a role the model needs (pelvis, neck,
            head, the legs' hip, knee and ankle, the arms' shoulder, elbow
            and wrist), naming it and the ``roles=`` that supplies it.
        """
        sk = _skeleton_of(skeleton)
        r = resolve_roles(sk, roles)
        r.require(*_NEEDED, purpose="the body model (Body.from_skeleton)")
        if not np.isfinite(foot_width) or foot_width < 0:
            raise ValueError(f"Expected `foot_width` >= 0 metres, got {foot_width!r}")
        if not np.isfinite(heel) or heel < 0:
            raise ValueError(f"Expected `heel` >= 0 metres, got {heel!r}")
        ref = _reference(skeleton, r, pose)
        frame = _body_frame(r, ref.joints)
        pelvis = r.index("pelvis")
        hips = ref.joints[r.indices("left_hip", "right_hip")].mean(axis=0)
        links = [_Link("pelvis", "lower_trunk", 1.0, pelvis, 0.5 * (hips + ref.joints[pelvis]))]
        links += _trunk_links(sk, r, ref.joints)
        links.append(_head_link(sk, r, ref, frame))
        links += _limb_links(sk, r, ref, frame)
        body = cls._assemble(sk, ref, links, total_mass=total_mass, table=table)
        return body._with_feet(sk, ref, r.feet(), r, foot_width, heel)

    @classmethod
    def from_links(
        cls,
        skeleton: Skeleton | Motion,
        links: Sequence[LinkSpec],
        *,
        total_mass: float = DEFAULT_TOTAL_MASS,
        table: Mapping[str, float] = DE_LEVA_MALE,
        pose: ArrayLike | Literal["rest"] | None = None,
    ) -> Body:
        """A body from explicit link specifications (no support points).

        Masses are ``total_mass * table[segment] / 100 * share``; they are not
        renormalised, so a partial mapping has less than ``total_mass``.
        Link centres are measured in ``pose`` (see :meth:`from_skeleton`).
        """
        ref = _reference(skeleton, None, pose)
        sk = _skeleton_of(skeleton)
        out = []
        for spec in links:
            a = np.mean([_point(sk, ref, p) for p in spec.a], axis=0)
            b = np.mean([_point(sk, ref, p) for p in spec.b], axis=0)
            out.append(_Link(spec.name, spec.segment, spec.share, sk.index(spec.owner), 0.5 * (a + b)))
        return cls._assemble(sk, ref, out, total_mass=total_mass, table=table)

    @classmethod
    def _assemble(
        cls,
        skeleton: Skeleton,
        pose: _Pose,
        links: Sequence[_Link],
        *,
        total_mass: float,
        table: Mapping[str, float],
    ) -> Body:
        """The body of links whose centres are points of the reference pose (the one builder behind the others)."""
        if not np.isfinite(total_mass) or total_mass <= 0:
            raise ValueError(f"Expected `total_mass` > 0 kilograms, got {total_mass!r}")
        for link in links:
            if link.segment not in table:
                raise KeyError(f"Segment {link.segment!r} of link {link.name!r} is not in the mass table {sorted(table)}")
        owners = np.array([link.owner for link in links], dtype=np.int64)
        offsets = _local(pose, owners, np.array([link.centre - pose.joints[link.owner] for link in links]).reshape(-1, 3))
        masses = np.array([total_mass * table[link.segment] / 100.0 * link.share for link in links])
        return cls(skeleton.names, tuple(link.name for link in links), owners, offsets, masses)

    def with_feet(
        self,
        skeleton: Skeleton | Motion,
        feet: Sequence[tuple[str, str | None] | tuple[str, str | None, str | None]] | None = None,
        *,
        roles: Mapping[str, Any] | None = None,
        foot_width: float = 0.09,
        heel: float = 0.05,
        pose: ArrayLike | Literal["rest"] | None = None,
    ) -> Body:
        """This body with heel and toe support points for each foot.

        Parameters
        ----------
        skeleton : Skeleton or Motion
        feet : sequence of (ankle, toe joint or None[, toe-tip point or None]), optional
            Joint names; default the feet of the joint roles
            (:meth:`mocaplab.roles.Roles.feet`).  A toe-tip point is a joint
            name or ``"Joint:end"``; without one it is found or estimated
            (see the module notes).
        roles : mapping of role names to joint names, optional
            Role overrides, used for the feet and for estimated points.
        foot_width, heel, pose
            See :meth:`from_skeleton`.
        """
        sk = _skeleton_of(skeleton)
        if not np.isfinite(foot_width) or foot_width < 0:
            raise ValueError(f"Expected `foot_width` >= 0 metres, got {foot_width!r}")
        if not np.isfinite(heel) or heel < 0:
            raise ValueError(f"Expected `heel` >= 0 metres, got {heel!r}")
        if feet is None:
            feet = resolve_roles(sk, roles).feet()
            if not feet:
                resolve_roles(sk, roles).require("left_ankle", "right_ankle", purpose="the feet of the body model")
        return self._with_feet(sk, _reference(skeleton, roles, pose), feet, roles, foot_width, heel)

    def _with_feet(
        self,
        skeleton: Skeleton,
        pose: _Pose,
        feet: Sequence[tuple[str, str | None] | tuple[str, str | None, str | None]],
        roles: Mapping[str, Any] | None,
        foot_width: float,
        heel: float,
    ) -> Body:
        """:meth:`with_feet` with the feet and the reference pose resolved."""

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
        return dataclasses.replace(
            self,
            point_joints=tuple(pj),
            point_owners=point_owners,
            point_offsets=_local(pose, point_owners, np.array(pof).reshape(-1, 3)),
            point_heights=np.array(heights),
        )

    def with_masses(self, masses: ArrayLike) -> Body:
        """The same body with other link masses (kilograms, shape (L,))."""
        return dataclasses.replace(self, masses=np.asarray(masses, dtype=float))

    # ---------------------------------------------------------- queries
    @property
    def n_links(self) -> int:
        return len(self.link_names)

    @property
    def total_mass(self) -> float:
        """Sum of the link masses, kilograms."""
        return float(self.masses.sum())

    def link_index(self, name: str) -> int:
        """Index of the link called ``name``."""
        try:
            return self.link_names.index(name)
        except ValueError:
            raise KeyError(f"No link named {name!r}; links are {list(self.link_names)}") from None

    def mirror_map(self) -> NDArray[np.int64]:
        """For each link, the index of its left/right counterpart (itself if none)."""
        lookup = {n: i for i, n in enumerate(self.link_names)}
        return np.array([lookup.get(mirror_name(n), i) for i, n in enumerate(self.link_names)], dtype=np.int64)

    def mass_table(self) -> dict[str, float]:
        """Link name to mass in kilograms."""
        return {n: float(m) for n, m in zip(self.link_names, self.masses, strict=True)}

    def check(self, motion: Motion) -> None:
        """Raise ValueError unless ``motion`` has this body's skeleton (by joint names)."""
        if not isinstance(motion, Motion):
            raise TypeError(f"Expected `motion` to be a Motion, got {type(motion).__name__}")
        if motion.skeleton.names != self.joint_names:
            raise ValueError(
                f"Expected a motion of the body's skeleton ({len(self.joint_names)} joints starting "
                f"{list(self.joint_names[:3])}), got {motion.n_joints} joints starting {list(motion.skeleton.names[:3])}"
            )

    def support_points(
        self, motion: Motion, joints: Sequence[str], *, fk: tuple[Array, Array] | None = None
    ) -> tuple[Array, NDArray[np.int64]]:
        """World positions of the support points of the given contact joints.

        Parameters
        ----------
        motion : Motion
        joints : sequence of str, length n
            Contact joints (the columns of a :class:`~mocaplab.contacts.Contacts` mask).
        fk : (global_rotations, global_positions), optional
            The motion's forward kinematics when already at hand.

        Returns
        -------
        points : ndarray, shape (F, P, 3)
        column : ndarray of int, shape (P,)
            Index into ``joints`` of the joint each point belongs to.  A joint
            without foot geometry contributes its own position.
        """
        self.check(motion)
        o, offsets, column, _ = self._support_layout(motion.skeleton, tuple(joints))
        grot, gpos = (motion.global_rotations(), motion.global_positions()) if fk is None else fk
        pts = gpos[:, o] + quat.rotate(grot[:, o], offsets)
        return pts, column

    def _support_layout(
        self, skeleton: Skeleton, joints: tuple[str, ...]
    ) -> tuple[NDArray[np.int64], Array, NDArray[np.int64], Array]:
        """Owners, local offsets, contact columns and reference heights (NaN: not rolling) of the support points."""
        key = (id(skeleton), joints)
        cache = self.__dict__.setdefault("_layout_cache", {})
        if key in cache:
            return cache[key]
        owners: list[int] = []
        offsets: list[Array] = []
        column: list[int] = []
        heights: list[float] = []
        for k, name in enumerate(joints):
            hits = [i for i, pj in enumerate(self.point_joints) if pj == name]
            if hits:
                owners.extend(int(self.point_owners[i]) for i in hits)
                offsets.extend(self.point_offsets[i] for i in hits)
                heights.extend(float(self.point_heights[i]) for i in hits)  # type: ignore[index]  # an array after __post_init__
                column.extend([k] * len(hits))
            else:
                owners.append(skeleton.index(name))
                offsets.append(np.zeros(3))
                heights.append(np.nan)
                column.append(k)
        out = (
            readonly(np.array(owners, dtype=np.int64)),
            readonly(np.array(offsets).reshape(-1, 3)),
            readonly(np.array(column, dtype=np.int64)),
            readonly(np.array(heights, dtype=float)),
        )
        cache[key] = out
        return out


# ---------------------------------------------------------------- kinematics
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


def link_positions(motion: Motion, body: Body, *, fk: tuple[Array, Array] | None = None) -> Array:
    """World positions of the link centres, shape (F, L, 3).

    ``fk`` optionally gives the motion's (global rotations, global positions).
    """
    body.check(motion)
    grot, gpos = (motion.global_rotations(), motion.global_positions()) if fk is None else fk
    return gpos[:, body.owners] + quat.rotate(grot[:, body.owners], body.offsets)


def paper_width(frames_at_30fps: float, fps: float) -> float:
    """A kernel width given in frames at the paper's 30 fps, in frames at ``fps``."""
    return float(frames_at_30fps) * float(fps) / 30.0


def smoothed_derivatives(
    positions: ArrayLike, fps: float, *, width: float
) -> tuple[Array, Array, Array]:
    """Gaussian-smoothed positions, velocities and accelerations along axis 0.

    The paper applies "a gaussian filter of width 5" (frames at 30 fps) and
    then finite differences.  A kernel of width ``w`` frames here is a
    Gaussian of standard deviation ``w / 4`` truncated at two standard
    deviations, so it spans ``w`` frames.  Before filtering, each end is
    padded with the least-squares parabola through its first (last) frames,
    so that the filter neither invents a stop at the ends nor bends a
    ballistic path (quadratic signals come out exact); then central
    differences.

    Parameters
    ----------
    positions : array_like, shape (F, ...)
    fps : float
    width : float
        Kernel width in frames of this clip (0 or less: no smoothing).

    Returns
    -------
    smoothed, velocity, acceleration : ndarray, shape (F, ...)
        Units per second and per second squared.
    """
    x = np.asarray(positions, dtype=float)
    n = x.shape[0]
    if n < 2:
        z = np.zeros_like(x)
        return x.copy(), z, z.copy()
    std = max(float(width), 0.0) / 4.0
    pad = int(2.0 * std + 0.5) + 1
    fit = min(n, max(3, 2 * pad))
    flat = x.reshape(n, -1)
    head = _extrapolate(flat[:fit], np.arange(-pad, 0))
    tail = _extrapolate(flat[n - fit :][::-1], np.arange(-pad, 0))[::-1]
    xp = np.concatenate([head, flat, tail], axis=0)
    if std > 0:
        xp = gaussian_filter1d(xp, std, axis=0, mode="nearest", truncate=2.0)
    s = xp[pad : pad + n]
    v = (xp[pad + 1 : pad + n + 1] - xp[pad - 1 : pad + n - 1]) * (0.5 * fps)
    a = (xp[pad + 1 : pad + n + 1] - 2.0 * s + xp[pad - 1 : pad + n - 1]) * (fps * fps)
    return s.reshape(x.shape), v.reshape(x.shape), a.reshape(x.shape)


def _positions_and_accelerations(positions: Array, fps: float, *, width: float) -> tuple[Array, Array]:
    """The smoothed positions and accelerations of :func:`smoothed_derivatives`, shape (F, ...) each.

    The same numbers (up to rounding), as one product with a cached sparse
    operator: the end padding, the Gaussian filter and the differences are
    linear in the positions.  Used where the touch-up needs them on every
    step (the operator depends only on the frame count, rate and width).
    """
    x = np.asarray(positions, dtype=float)
    n = x.shape[0]
    if n < 2:
        return x.copy(), np.zeros_like(x)
    both = _pos_acc_operator(n, float(fps), float(width)) @ x.reshape(n, -1)
    return both[:n].reshape(x.shape), both[n:].reshape(x.shape)


@lru_cache(maxsize=4)
def _pos_acc_operator(n: int, fps: float, width: float) -> sparse.csr_matrix:
    """Sparse (2n, n) map from positions to [smoothed positions; accelerations] (see smoothed_derivatives)."""
    std = max(float(width), 0.0) / 4.0
    pad = int(2.0 * std + 0.5) + 1
    fit = min(n, max(3, 2 * pad))
    ext = _extrapolator(fit, tuple(range(-pad, 0)))  # (pad, fit)
    # padding: least-squares parabolas at both ends, the samples in between
    rows = [np.repeat(np.arange(pad), fit), pad + np.arange(n), np.repeat(np.arange(pad + n, 2 * pad + n)[::-1], fit)]
    cols = [np.tile(np.arange(fit), pad), np.arange(n), np.tile(n - 1 - np.arange(fit), pad)]
    vals = [ext.ravel(), np.ones(n), ext.ravel()]
    padded = sparse.csr_matrix((np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))), shape=(n + 2 * pad, n))
    if std > 0:
        # the kernel of gaussian_filter1d (mode "nearest", truncated at 2 std)
        radius = int(2.0 * std + 0.5)
        impulse = np.zeros(2 * radius + 1)
        impulse[radius] = 1.0
        kernel = gaussian_filter1d(impulse, std, mode="constant", truncate=2.0)[::-1]
        m = n + 2 * pad
        i = np.repeat(np.arange(m), 2 * radius + 1)
        j = np.clip(i + np.tile(np.arange(-radius, radius + 1), m), 0, m - 1)
        blur = sparse.csr_matrix((np.tile(kernel, m), (i, j)), shape=(m, m))  # duplicates (clamped) add up
        padded = blur @ padded
    padded = sparse.csr_matrix(padded)
    mid = padded[pad : pad + n]
    acc = (padded[pad + 1 : pad + n + 1] - 2.0 * mid + padded[pad - 1 : pad + n - 1]) * (fps * fps)
    out = sparse.csr_matrix(sparse.vstack([mid, acc]))
    out.sum_duplicates()
    return out


def _extrapolate(samples: Array, at: NDArray[np.int64]) -> Array:
    """Least-squares parabola (line for two samples) through ``samples`` (q, K) at indices ``at``."""
    return _extrapolator(samples.shape[0], tuple(int(a) for a in at)) @ samples


@lru_cache(maxsize=64)
def _extrapolator(q: int, at: tuple[int, ...]) -> Array:
    """The linear map from ``q`` samples to their least-squares parabola at ``at``."""
    deg = min(2, q - 1)
    basis = np.vander(np.arange(q, dtype=float), deg + 1)
    return readonly(np.vander(np.asarray(at, dtype=float), deg + 1) @ np.linalg.pinv(basis))


def center_of_mass(motion: Motion, body: Body) -> Array:
    """Centre of mass on every frame (equation 1), shape (F, 3)."""
    r = link_positions(motion, body)
    return np.einsum("l,flc->fc", body.masses, r) / body.total_mass


def _smoothing(motion: Motion, width: float | None) -> float:
    return paper_width(5.0, motion.fps) if width is None else float(width)


def linear_momentum(motion: Motion, body: Body, *, width: float | None = None) -> Array:
    """Linear momentum ``sum m_i v_i`` (kg m/s), shape (F, 3).

    Velocities are central differences of positions smoothed with a
    Gaussian of ``width`` frames (default 5 frames at 30 fps, scaled to the
    clip's rate; see :func:`smoothed_derivatives`).
    """
    _, v, _ = smoothed_derivatives(link_positions(motion, body), motion.fps, width=_smoothing(motion, width))
    return np.einsum("l,flc->fc", body.masses, v)


def angular_momentum(
    motion: Motion, body: Body, *, about: ArrayLike | str = "com", width: float | None = None
) -> Array:
    """Angular momentum of the point masses (equation 2), kg m^2/s, shape (F, 3).

    Parameters
    ----------
    motion : Motion
    body : Body
    about : "com" or array_like, shape (3,) or (F, 3)
        Reference point: the centre of mass (default, ``h_CM`` of the paper)
        or fixed/per-frame points.
    width : float, optional
        Smoothing width in frames (default 5 frames at 30 fps).
    """
    s, v, _ = smoothed_derivatives(link_positions(motion, body), motion.fps, width=_smoothing(motion, width))
    m = body.masses
    if isinstance(about, str):
        if about != "com":
            raise ValueError(f"Expected `about` to be 'com' or points of shape (3,) or (F, 3), got {about!r}")
        ref = np.einsum("l,flc->fc", m, s) / m.sum()
    else:
        ref = np.broadcast_to(np.asarray(about, dtype=float), (motion.n_frames, 3))
    return np.einsum("l,flc->fc", m, np.cross(s - ref[:, None], v))

