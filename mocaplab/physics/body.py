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

Rigid segments
--------------
The paper's links are points; it reports that boxes of points change the
angular momentum by under 2 %.  For ``inertia="segments"``
(:func:`angular_momentum`, :func:`~mocaplab.physics.flight_measures`,
:func:`~mocaplab.physics.touch_up`) each link is also a rigid segment with
de Leva's radii of gyration (:data:`DE_LEVA_GYRATION_MALE`, percent of the
segment's length about its sagittal, transverse and long axes), measured in
the reference pose (:attr:`Body.inertia`).  Its own spin is 7-42 % of the
angular momentum over the flights of the CMU clips (16_05, 16_01, 49_03,
09_06, 16_35, 127_04, 127_17, 127_21; median 15 %), at 30 as at 120 fps.

Mapping onto skeletons (choices made here, the paper gives none)
---------------------------------------------------------------
:meth:`Body.from_skeleton` maps the segments onto any humanoid skeleton
through its joint roles (:mod:`mocaplab.roles`: pelvis, spine, neck, head,
hips, knees, ankles, toes, shoulders, elbows, wrists), never through joint
names.  A link is rigidly attached to one joint (its owner); its centre is
the midpoint of two points of the reference pose (normally the rest pose,
see :mod:`mocaplab.anatomy`, "Reference pose"), expressed in the owner's
frame:

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
  (Daz: the eyes), else :data:`~mocaplab.anatomy.HEAD_TOP` leg lengths
  beyond the head joint along the neck-to-head direction; owned by the
  last joint of the neck-to-head chain that lies at or below the link
  centre (CMU ``Neck1``, Daz ``head``);
* **arms**: upper arm from the shoulder to the elbow, forearm from the
  elbow to the wrist, hand from the wrist to its far point: the last joint
  of the longest chain of joints below the wrist (CMU ``LeftHandIndex1``,
  Daz ``lIndex2``), else the wrist's end site, else
  :data:`~mocaplab.anatomy.HAND` forearm lengths beyond the wrist;
* **legs**: thigh from the hip to the knee, shank from the knee to the
  ankle, foot from the ankle to the toe (the ball of the foot), or, when
  there is no toe joint, to the toe tip below;
* clavicles, helper joints, fingers and eyes carry no mass of their own.

The estimated points (the top of the head, the hand's far point, the toe
tips), the body's scale ("leg length") and the reference pose belong to
the skeleton's anatomy, not to the mass model: they live in
:mod:`mocaplab.anatomy` (sections "Estimated end points",
"Support-polygon points" and "Reference pose"), which this module uses.
The body's heel and toe support points (:meth:`Body.with_feet`) are that
module's foot points, carried by the ankles and toes; the ZMP's support
polygon is built from them (:func:`mocaplab.physics.support_polygon`).

Conventions are those of :mod:`mocaplab.motion`: metres, seconds, Y up,
ground y = 0, kilograms.

