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
Links are found by joint names, for the CMU 31-joint skeleton of the BVH
clips and the Daz skeleton of the CMU salsa clips.  A link centre is the
midpoint of two skeleton points in the rest pose, expressed in the owner's
frame:

* limbs: the bone from the joint to its child (thigh ``LeftUpLeg`` to
  ``LeftLeg``, foot from the ankle to the ball of the foot, hand from the
  wrist to the knuckles);
* lower trunk: owned by the root, centred between the hip-joint midpoint
  and the root (de Leva puts it 61 % of the way from the navel down to the
  hip joints);
* middle trunk: CMU splits it over two vertebral bones, ``LowerBack`` and
  ``Spine``, which get half of it each; Daz has one, ``abdomen``;
* upper trunk: ``Spine1`` (CMU thorax) or ``chest`` (Daz) to the neck base;
* head and neck: one link from the neck base to the top of the head (CMU,
  owned by ``Neck1``) or to the eyes (Daz, owned by ``head``);
* clavicles, toes, fingers and eyes carry no mass of their own.

Support-polygon points
---------------------
A planted foot touches the ground at a heel point behind the ankle and at
toe points (the ball and the toe tip); ``foot_width`` spreads the ball and
heel points sideways (plus and minus half the width at the ball, a third at
the heel).  A planted joint without foot geometry contributes its own
position.

Conventions are those of :mod:`mocaplab.motion`: metres, seconds, Y up,
ground y = 0, kilograms.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping, Sequence
from functools import lru_cache
from types import MappingProxyType

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy import sparse
from scipy.ndimage import gaussian_filter1d

from .. import quat
from ..motion import Motion, Skeleton, mirror_name