Longer than 800 lines because the body model, the table it is built from and
the quantities of equations 1 and 2 share the link layout and the one
smoothing rule, and each public function carries a runnable example.
"""

from __future__ import annotations

import dataclasses
import itertools
from collections.abc import Mapping, Sequence
from functools import lru_cache
from types import MappingProxyType
from typing import Any, Literal, NamedTuple

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy import sparse
from scipy.ndimage import gaussian_filter1d

from .. import quat
from ..anatomy import (
    _NEEDED,
    _body_frame,
    _foot_points,
    _Frame,
    _head_top,
    _knuckles,
    _local,
    _point,
    _Pose,
    _reference,
    _skeleton_of,
    _support_points,
    _zero_length,
)
from ..kinematics import angular_velocities
from ..motion import Motion, Skeleton, readonly
from ..roles import Roles, mirror_name, resolve_roles

__all__ = [
    "DE_LEVA_GYRATION_MALE",
    "DE_LEVA_MALE",
    "DEFAULT_TOTAL_MASS",
    "GRAVITY",
    "Body",
    "LinkSpec",
    "link_positions",
    "center_of_mass",
    "linear_momentum",
    "angular_momentum",
    "smoothed_derivatives",
    "paper_width",
]

Array = NDArray[np.float64]

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

#: de Leva (1996) male radii of gyration about the segment's centre of mass,
#: percent of the segment's length: about its sagittal (front-back), its
#: transverse (left-right) and its longitudinal axis.  The head and neck
#: from the vertex to the seventh cervical vertebra (as the link of
#: :meth:`Body.from_skeleton` runs from the neck joint to the top of the
#: head), the hand from the wrist to the third knuckle.
DE_LEVA_GYRATION_MALE: Mapping[str, tuple[float, float, float]] = MappingProxyType({
    "head_neck": (30.3, 31.5, 26.1),
    "upper_trunk": (71.6, 45.4, 65.9),
    "middle_trunk": (48.2, 38.3, 46.8),
    "lower_trunk": (61.5, 55.1, 58.7),
    "upper_arm": (28.5, 26.9, 15.8),
    "forearm": (27.6, 26.5, 12.1),
    "hand": (62.8, 51.3, 40.1),
    "thigh": (32.9, 32.9, 14.9),
    "shank": (25.5, 24.9, 10.3),
    "foot": (25.7, 24.5, 12.4),
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

    Examples
    --------
    >>> from mocaplab.physics import LinkSpec
    >>> thigh = LinkSpec("left_thigh", "thigh", 1.0, "LeftUpLeg", ("LeftUpLeg",), ("LeftLeg",))
    >>> thigh.owner, thigh.share
    ('LeftUpLeg', 1.0)
    """

    name: str
    segment: str
    share: float
    owner: str
    a: tuple[str, ...]
    b: tuple[str, ...]


class _Link(NamedTuple):
    """One link of a body being built: it spans two points of the reference pose, ``a`` to ``b``; its centre is their midpoint."""

    name: str
    segment: str
    share: float
    owner: int
    a: Array
    b: Array

    @property
    def centre(self) -> Array:
        return 0.5 * (self.a + self.b)



def _segment_inertia(link: _Link, mass: float, forward: Array) -> Array:
    """A link's own inertia about its centre, world axes of the reference pose, kg m^2, shape (3, 3).

    The link's segment is taken as a rigid body of the link's mass whose
    radii of gyration are :data:`DE_LEVA_GYRATION_MALE` times the segment's
    length: the link's length ``|b - a|`` divided by its share (a segment
    split over ``k`` bones, as the middle trunk over a spine, is ``k`` such
    links long).  The longitudinal axis runs from ``a`` to ``b``, the
    sagittal axis is the body's ``forward`` direction made perpendicular to
    it (its up direction for a segment lying along ``forward``, a foot),
    the transverse axis the third.
    """
    axis = link.b - link.a
    length = float(np.linalg.norm(axis))
    if length <= 0.0:
        return np.zeros((3, 3))
    along = axis / length
    across = forward - (forward @ along) * along
    if np.linalg.norm(across) < 0.3:  # lying near the forward direction: front-back is up-down
        across = np.array([0.0, 1.0, 0.0]) - along[1] * along
    front = across / np.linalg.norm(across)
    side = np.cross(along, front)
    radii = np.array(DE_LEVA_GYRATION_MALE[link.segment]) / 100.0 * length / link.share
    axes = np.stack([front, side, along])  # rows: sagittal, transverse, longitudinal
    return mass * np.einsum("k,ki,kj->ij", radii**2, axes, axes)


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
            _Link("middle_trunk", "middle_trunk", 1.0, a, pa, 0.5 * (pa + pb)),
            _Link("upper_trunk", "upper_trunk", 1.0, a, 0.5 * (pa + pb), pb),
        ]
    middle = bones[:-1]
    names = ["middle_trunk"] if len(middle) == 1 else [f"middle_trunk_{k + 1}" for k in range(len(middle))]
    links = [
        _Link(name, "middle_trunk", 1.0 / len(middle), a, joints[a], joints[b])
        for name, (a, b) in zip(names, middle, strict=True)
    ]
    a, b = bones[-1]
    return links + [_Link("upper_trunk", "upper_trunk", 1.0, a, joints[a], joints[b])]


def _head_link(skeleton: Skeleton, roles: Roles, pose: _Pose, frame: _Frame) -> _Link:
    """Head and neck from the neck to the top of the head, owned by the chain joint below its centre."""
    joints = pose.joints
    neck, head = roles.index("neck"), roles.index("head")
    top = _head_top(skeleton, roles, pose, frame)
    a = joints[neck]
    chain = skeleton.chain(neck, head) if head != neck else [neck]
    span = top - a
    along = [float((joints[j] - a) @ span / max(float(span @ span), 1e-24)) for j in chain]
    owner = [j for j, t in zip(chain, along, strict=True) if t <= 0.5][-1]
    return _Link("head", "head_neck", 1.0, int(owner), a, top)


def _limb_links(skeleton: Skeleton, roles: Roles, pose: _Pose, frame: _Frame) -> list[_Link]:
    joints = pose.joints
    links = []
    for side in ("left", "right"):
        shoulder, elbow, wrist = roles.indices(*(f"{side}_{p}" for p in ("shoulder", "elbow", "wrist")))
        hip, knee, ankle = roles.indices(*(f"{side}_{p}" for p in ("hip", "knee", "ankle")))
        toe = roles.get(f"{side}_toe")
        _, ball, tip = _foot_points(skeleton, pose, ankle, None if toe is None else skeleton.index(toe), None, frame)
        links += [
            _Link(f"{side}_upper_arm", "upper_arm", 1.0, shoulder, joints[shoulder], joints[elbow]),
            _Link(f"{side}_forearm", "forearm", 1.0, elbow, joints[elbow], joints[wrist]),
            _Link(f"{side}_hand", "hand", 1.0, wrist, joints[wrist], _knuckles(skeleton, pose, wrist, elbow)),
            _Link(f"{side}_thigh", "thigh", 1.0, hip, joints[hip], joints[knee]),
            _Link(f"{side}_shank", "shank", 1.0, knee, joints[knee], joints[ankle]),
            _Link(f"{side}_foot", "foot", 1.0, ankle, joints[ankle], ball if toe is not None else tip),
        ]
    return links