__all__ = [
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
        Two skeleton points whose rest-pose midpoint is the link centre; each
        point is the mean of the named joints, ``"Joint:end"`` naming the end
        site of ``Joint``.
    """

    name: str
    segment: str
    share: float
    owner: str
    a: tuple[str, ...]
    b: tuple[str, ...]


def _limbs(side: str, names: Mapping[str, str]) -> list[LinkSpec]:
    s = side
    return [
        LinkSpec(f"{s}_upper_arm", "upper_arm", 1.0, names["arm"], (names["arm"],), (names["forearm"],)),
        LinkSpec(f"{s}_forearm", "forearm", 1.0, names["forearm"], (names["forearm"],), (names["hand"],)),
        LinkSpec(f"{s}_hand", "hand", 1.0, names["hand"], (names["hand"],), (names["knuckles"],)),
        LinkSpec(f"{s}_thigh", "thigh", 1.0, names["thigh"], (names["thigh"],), (names["shank"],)),
        LinkSpec(f"{s}_shank", "shank", 1.0, names["shank"], (names["shank"],), (names["foot"],)),
        LinkSpec(f"{s}_foot", "foot", 1.0, names["foot"], (names["foot"],), (names["ball"],)),
    ]


def _cmu_links() -> list[LinkSpec]:
    trunk = [
        LinkSpec("pelvis", "lower_trunk", 1.0, "Hips", ("LeftUpLeg", "RightUpLeg"), ("Hips",)),
        LinkSpec("lower_back", "middle_trunk", 0.5, "LowerBack", ("LowerBack",), ("Spine",)),
        LinkSpec("upper_back", "middle_trunk", 0.5, "Spine", ("Spine",), ("Spine1",)),
        LinkSpec("thorax", "upper_trunk", 1.0, "Spine1", ("Spine1",), ("Neck",)),
        LinkSpec("head", "head_neck", 1.0, "Neck1", ("Neck",), ("Head:end",)),
    ]
    limbs = []
    for side, p in (("left", "Left"), ("right", "Right")):
        limbs += _limbs(
            side,
            {
                "arm": f"{p}Arm",
                "forearm": f"{p}ForeArm",
                "hand": f"{p}Hand",
                "knuckles": f"{p}HandIndex1",
                "thigh": f"{p}UpLeg",
                "shank": f"{p}Leg",
                "foot": f"{p}Foot",
                "ball": f"{p}ToeBase",
            },
        )
    return trunk + limbs


def _daz_links() -> list[LinkSpec]:
    trunk = [
        LinkSpec("pelvis", "lower_trunk", 1.0, "hip", ("lThigh", "rThigh"), ("hip",)),
        LinkSpec("abdomen", "middle_trunk", 1.0, "abdomen", ("abdomen",), ("chest",)),
        LinkSpec("thorax", "upper_trunk", 1.0, "chest", ("chest",), ("neck",)),
        LinkSpec("head", "head_neck", 1.0, "head", ("neck",), ("leftEye", "rightEye")),
    ]
    limbs = []
    for side, p in (("left", "l"), ("right", "r")):
        limbs += _limbs(
            side,
            {
                "arm": f"{p}Shldr",
                "forearm": f"{p}ForeArm",
                "hand": f"{p}Hand",
                "knuckles": f"{p}Mid1",
                "thigh": f"{p}Thigh",
                "shank": f"{p}Shin",
                "foot": f"{p}Foot",
                "ball": f"{p}Foot:end",
            },
        )
    return trunk + limbs


# (ankle joint, ball/toe joint or None, toe-tip point) per foot and skeleton
_FEET = {
    "cmu": (("LeftFoot", "LeftToeBase", "LeftToeBase:end"), ("RightFoot", "RightToeBase", "RightToeBase:end")),
    "daz": (("lFoot", None, "lFoot:end"), ("rFoot", None, "rFoot:end")),
}
_LINKS = {"cmu": _cmu_links, "daz": _daz_links}


def _detect(skeleton: Skeleton) -> str:
    names = set(skeleton.names)
    missing: dict[str, list[str]] = {}
    for kind, make in _LINKS.items():
        needed = set()
        for spec in make():
            needed.add(spec.owner)
            needed.update(p.split(":")[0] for p in spec.a + spec.b)
        miss = sorted(needed - names)
        if not miss:
            return kind
        missing[kind] = miss
    raise ValueError(
        "Could not map the skeleton onto a body model by joint names: "
        + "; ".join(f"{k} skeleton lacks {v[:6]}" for k, v in missing.items())
        + ". Build one with Body.from_links(skeleton, [LinkSpec(...), ...])."
    )


def _rest_points(skeleton: Skeleton) -> tuple[Array, Array]:
    """Rest-pose world positions of the joints (J, 3) and end sites (E, 3)."""
    pos = np.zeros((skeleton.n_joints, 3))
    for j in range(1, skeleton.n_joints):
        pos[j] = pos[skeleton.parents[j]] + skeleton.offsets[j]
    ends = pos[skeleton.end_site_parents] + skeleton.end_site_offsets
    return pos, ends


def _point(skeleton: Skeleton, rest: tuple[Array, Array], spec: str) -> Array:
    joints, ends = rest
    if spec.endswith(":end"):
        j = skeleton.index(spec[:-4])
        hits = np.flatnonzero(skeleton.end_site_parents == j)
        if hits.size == 0:
            raise ValueError(f"Joint {spec[:-4]!r} has no end site (point {spec!r})")
        return ends[hits[0]]
    return joints[skeleton.index(spec)]


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
        (``"LeftFoot"`` for heel points, ``"LeftToeBase"`` for toe points).
    point_owners : array_like of int, shape (P,)
    point_offsets : array_like, shape (P, 3)
        Support point in its owner's local frame.

    Use :meth:`from_skeleton` to build one from a CMU or Daz skeleton.

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
        for name, arr in (("owners", owners), ("offsets", offsets), ("masses", masses), ("point_owners", po), ("point_offsets", pof)):
            arr = np.array(arr, copy=True)
            arr.flags.writeable = False
            object.__setattr__(self, name, arr)
        object.__setattr__(self, "joint_names", jn)
        object.__setattr__(self, "link_names", ln)
        object.__setattr__(self, "point_joints", pj)

    # ---------------------------------------------------------- builders
    @classmethod
    def from_skeleton(
        cls,
        skeleton: Skeleton | Motion,
        *,
        total_mass: float = DEFAULT_TOTAL_MASS,
        table: Mapping[str, float] = DE_LEVA_MALE,
        foot_width: float = 0.09,
        heel: float = 0.05,
    ) -> Body:
        """The default body of a CMU or Daz skeleton (found by joint names).

        Parameters
        ----------
        skeleton : Skeleton or Motion
        total_mass : float
            Body mass in kilograms; the table's percentages are scaled to it.
        table : mapping of str to float
            Segment masses in percent (default :data:`DE_LEVA_MALE`).
        foot_width : float
            Width of the foot's support outline in metres (0 gives the
            heel-to-toe line of the paper's description).
        heel : float
            How far the heel point lies behind the ankle, metres.

        Returns
        -------
        Body
        """
        sk = getattr(skeleton, "skeleton", skeleton)
        if not isinstance(sk, Skeleton):
            raise TypeError(f"Expected `skeleton` to be a Skeleton or Motion, got {type(skeleton).__name__}")
        kind = _detect(sk)
        body = cls.from_links(sk, _LINKS[kind](), total_mass=total_mass, table=table)
        return body.with_feet(sk, _FEET[kind], foot_width=foot_width, heel=heel)

    @classmethod
    def from_links(
        cls,
        skeleton: Skeleton,
        links: Sequence[LinkSpec],
        *,
        total_mass: float = DEFAULT_TOTAL_MASS,
        table: Mapping[str, float] = DE_LEVA_MALE,
    ) -> Body:
        """A body from explicit link specifications (no support points).

        Masses are ``total_mass * table[segment] / 100 * share``; they are not
        renormalised, so a partial mapping has less than ``total_mass``.
        """
        if not np.isfinite(total_mass) or total_mass <= 0:
            raise ValueError(f"Expected `total_mass` > 0 kilograms, got {total_mass!r}")
        rest = _rest_points(skeleton)
        owners, offsets, masses, names = [], [], [], []
        for spec in links:
            if spec.segment not in table:
                raise KeyError(f"Segment {spec.segment!r} of link {spec.name!r} is not in the mass table {sorted(table)}")
            j = skeleton.index(spec.owner)
            a = np.mean([_point(skeleton, rest, p) for p in spec.a], axis=0)
            b = np.mean([_point(skeleton, rest, p) for p in spec.b], axis=0)
            owners.append(j)
            # rest rotations are identities: a rest vector is the local offset
            offsets.append(0.5 * (a + b) - rest[0][j])
            masses.append(total_mass * table[spec.segment] / 100.0 * spec.share)
            names.append(spec.name)
        return cls(skeleton.names, tuple(names), np.array(owners), np.array(offsets), np.array(masses))

    def with_feet(
        self,
        skeleton: Skeleton,
        feet: Sequence[tuple[str, str | None, str]],
        *,
        foot_width: float = 0.09,
        heel: float = 0.05,
    ) -> Body:
        """This body with heel and toe support points for each foot.

        Parameters
        ----------
        skeleton : Skeleton
        feet : sequence of (ankle, toe joint or None, toe-tip point)
            The toe-tip point is a joint name or ``"Joint:end"``.
        foot_width, heel : float
            See :meth:`from_skeleton`.
        """
        if not np.isfinite(foot_width) or foot_width < 0:
            raise ValueError(f"Expected `foot_width` >= 0 metres, got {foot_width!r}")
        if not np.isfinite(heel) or heel < 0:
            raise ValueError(f"Expected `heel` >= 0 metres, got {heel!r}")
        rest = _rest_points(skeleton)
        pj: list[str] = []
        po: list[int] = []
        pof: list[Array] = []
        up = np.array([0.0, 1.0, 0.0])
        for ankle, toe, tip in feet:
            ja = skeleton.index(ankle)
            pa = rest[0][ja]
            ptip = _point(skeleton, rest, tip)
            ball = rest[0][skeleton.index(toe)] if toe is not None else pa + 0.7 * (ptip - pa)
            fwd = ball - pa
            fwd[1] = 0.0
            norm = np.linalg.norm(fwd)
            fwd = fwd / norm if norm > 1e-9 else np.array([0.0, 0.0, 1.0])
            side = np.cross(up, fwd)
            heel_pt = pa - heel * fwd
            hw = foot_width / 3.0
            for s in (-hw, hw) if hw > 0 else (0.0,):
                pj.append(ankle)
                po.append(ja)
                pof.append(heel_pt + s * side - pa)
            owner = skeleton.index(toe) if toe is not None else ja
            base = rest[0][owner]
            bw = foot_width / 2.0
            for s in (-bw, bw) if bw > 0 else (0.0,):
                pj.append(toe if toe is not None else ankle)
                po.append(owner)
                pof.append(ball + s * side - base)
            pj.append(toe if toe is not None else ankle)
            po.append(owner)
            pof.append(ptip - base)
        return dataclasses.replace(
            self, point_joints=tuple(pj), point_owners=np.array(po, dtype=np.int64), point_offsets=np.array(pof)
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
        o, offsets, column = self._support_layout(motion.skeleton, tuple(joints))
        grot, gpos = (motion.global_rotations(), motion.global_positions()) if fk is None else fk
        pts = gpos[:, o] + quat.rotate(grot[:, o], offsets)
        return pts, column

    def _support_layout(self, skeleton: Skeleton, joints: tuple[str, ...]) -> tuple[NDArray[np.int64], Array, NDArray[np.int64]]:
        key = (id(skeleton), joints)
        cache = self.__dict__.setdefault("_layout_cache", {})
        if key in cache:
            return cache[key]
        owners: list[int] = []
        offsets: list[Array] = []
        column: list[int] = []
        for k, name in enumerate(joints):
            hits = [i for i, pj in enumerate(self.point_joints) if pj == name]
            if hits:
                owners.extend(int(self.point_owners[i]) for i in hits)
                offsets.extend(self.point_offsets[i] for i in hits)
                column.extend([k] * len(hits))
            else:
                owners.append(skeleton.index(name))
                offsets.append(np.zeros(3))
                column.append(k)
        out = (np.array(owners, dtype=np.int64), np.array(offsets).reshape(-1, 3), np.array(column, dtype=np.int64))
        cache[key] = out
        return out


# ---------------------------------------------------------------- kinematics
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
    out = np.vander(np.asarray(at, dtype=float), deg + 1) @ np.linalg.pinv(basis)
    out.flags.writeable = False
    return out


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