@dataclasses.dataclass(frozen=True, eq=False)
class Body:
    """Point masses attached to the joints of a skeleton.

    Use :meth:`from_skeleton` to build one from any humanoid skeleton (by its joint roles).
    Its arrays are copies, read-only for good (views of read-only owners).

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
    inertia : array_like, shape (L, 3, 3), optional
        Each link's own inertia about its centre, in its owner's frame,
        kg m^2: the link as a rigid segment rather than a point
        (``inertia="segments"`` of :func:`angular_momentum`,
        :func:`~mocaplab.physics.flight_measures` and
        :func:`~mocaplab.physics.touch_up`).  :meth:`from_skeleton` gives
        de Leva's (:data:`DE_LEVA_GYRATION_MALE`); None (a point-mass body
        only) by default.

    Examples
    --------
    >>> import mocaplab as ml
    >>> body = ml.physics.Body.from_skeleton(ml.cmu("16_15").skeleton)
    >>> round(body.total_mass, 1), body.masses.shape
    (70.0, (17,))
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
    inertia: Array | None = None

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
        if self.inertia is not None:
            inertia = np.asarray(self.inertia, dtype=float)
            if inertia.shape != (n_links, 3, 3) or not np.all(np.isfinite(inertia)):
                raise ValueError(f"Expected finite `inertia` of shape ({n_links}, 3, 3), got {inertia.shape}")
            if not np.allclose(inertia, np.swapaxes(inertia, 1, 2), atol=1e-12 + 1e-9 * np.abs(inertia).max()):
                raise ValueError("Expected symmetric `inertia` tensors (kg m^2), got asymmetric ones")
            object.__setattr__(self, "inertia", readonly(np.array(inertia, copy=True)))
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
            (see :mod:`mocaplab.anatomy`, "Reference pose"): local rotations
            (for instance ``motion.rotations[k]``), or ``"rest"`` for the
            rest pose.  Default: the rest pose when it is a standing pose;
            else, when a Motion is given,
            :func:`~mocaplab.anatomy.standing_pose` of the motion, with a
            :class:`~mocaplab.anatomy.RestPoseWarning` (a Skeleton alone keeps its rest
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
        links = [_Link("pelvis", "lower_trunk", 1.0, pelvis, ref.joints[pelvis], hips)]
        links += _trunk_links(sk, r, ref.joints)
        links.append(_head_link(sk, r, ref, frame))
        links += _limb_links(sk, r, ref, frame)
        body = cls._assemble(sk, ref, links, total_mass=total_mass, table=table, forward=frame.forward)
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
            out.append(_Link(spec.name, spec.segment, spec.share, sk.index(spec.owner), a, b))
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
        forward: Array | None = None,
    ) -> Body:
        """The body of links whose centres are points of the reference pose (the one builder behind the others).

        With the body's ``forward`` direction (reference pose) and segments
        of :data:`DE_LEVA_GYRATION_MALE`, each link also gets its segment's
        own inertia (:attr:`Body.inertia`, see :func:`_segment_inertia`).
        """
        if not np.isfinite(total_mass) or total_mass <= 0:
            raise ValueError(f"Expected `total_mass` > 0 kilograms, got {total_mass!r}")
        for link in links:
            if link.segment not in table:
                raise KeyError(f"Segment {link.segment!r} of link {link.name!r} is not in the mass table {sorted(table)}")
        owners = np.array([link.owner for link in links], dtype=np.int64)
        offsets = _local(pose, owners, np.array([link.centre - pose.joints[link.owner] for link in links]).reshape(-1, 3))
        masses = np.array([total_mass * table[link.segment] / 100.0 * link.share for link in links])
        inertia = None
        if forward is not None and all(link.segment in DE_LEVA_GYRATION_MALE for link in links):
            world = np.stack([_segment_inertia(link, mass, forward) for link, mass in zip(links, masses, strict=True)])
            turn = quat.to_matrix(pose.rotations[owners])  # (L, 3, 3): owner frame -> world
            inertia = np.einsum("lji,ljk,lkm->lim", turn, world, turn)
        return cls(skeleton.names, tuple(link.name for link in links), owners, offsets, masses, inertia=inertia)

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
            (see :mod:`mocaplab.anatomy`, "Support-polygon points").
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
        """:meth:`with_feet` with the feet and the reference pose resolved (the points: :mod:`mocaplab.anatomy`)."""
        return dataclasses.replace(self, **_support_points(skeleton, pose, feet, roles, foot_width, heel)._asdict())

    def with_masses(self, masses: ArrayLike) -> Body:
        """The same body with other link masses (kilograms, shape (L,)); each link's :attr:`inertia` scales with its mass."""
        new = np.asarray(masses, dtype=float)
        if self.inertia is None or new.shape != self.masses.shape:
            return dataclasses.replace(self, masses=new)
        return dataclasses.replace(self, masses=new, inertia=self.inertia * (new / self.masses)[:, None, None])

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


def link_positions(motion: Motion, body: Body, *, fk: tuple[Array, Array] | None = None) -> Array:
    """World positions of the link centres, shape (F, L, 3).

    Parameters
    ----------
    motion : Motion
    body : Body
    fk : (ndarray (F, J, 4), ndarray (F, J, 3)), optional
        The motion's global rotations and global positions when already at hand.

    Returns
    -------
    ndarray, shape (F, L, 3)
        Metres.

    Examples
    --------
    >>> import mocaplab as ml
    >>> walk = ml.cmu("16_15").resample(30)[:60]
    >>> body = ml.physics.Body.from_skeleton(walk.skeleton)
    >>> ml.physics.link_positions(walk, body).shape
    (60, 17, 3)
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

    Examples
    --------
    A ballistic height ``1 - 4.9 t^2`` comes out with its exact acceleration, ends included:

    >>> import numpy as np
    >>> from mocaplab.physics import smoothed_derivatives
    >>> t = np.arange(30) / 30.0
    >>> _, _, acc = smoothed_derivatives(1 - 4.9 * t**2, 30.0, width=5)
    >>> acc[[0, 15, 29]].round(6).tolist()
    [-9.8, -9.8, -9.8]
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
    """Centre of mass on every frame (equation 1), shape (F, 3).

    Parameters
    ----------
    motion : Motion
    body : Body
        Its joint names must match the motion's skeleton.

    Returns
    -------
    ndarray, shape (F, 3)
        Metres.

    Examples
    --------
    >>> import mocaplab as ml
    >>> walk = ml.cmu("16_15").resample(30)[:60]
    >>> body = ml.physics.Body.from_skeleton(walk.skeleton)
    >>> ml.physics.center_of_mass(walk, body)[0].round(3).tolist()
    [0.082, 0.937, -1.491]
    """
    r = link_positions(motion, body)
    return np.einsum("l,flc->fc", body.masses, r) / body.total_mass


def _smoothing(motion: Motion, width: float | None) -> float:
    return paper_width(5.0, motion.fps) if width is None else float(width)


def linear_momentum(motion: Motion, body: Body, *, width: float | None = None) -> Array:
    """Linear momentum ``sum m_i v_i`` (kg m/s), shape (F, 3).

    Velocities are central differences of positions smoothed with a
    Gaussian of ``width`` frames (default 5 frames at 30 fps, scaled to the
    clip's rate; see :func:`smoothed_derivatives`).

    Parameters
    ----------
    motion : Motion
    body : Body
    width : float, optional
        Smoothing width in frames of this clip.

    Returns
    -------
    ndarray, shape (F, 3)
        kg m/s.

    Examples
    --------
    Divided by the mass, the walker's speed: about 1 m/s along z.

    >>> import mocaplab as ml
    >>> walk = ml.cmu("16_15").resample(30)[:60]
    >>> body = ml.physics.Body.from_skeleton(walk.skeleton)
    >>> (ml.physics.linear_momentum(walk, body)[30] / body.total_mass).round(2).tolist()
    [-0.01, -0.1, 1.04]
    """
    _, v, _ = smoothed_derivatives(link_positions(motion, body), motion.fps, width=_smoothing(motion, width))
    return np.einsum("l,flc->fc", body.masses, v)


Inertia = Literal["points", "segments"]


def check_inertia(inertia: object, body: Body | None = None) -> Inertia:
    """The ``inertia=`` option read as everywhere: ``"points"`` or ``"segments"`` (with a ``body``: one with :attr:`Body.inertia`).

    Raises ValueError naming what was expected and what was given.
    """
    if inertia not in ("points", "segments"):
        raise ValueError(
            f'Expected `inertia` to be "points" (the paper\'s point masses) or "segments" (each link a rigid '
            f"segment with de Leva's radii of gyration), got {inertia!r}"
        )
    if inertia == "segments" and body is not None and body.inertia is None:
        raise ValueError(
            'inertia="segments" needs a body with segment inertia (Body.inertia); this body has none: build it '
            "with Body.from_skeleton, or give Body(..., inertia=...)"
        )
    return inertia  # type: ignore[return-value]  # checked above


def _segment_spin(motion: Motion, body: Body, width: float, fk: tuple[Array, Array] | None = None) -> Array:
    """The links' own spin, ``sum R I R^T w`` over the links (kg m^2/s), shape (F, 3).

    ``R`` the owner's global rotation, ``I`` the link's :attr:`Body.inertia`
    in the owner's frame, ``w`` the owner's angular velocity (central
    differences, :func:`mocaplab.kinematics.angular_velocities`, smoothed by
    the Gaussian of ``width`` frames that smooths the link positions).
    """
    if body.inertia is None:
        raise ValueError("Expected a body with segment inertia (Body.inertia), got None")
    grot = motion.global_rotations() if fk is None else fk[0]
    owners = np.unique(body.owners)
    q = grot[:, owners]
    w = angular_velocities(q, motion.fps)
    std = max(float(width), 0.0) / 4.0
    if std > 0:
        w = gaussian_filter1d(w, std, axis=0, mode="nearest", truncate=2.0)
    rot = quat.to_matrix(q)  # (F, K, 3, 3)
    column = np.searchsorted(owners, body.owners)
    by_owner = np.zeros((len(owners), 3, 3))
    np.add.at(by_owner, column, body.inertia)
    local = np.einsum("fkji,fkj->fki", rot, w)  # angular velocity in the owner's frame
    return np.einsum("fkij,fkj->fi", rot, np.einsum("kij,fkj->fki", by_owner, local))


def angular_momentum(
    motion: Motion,
    body: Body,
    *,
    about: ArrayLike | str = "com",
    width: float | None = None,
    inertia: Inertia = "points",
) -> Array:
    """Angular momentum of the body (equation 2), kg m^2/s, shape (F, 3).

    Parameters
    ----------
    motion : Motion
    body : Body
    about : "com" or array_like, shape (3,) or (F, 3)
        Reference point: the centre of mass (default, ``h_CM`` of the paper)
        or fixed/per-frame points.
    width : float, optional
        Smoothing width in frames (default 5 frames at 30 fps).
    inertia : "points" or "segments"
        ``"points"`` (default): the paper's point masses,
        ``sum m_i (r_i - c) x v_i``.  ``"segments"``: each link a rigid
        segment, adding its own spin ``R I R^T w`` (:attr:`Body.inertia`,
        de Leva's radii of gyration; ``w`` the angular velocity of the joint
        the link moves with).

    Returns
    -------
    ndarray, shape (F, 3)
        kg m^2/s.

    Examples
    --------
    >>> import mocaplab as ml
    >>> walk = ml.cmu("16_15").resample(30)[:60]
    >>> body = ml.physics.Body.from_skeleton(walk.skeleton)
    >>> ml.physics.angular_momentum(walk, body).shape
    (60, 3)

    The segments' own spin adds a little to the walk's (kg m^2/s, mean magnitude):

    >>> import numpy as np
    >>> h = ml.physics.angular_momentum(walk, body, inertia="segments")
    >>> spin = h - ml.physics.angular_momentum(walk, body)
    >>> bool(0 < np.linalg.norm(spin, axis=1).mean() < np.linalg.norm(h, axis=1).mean())
    True
    """
    inertia = check_inertia(inertia, body)
    w = _smoothing(motion, width)
    s, v, _ = smoothed_derivatives(link_positions(motion, body), motion.fps, width=w)
    m = body.masses
    if isinstance(about, str):
        if about != "com":
            raise ValueError(f"Expected `about` to be 'com' or points of shape (3,) or (F, 3), got {about!r}")
        ref = np.einsum("l,flc->fc", m, s) / m.sum()
    else:
        ref = np.broadcast_to(np.asarray(about, dtype=float), (motion.n_frames, 3))
    h = np.einsum("l,flc->fc", m, np.cross(s - ref[:, None], v))
    return h + _segment_spin(motion, body, w) if inertia == "segments" else h
