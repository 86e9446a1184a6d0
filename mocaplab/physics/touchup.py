"""Physical touch-up of edited motions (Shin, Kovar and Gleicher 2003).

A touch-up is a sequence of **adjustments** (a *schedule*).  Each adjustment
names three link sets (section 3.1): S1 is left alone, S2 is rotated, S3 is
carried along by S2 but keeps its global orientation; a time scale
``sigma`` and a damping factor ``rho``.  One step (Figure 2):

1. on every frame independently, compute the rotation of S2 that best
   satisfies the physical law of the frame's stage:

   * **ground frames** (section 3.3): the rotation that brings the ZMP onto
     its projection on the support polygon, about a horizontal axis
     perpendicular to the correction, by the closed form of equations 6-7
     (coefficients of the Appendix, computed here as per-link sums);
   * **flight frames** (section 3.4): first the rotation giving the
     average angular momentum of the flight (equations 8-9), then the
     translation or rotation putting the centre of mass on the parabola
     with ``v0 = d / T - g T / 2``;

2. scale it by ``rho`` and smooth it over time with a Gaussian kernel of
   width ``sigma`` (the rotation as a world rotation vector, i.e. the
   logarithm of the displacement relative to the identity, which is how
   Lee and Shin filter orientation displacements; the root translation
   linearly);
3. apply it as a displacement map (S2's top joint rotated, S3's top joint
   counter-rotated) and re-enforce the footplants.

Choices made where the paper leaves them open
---------------------------------------------
* Link sets are given by joint names (each name means the joint and its
  descendants) or presets ``"lower_body"``, ``"upper_body"``, ``"arms"``,
  ``"all"``, found from the joint roles of any skeleton (see
  :func:`preset_mask`; ``roles=`` overrides them); S3 overrides S2 and S1
  is everything else.  One rotation angle is shared by all parts of S2
  (e.g. both arms), each turning about its own top joint.
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
* The per-frame ground angle is clamped to +-0.35 rad (20 degrees), a guard
  against frames with absurd accelerations.
* Kernel widths and windows are stored in seconds: the paper's 40/20/10 and
  10/10/5 frames and its 15-frame flight window were at 30 fps.  A kernel of
  width ``w`` is a Gaussian of standard deviation ``w / 4`` truncated at two
  standard deviations.  Near the ends of the clip the kernel is cut at the
  first or last frame and renormalised (a weighted mean over the frames
  that exist): extending the edge value instead (``mode="nearest"``) gives
  an end frame up to half the kernel's weight, so one badly balanced end
  frame (a foot landing or taking off as the capture starts or stops, an
  acceleration estimated from one side) leaned the whole start or end of
  a captured walk by many centimetres (CMU 02_01: joints moved 2.5 cm on
  average after three passes instead of 1.2 cm).
* Equation 9 relates consecutive frames; the angular-velocity correction
  ``I^-1 (h* - h)`` is therefore **integrated** over the flight (from the
  middle of the flight outwards) to give each frame's rotation, so that the
  corrected motion really has the target angular velocity.  The paper's
  footnote writes the inertia of point masses as ``sum m r r^T``; the
  inertia tensor ``sum m (|r|^2 I - r r^T)`` is used here.
* Ground frames within ``flight_window`` (0.5 s) of a flight, and no
  further than half-way to the next flight, keep the flight's boundary
  adjustment, blended to zero with a raised cosine (Figure 4); the ground
  adjustments still apply to them.  The parabola's correction is zero at
  both ends of a flight, so only the angular-momentum rotation and the
  S2 rotation of a non-empty S1 are carried into the windows.  (Continuing
  them with their boundary slope was tried: it makes take-off and landing
  far less balanced.)
* Footplants are re-enforced after every step that can move a contact
  joint (an adjustment of the upper body or the arms leaves the feet
  alone), per frame like the paper's choice (Kovar et al. 2002, "because
  of its efficiency").  There is one correction layer: footplants are
  goals (:class:`mocaplab.refinement.Goal`), built once from the input's
  contacts in :func:`start`, and met after each step by the refinement
  module's IK layer (:func:`mocaplab.refinement.solve_goals`: two-bone IK
  of the legs, then each foot turned about its ankle toward its toe goal)
  without root lowering.  The options differ in the goals only:

  - ``"plant"`` (what ``"auto"`` picks): the plant goals of
    :func:`mocaplab.refinement.foot_goals`, one plant position per contact
    interval of the input, blended in and out over 0.05 s (shorter than
    refine's default, so that corrections leak little into flight frames);
  - ``"ik"``: each planted joint back where the input motion had it, frame
    by frame (targets the input's positions, weights
    :func:`mocaplab.refinement.blend_weights` over 0.2 s around the frames
    where its foot is planted); the ankle's orientation is the IK layer's
    (the foot keeps its turn about the ankle-to-toe axis);
  - ``"refine"``: the full :func:`mocaplab.refinement.refine`, which also
    lowers the root where a leg cannot reach and smooths the corrections
    with a displacement map; both leak into flight frames and bend the
    ballistic centre-of-mass path again (on the CMU hops of 49_03 the fitted
    gravity of a short flight drops by about 15 %), so it is not the default;
  - ``None`` skips the step.

* Speed: the forward kinematics of the current motion travel with the
  state; after an adjustment they follow in closed form (S2 moves rigidly,
  carried parts translate: one batched matrix product for all parts), the
  IK layer hands back the legs' recomputed transforms.  Contacts and plant
  goals are computed once, from the input, in :func:`start`.  After each
  step the ZMP analysis is redone only for the
  links whose joints moved (an arm adjustment leaves the legs' link
  centres, their smoothed accelerations and the support polygons as they
  were; the numbers are identical to a fresh :func:`balance`).  The ZMP's
  smoothed positions and accelerations are one product with a cached
  sparse operator.

Examples
--------
>>> from mocaplab.data import cmu                               # doctest: +SKIP
>>> from mocaplab.physics import touch_up                       # doctest: +SKIP
>>> history = touch_up(cmu("16_15").resample(30), iterations=2)  # doctest: +SKIP
>>> history.mean_zmp_distance                                   # doctest: +SKIP
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable, Mapping, Sequence
from functools import lru_cache
from typing import TYPE_CHECKING, Any, Literal, NamedTuple

import numpy as np
from numpy.typing import NDArray
from scipy.ndimage import gaussian_filter1d

from .. import quat
from ..contacts import intervals_from_mask
from ..motion import Motion, Skeleton, _owned
from ..refinement import Goal, _solve_goals, blend_weights, foot_goals, refine
from ..roles import Roles, RolesError, resolve_roles
from .body import GRAVITY, Body, link_positions, paper_width, smoothed_derivatives
from .zmp import Balance, _check_contacts, _rebalance, balance, default_contacts

if TYPE_CHECKING:  # pragma: no cover
    from ..contacts import Contacts

__all__ = [
    "Adjustment",
    "GROUND_SCHEDULE",
    "FLIGHT_SCHEDULE",
    "default_schedule",
    "LinkSets",
    "link_sets",
    "preset_mask",
    "flight_stages",
    "TouchUpState",
    "TouchUpHistory",
    "start",
    "step",
    "touch_up",
    "TouchUpSession",
]

Array = NDArray[np.float64]
Stage = Literal["ground", "flight"]
Footplants = Literal["auto", "plant", "refine", "ik"] | Callable[[Motion, "Contacts", Motion], Motion] | None

#: Largest per-frame ground rotation, radians.
MAX_GROUND_ANGLE = 0.35
#: Blend window of the ``"ik"`` footplant goals on each side of a plant, seconds.
FOOT_BLEND = 0.2
#: Blend window of the plant goals on each side of a contact, seconds (short,
#: so that plant corrections leak little into flight frames).
PLANT_BLEND = 0.05


# ======================================================================
# schedules
# ======================================================================
@dataclasses.dataclass(frozen=True)
class Adjustment:
    """One step of a touch-up schedule.

    Parameters
    ----------
    s2 : tuple of str
        Rotated links: joint names (each with its descendants) or presets
        ``"lower_body"``, ``"upper_body"``, ``"arms"``, ``"all"``.
    s3 : tuple of str
        Links carried by S2 that keep their global orientation (empty in
        flight).  S1 is every joint in neither set.
    sigma : float
        Width of the smoothing kernel in seconds (the paper's 40 frames at
        30 fps is 4/3 s).
    rho : float
        Damping factor in (0, 1]: the share of the computed adjustment used.
    stage : {"ground", "flight"}
        Which frames this adjustment corrects.
    label : str
        A short description for displays.
    """

    s2: tuple[str, ...]
    s3: tuple[str, ...] = ()
    sigma: float = 40.0 / 30.0
    rho: float = 0.5
    stage: Stage = "ground"
    label: str = ""

    def __post_init__(self) -> None:
        s2 = (self.s2,) if isinstance(self.s2, str) else tuple(str(s) for s in self.s2)
        s3 = (self.s3,) if isinstance(self.s3, str) else tuple(str(s) for s in self.s3)
        if not s2:
            raise ValueError("Expected at least one joint name or preset in `s2`, got none")
        if not (np.isfinite(self.sigma) and self.sigma >= 0):
            raise ValueError(f"Expected `sigma` >= 0 seconds, got {self.sigma!r}")
        if not (np.isfinite(self.rho) and 0 < self.rho <= 1):
            raise ValueError(f"Expected `rho` in (0, 1], got {self.rho!r}")
        if self.stage not in ("ground", "flight"):
            raise ValueError(f"Expected `stage` to be 'ground' or 'flight', got {self.stage!r}")
        if self.stage == "flight" and s3:
            raise ValueError(f"Expected an empty `s3` for a flight adjustment (section 3.4), got {s3}")
        object.__setattr__(self, "s2", s2)
        object.__setattr__(self, "s3", s3)
        object.__setattr__(self, "sigma", float(self.sigma))
        object.__setattr__(self, "rho", float(self.rho))
        if not self.label:
            text = f"{self.stage}: S2 {'+'.join(s2)}" + (f", S3 {'+'.join(s3)}" if s3 else "")
            object.__setattr__(self, "label", text)

    def replace(self, **changes: object) -> Adjustment:
        """A copy with some fields changed (the label is rebuilt when the link sets or stage change)."""
        new = dataclasses.replace(self, **changes)  # type: ignore[arg-type]
        if "label" not in changes and (new.s2, new.s3, new.stage) != (self.s2, self.s3, self.stage):
            new = dataclasses.replace(new, label="")
        return new

    def width(self, fps: float) -> float:
        """Kernel width in frames at ``fps``."""
        return self.sigma * float(fps)


#: The paper's ground schedule (section 4.1): lean with the lower body
#: (upper body keeps its orientation), then the upper body, then the arms.
GROUND_SCHEDULE: tuple[Adjustment, ...] = (
    Adjustment(("lower_body",), ("upper_body",), 40 / 30, 0.5, "ground", "ground: lower body (S2), upper body (S3)"),
    Adjustment(("upper_body",), (), 20 / 30, 0.3, "ground", "ground: upper body (S2)"),
    Adjustment(("arms",), (), 10 / 30, 0.2, "ground", "ground: arms (S2)"),
)

#: The paper's flight schedule (section 4.1): lower body, upper body, all.
FLIGHT_SCHEDULE: tuple[Adjustment, ...] = (
    Adjustment(("lower_body",), (), 10 / 30, 0.3, "flight", "flight: lower body (S2)"),
    Adjustment(("upper_body",), (), 10 / 30, 0.3, "flight", "flight: upper body (S2)"),
    Adjustment(("all",), (), 5 / 30, 1.0, "flight", "flight: whole body (S2)"),
)


def default_schedule(
    stage: Literal["ground", "flight", "both"] = "both", *, contacts: Contacts | None = None
) -> tuple[Adjustment, ...]:
    """The paper's default schedules.

    ``stage="both"`` gives the ground schedule followed by the flight one;
    with ``contacts`` given, the flight part is left out when the clip has
    no flight frame.
    """
    if stage == "ground":
        return GROUND_SCHEDULE
    if stage == "flight":
        return FLIGHT_SCHEDULE
    if stage != "both":
        raise ValueError(f"Expected `stage` 'ground', 'flight' or 'both', got {stage!r}")
    if contacts is not None and not flight_stages(contacts):
        return GROUND_SCHEDULE
    return GROUND_SCHEDULE + FLIGHT_SCHEDULE


def _as_schedule(schedule: str | Adjustment | Sequence[Adjustment], contacts: Contacts) -> tuple[Adjustment, ...]:
    if isinstance(schedule, str):
        if schedule == "default":
            return default_schedule("both", contacts=contacts)
        if schedule in ("ground", "flight", "both"):
            return default_schedule(schedule, contacts=contacts if schedule == "both" else None)  # type: ignore[arg-type]
        raise ValueError(f"Expected `schedule` 'default', 'ground', 'flight' or a sequence of Adjustment, got {schedule!r}")
    if isinstance(schedule, Adjustment):
        return (schedule,)
    out = tuple(schedule)
    if not out or not all(isinstance(a, Adjustment) for a in out):
        raise TypeError(f"Expected `schedule` to be a non-empty sequence of Adjustment, got {schedule!r}")
    return out


# ======================================================================
# link sets
# ======================================================================
PRESETS = ("lower_body", "upper_body", "arms", "all")


def _subtree(skeleton: Skeleton, j: int) -> NDArray[np.bool_]:
    mask = np.zeros(skeleton.n_joints, dtype=bool)
    mask[j] = True
    for k in range(j + 1, skeleton.n_joints):
        if mask[skeleton.parents[k]]:
            mask[k] = True
    return mask


def preset_mask(skeleton: Skeleton, name: str, *, roles: Mapping[str, Any] | None = None) -> NDArray[np.bool_]:
    """Joints of a preset (or of a joint's subtree), shape (J,) bool.

    Presets come from the joint roles (:mod:`mocaplab.roles`):
    ``"upper_body"`` is the subtree of the joint above the pelvis on the way
    to the neck (the first spine joint, or the neck when the spine role is
    empty: ``LowerBack`` on CMU, ``abdomen`` on Daz), ``"lower_body"``
    everything else (the root, the pelvis, the legs, and a static reference
    joint above the pelvis if there is one), ``"arms"`` the subtrees of
    both upper-arm joints (the ``shoulder`` roles), ``"all"`` every joint.
    Any other string must be a joint name: that joint and its descendants.

    Parameters
    ----------
    skeleton : Skeleton
    name : str
    roles : mapping of role names to joint names, optional
        Role overrides (:func:`mocaplab.roles.resolve_roles`).
    """
    if name == "all":
        return np.ones(skeleton.n_joints, dtype=bool)
    if name in ("upper_body", "lower_body"):
        r = resolve_roles(skeleton, roles)
        r.require("pelvis", "neck", purpose=f"the {name!r} preset")
        pelvis, neck = r.index("pelvis"), r.index("neck")
        try:
            chain = skeleton.chain(pelvis, neck)
        except ValueError:
            chain = []
        if len(chain) < 2:
            raise RolesError(
                f"The {name!r} preset needs the neck {r['neck']!r} below the pelvis {r['pelvis']!r}; "
                "give the roles with roles={'pelvis': ..., 'neck': ...} or name the joints"
            )
        upper = _subtree(skeleton, chain[1])
        return upper if name == "upper_body" else ~upper
    if name == "arms":
        r = resolve_roles(skeleton, roles)
        r.require("left_shoulder", "right_shoulder", purpose="the 'arms' preset")
        left, right = r.indices("left_shoulder", "right_shoulder")
        return _subtree(skeleton, left) | _subtree(skeleton, right)
    if name not in skeleton.names:
        raise KeyError(f"{name!r} is neither a preset {list(PRESETS)} nor a joint; joints are {list(skeleton.names)}")
    return _subtree(skeleton, skeleton.index(name))


@dataclasses.dataclass(frozen=True, eq=False)
class LinkSets:
    """The S1/S2/S3 split of a skeleton for one adjustment.

    Attributes
    ----------
    roles : ndarray of int, shape (J,)
        1, 2 or 3 per joint.
    s2_tops : tuple of int
        Top joint of each connected part of S2.
    carried : tuple of (int, int)
        ``(joint, part)``: top joints of S3 (or S1) parts hanging below S2
        part ``part``; they are counter-rotated to keep their orientation.
    carried_s1 : tuple of bool
        Whether each carried top is an S1 part (only below a root-holding S2).
    part : ndarray of int, shape (J,)
        S2 part moving each joint (-1 for joints that do not move).
    carried_top : ndarray of int, shape (J,)
        For joints of a carried part, its top joint; -1 elsewhere.
    """

    roles: NDArray[np.int64]
    s2_tops: tuple[int, ...]
    carried: tuple[tuple[int, int], ...]
    carried_s1: tuple[bool, ...]
    part: NDArray[np.int64]
    carried_top: NDArray[np.int64]

    def names(self, skeleton: Skeleton, role: int) -> list[str]:
        """Joint names with the given role (1, 2 or 3)."""
        return [skeleton.names[j] for j in np.flatnonzero(self.roles == role)]


def link_sets(skeleton: Skeleton, adjustment: Adjustment, *, roles: Mapping[str, Any] | None = None) -> LinkSets:
    """Resolve an adjustment's S1/S2/S3 on a skeleton and check its shape.

    ``roles`` overrides joint roles for the presets (see :func:`preset_mask`).
    Raises ValueError when S3 does not hang below S2, when S2 hangs below S3,
    or when an S1 part hangs below an S2 part that does not hold the root.
    Results are cached per skeleton, roles and link sets.
    """
    r = resolve_roles(skeleton, roles)
    return _link_sets(skeleton, adjustment.s2, adjustment.s3, tuple(r.items()))


@lru_cache(maxsize=128)
def _link_sets(
    skeleton: Skeleton, s2: tuple[str, ...], s3: tuple[str, ...], role_items: tuple[tuple[str, Any], ...]
) -> LinkSets:
    n = skeleton.n_joints
    known = Roles(skeleton.names, dict(role_items))
    roles = np.ones(n, dtype=np.int64)
    for name in s2:
        roles[preset_mask(skeleton, name, roles=known)] = 2
    for name in s3:
        roles[preset_mask(skeleton, name, roles=known)] = 3
    if not np.any(roles == 2):
        raise ValueError(f"S2 ({'+'.join(s2)}) is empty on this skeleton (S3 covers it)")
    parents = skeleton.parents
    part = np.full(n, -1, dtype=np.int64)
    tops: list[int] = []
    carried: list[tuple[int, int]] = []
    carried_s1: list[bool] = []
    for j in range(n):
        p = int(parents[j])
        if roles[j] == 2:
            if p < 0 or roles[p] == 1:
                tops.append(j)
                part[j] = len(tops) - 1
            elif roles[p] == 3:
                raise ValueError(f"S2 joint {skeleton.names[j]!r} hangs below S3 joint {skeleton.names[p]!r}")
            else:
                part[j] = part[p]
        elif roles[j] == 3:
            if p < 0 or roles[p] == 1:
                where = "is the root" if p < 0 else f"hangs below S1 joint {skeleton.names[p]!r}"
                raise ValueError(f"S3 must hang below S2, but S3 joint {skeleton.names[j]!r} {where}")
            part[j] = part[p]
            if roles[p] == 2:
                carried.append((j, int(part[p])))
                carried_s1.append(False)
        else:
            if p >= 0 and part[p] >= 0:
                if roles[p] == 2 and tops[int(part[p])] == 0:
                    part[j] = part[p]
                    carried.append((j, int(part[p])))
                    carried_s1.append(True)
                elif roles[p] == 3:
                    raise ValueError(f"S1 joint {skeleton.names[j]!r} hangs below S3 joint {skeleton.names[p]!r}")
                else:
                    part[j] = part[p]
                    if roles[p] == 2:
                        raise ValueError(
                            f"S1 joint {skeleton.names[j]!r} hangs below S2 joint {skeleton.names[p]!r}, "
                            "which does not hold the root: it would move"
                        )
    carried_top = np.full(n, -1, dtype=np.int64)
    for u, _ in carried:
        carried_top[_subtree(skeleton, u)] = u
    for arr in (roles, part, carried_top):
        arr.flags.writeable = False
    return LinkSets(roles, tuple(tops), tuple(carried), tuple(carried_s1), part, carried_top)


# ======================================================================
# stages
# ======================================================================
def flight_stages(contacts: Contacts, *, min_frames: int = 2) -> list[tuple[int, int]]:
    """Half-open frame intervals with no joint planted (at least ``min_frames`` long)."""
    ground = np.asarray(contacts.mask, dtype=bool).any(axis=1)
    edges = np.diff(np.concatenate(([0], (~ground).astype(np.int8), [0])))
    starts, stops = np.flatnonzero(edges == 1), np.flatnonzero(edges == -1)
    return [(int(a), int(b)) for a, b in zip(starts, stops, strict=True) if b - a >= min_frames]


def _flight_windows(n: int, stages: list[tuple[int, int]], window: int) -> list[tuple[int, int, int, int]]:
    """Ground windows ``(lo, a, b, hi)`` around each flight ``[a, b)``.

    At most ``window`` frames on each side, and never more than half of the
    ground gap to the neighbouring flight, so windows do not overlap.
    """
    out = []
    for k, (a, b) in enumerate(stages):
        prev_end = stages[k - 1][1] if k > 0 else None
        next_start = stages[k + 1][0] if k + 1 < len(stages) else None
        lo = max(0, a - window) if prev_end is None else max(a - window, a - (a - prev_end) // 2)
        hi = min(n, b + window) if next_start is None else min(b + window, b + (next_start - b + 1) // 2)
        out.append((lo, a, b, hi))
    return out


def _flight_weights(n: int, stages: list[tuple[int, int]], window: int) -> Array:
    """1 on flight frames, a raised cosine down to 0 over the ground windows around them."""
    w = np.zeros(n)
    for lo, a, b, hi in _flight_windows(n, stages, window):
        w[a:b] = 1.0
        k = np.arange(a - lo, 0, -1)  # distance of frames lo..a-1 from the flight
        w[lo:a] = 0.5 * (1.0 + np.cos(np.pi * k / (window + 1)))
        k = np.arange(1, hi - b + 1)
        w[b:hi] = 0.5 * (1.0 + np.cos(np.pi * k / (window + 1)))
    return w


# ======================================================================
# displacement maps
# ======================================================================
def _smooth(x: Array, width: float) -> Array:
    """Gaussian smoothing over frames (std ``width / 4``, two-std truncation).

    At the ends the kernel is cut to the existing frames and renormalised
    (see the module notes): a normalised convolution, the zero-padded
    filter divided by the filtered ones.
    """
    n = x.shape[0]
    std = width / 4.0
    if std <= 0 or n < 2:
        return x
    out = gaussian_filter1d(x, std, axis=0, mode="constant", truncate=2.0)
    out /= _kernel_mass(n, float(std)).reshape((n,) + (1,) * (x.ndim - 1))
    return out


@lru_cache(maxsize=32)
def _kernel_mass(n: int, std: float) -> Array:
    """Weight of the truncated Gaussian kernel that falls inside ``n`` frames, per frame (n,)."""
    mass = gaussian_filter1d(np.ones(n), std, mode="constant", truncate=2.0)
    mass.flags.writeable = False
    return mass


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
    for arr in out.values():
        arr.flags.writeable = False
    return out


#: Left-multiplication matrix of a quaternion (x, y, z, w): (q g)_i = sum_j
#: _SIGN[i, j] q[_INDEX[i, j]] g_j.
_INDEX = np.array([[3, 2, 1, 0], [2, 3, 0, 1], [1, 0, 3, 2], [0, 1, 2, 3]])
_SIGN = np.array([[1.0, -1.0, 1.0, 1.0], [1.0, 1.0, -1.0, 1.0], [-1.0, 1.0, 1.0, 1.0], [-1.0, -1.0, -1.0, 1.0]])


def _left_matrix(q: Array) -> Array:
    """Matrices (..., 4, 4) with ``L(q) @ g == quat.mul(q, g)``."""
    return q[..., _INDEX] * _SIGN


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
    """
    motion, grot, gpos = posed
    lay = _apply_layout(sets)
    parents = motion.skeleton.parents
    q = quat.exp(omega)
    # the shared rotation as matrices acting on row vectors: quaternions
    # g -> q g and vectors v -> q v, one batched matrix product each for
    # all joints of all parts (much cheaper than the component formulas)
    lq = _left_matrix(q).transpose(0, 2, 1)  # (F, 4, 4): g @ lq = q g
    rq = quat.to_matrix(q).transpose(0, 2, 1)  # (F, 3, 3): v @ rq = q v
    rot = np.array(motion.rotations, copy=True)
    root = motion.root_positions
    # pivot of each part, before and after the move
    pivots = gpos[:, list(sets.s2_tops)]  # (F, parts, 3)
    moved = pivots
    if sets.s2_tops[0] == 0:
        rot[:, 0] = quat.mul(q, rot[:, 0])
        if pivot != 0:
            pivots = pivots.copy()
            pivots[:, 0] = gpos[:, pivot]
        if root_delta is not None or pivot != 0:
            moved = pivots.copy()
            if root_delta is not None:
                moved[:, 0] += root_delta
            # joint 0 turns about the pivot and moves with it
            if pivot == 0 and root_delta is not None:
                root = root + root_delta
            else:
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
    if root is motion.root_positions:
        new = motion.replace(rotations=_owned(rot))
    else:
        new = motion.replace(rotations=_owned(rot), root_positions=_owned(root))
    return _Posed(new, new_grot, new_gpos)


# ======================================================================
# ground frames (section 3.3)
# ======================================================================
@lru_cache(maxsize=128)
def _lever_layout(sets: LinkSets, body: Body) -> tuple[NDArray[np.int64], NDArray[np.int64], NDArray[np.int64], NDArray[np.int64]]:
    """Links an adjustment moves, for equations 6-7 (cached per link sets and body).

    Returns the moving links (M,), the S2 part moving each (M,), and, for
    the carried ones among them, their positions in the moving list and
    their carried top joints: a rotated link turns about its part's centre
    with its own centre as lever point, a carried link (S3, or S1 below a
    root part) translates with its top joint, which is its lever point.
    """
    link_top = sets.carried_top[body.owners]
    carried = link_top >= 0
    rotated = (sets.roles[body.owners] == 2) & ~carried
    moving = np.flatnonzero(rotated | carried)
    part = sets.part[body.owners][moving]
    slots = np.flatnonzero(carried[moving])
    tops = link_top[moving][slots]
    out = (moving, part, slots, tops)
    for arr in out:
        arr.flags.writeable = False
    return out


def _ground_rotation(
    motion: Motion, body: Body, sets: LinkSets, bal: Balance, weight: Array, gpos: Array | None = None
) -> tuple[Array, Array]:
    """Per-frame world rotation vectors (F, 3) and S2 centres of the root part (F, 3).

    Closed form of equations 6 and 7 in the frame whose x axis ``x'`` points
    from the ZMP to its projection on the support polygon.  With
    ``alpha_l = m_l (a_ly - g_y)``, ``beta_l = m_l a_l . x'``, each moving
    link's lever point ``P_l`` (its centre when rotated, its carried top
    joint when carried) relative to its part's rotation centre ``C``, in
    coordinates ``dx = (P_l - C) . x'`` and ``dy = (P_l - C)_y``, the ZMP's
    ``x'`` coordinate after a rotation by ``theta`` is
    ``(a1 cos(theta) - a2 sin(theta) + a3) / sum_l alpha_l`` with
    ``a1 = sum_moving (alpha dx - beta dy)``,
    ``a2 = sum_moving (alpha dy + beta dx)`` and
    ``a3 = sum_all (alpha x - beta y) - a1`` (the Appendix's coefficients,
    as per-link sums).
    """
    n = motion.n_frames
    gpos = motion.global_positions() if gpos is None else gpos
    z = bal.zmp
    target = bal.projection
    todo = (bal.distance > 0) & (weight > 0)  # NaN (flight) compares False
    omega = np.zeros((n, 3))
    root_centre = np.zeros((n, 3))
    if not np.any(todo):
        return omega, root_centre
    idx = np.flatnonzero(todo)
    # x': horizontal unit vector towards the polygon, (cx, 0, cz)
    dx = target[idx, 0] - z[idx, 0]
    dz = target[idx, 2] - z[idx, 2]
    h = np.hypot(dx, dz)
    cx, cz = (dx / h)[:, None], (dz / h)[:, None]

    r = bal.positions[idx]  # (f, L, 3) smoothed link centres
    acc = bal.accelerations[idx]
    m = body.masses
    alpha = m * (acc[..., 1] - GRAVITY[1])  # (f, L)
    beta = m * (acc[..., 0] * cx + acc[..., 2] * cz)
    total = alpha * (r[..., 0] * cx + r[..., 2] * cz) - beta * r[..., 1]

    # rotation centres of the S2 parts: the boundary joint, or the ZMP's
    # projection on the ground for a part holding the root
    tops = sets.s2_tops
    centres = gpos[idx][:, list(tops)]  # (f, parts, 3)
    if tops[0] == 0:
        centres[:, 0] = target[idx]
        centres[:, 0, 1] = 0.0
        root_centre[idx] = centres[:, 0]
    moving, part, slots, carried_tops = _lever_layout(sets, body)
    lever = r[:, moving]
    if slots.size:
        lever[:, slots] = gpos[idx][:, carried_tops]
    d = lever - centres[:, part]
    ddx = d[..., 0] * cx + d[..., 2] * cz
    ddy = d[..., 1]
    am, bm = alpha[:, moving], beta[:, moving]
    a1 = (am * ddx - bm * ddy).sum(axis=1)
    a2 = (am * ddy + bm * ddx).sum(axis=1)  # Z'_x = (a1 cos - a2 sin + a3) / sig, equation 6
    a3 = total.sum(axis=1) - a1
    sig = alpha.sum(axis=1)
    want = (target[idx, 0] * cx[:, 0] + target[idx, 2] * cz[:, 0]) * sig - a3
    # a1 cos(t) - a2 sin(t) = R cos(t + phi), R = hypot(a1, a2), phi = atan2(a2, a1)
    radius = np.hypot(a1, a2)
    phi = np.arctan2(a2, a1)
    acs = np.arccos(np.clip(want / np.where(radius > 0, radius, 1.0), -1.0, 1.0))  # no exact solution: clamp
    t1 = (acs - phi + np.pi) % (2.0 * np.pi) - np.pi
    t2 = (-acs - phi + np.pi) % (2.0 * np.pi) - np.pi
    theta = np.where(np.abs(t1) <= np.abs(t2), t1, t2)  # the smaller solution
    theta = np.where(radius > 0, np.clip(theta, -MAX_GROUND_ANGLE, MAX_GROUND_ANGLE), 0.0) * weight[idx]
    # z' = x' x y = (-cz, 0, cx): +theta turns x' into y
    omega[idx, 0] = -cz[:, 0] * theta
    omega[idx, 2] = cx[:, 0] * theta
    return omega, root_centre


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


def _ground_step(posed: _Posed, body: Body, adj: Adjustment, sets: LinkSets, bal: Balance, path_joint: int) -> _Posed:
    motion = posed.motion
    omega, centre = _ground_rotation(motion, body, sets, bal, np.ones(motion.n_frames), posed.gpos)
    omega *= adj.rho
    root_delta = None
    pivot = _root_pivot(sets, path_joint)
    if 0 in sets.s2_tops:
        p = posed.gpos[:, pivot]
        root_delta = np.where(np.any(omega != 0, axis=1)[:, None], _rotate_about(omega, centre, p) - p, 0.0)
        root_delta = _smooth(root_delta, adj.width(motion.fps))
    omega = _smooth(omega, adj.width(motion.fps))
    return _apply(posed, sets, omega, root_delta, pivot)


# ======================================================================
# flight frames (section 3.4)
# ======================================================================
def _flight_centre(motion: Motion, body: Body, sets: LinkSets, positions: Array, gpos: Array) -> Array:
    """Rotation centre of the (single) S2 part on every frame, shape (F, 3)."""
    top = sets.s2_tops[0]
    if top != 0:
        return np.array(gpos[:, top])
    below = [u for (u, _), s1 in zip(sets.carried, sets.carried_s1, strict=True) if s1]
    if len(below) > 1:
        names = [motion.skeleton.names[u] for u in below]
        raise ValueError(f"A flight adjustment needs one S1/S2 boundary joint, got {names}")
    if below:
        return np.array(gpos[:, below[0]])
    return np.einsum("l,flc->fc", body.masses, positions) / body.total_mass


def _hold_into_windows(field: Array, stages: list[tuple[int, int]], flight_w: Array, window: int) -> Array:
    """Carry each flight's boundary values into its ground windows, times the window weight."""
    out = np.array(field, copy=True)
    for lo, a, b, hi in _flight_windows(field.shape[0], stages, window):
        out[lo:a] = field[a] * flight_w[lo:a, None]
        out[b:hi] = field[b - 1] * flight_w[b:hi, None]
    return out


def _flight_step(
    posed: _Posed,
    body: Body,
    adj: Adjustment,
    sets: LinkSets,
    stages: list[tuple[int, int]],
    flight_w: Array,
    window: int,
    path_joint: int,
) -> _Posed:
    motion = posed.motion
    pivot = _root_pivot(sets, path_joint)
    if len(sets.s2_tops) != 1:
        names = [motion.skeleton.names[t] for t in sets.s2_tops]
        raise ValueError(f"A flight adjustment needs S2 to be one connected part, got parts at {names}")
    n = motion.n_frames
    dt = motion.dt
    width = adj.width(motion.fps)
    # S3 is empty in flight: S2 links rotate, S1 links (above or below) stay
    in_s2 = sets.roles[body.owners] == 2
    m = body.masses

    # ---- 3.4.1 angular momentum: average of the flight, by rotating S2
    width5 = paper_width(5.0, motion.fps)
    s, v, _ = smoothed_derivatives(link_positions(motion, body, fk=posed[1:]), motion.fps, width=width5)
    com = np.einsum("l,flc->fc", m, s) / m.sum()
    h = np.einsum("l,flc->fc", m, np.cross(s - com[:, None], v))
    centre = _flight_centre(motion, body, sets, s, posed.gpos)
    phi = np.zeros((n, 3))
    for a, b in stages:
        target = h[a:b].mean(axis=0)
        q = s[a:b][:, in_s2] - centre[a:b, None]
        ms = m[in_s2]
        qq = np.einsum("l,flc,flc->f", ms, q, q)
        inertia = qq[:, None, None] * np.eye(3) - np.einsum("l,flc,fld->fcd", ms, q, q)
        inertia += 1e-9 * np.eye(3)
        domega = np.linalg.solve(inertia, (target - h[a:b])[..., None])[..., 0]  # equation 8, minus current
        cum = np.cumsum(domega, axis=0) * dt
        phi[a:b] = cum - cum[(b - a) // 2]
    phi = _hold_into_windows(phi, stages, flight_w, window) * adj.rho
    root_delta = None
    if 0 in sets.s2_tops:
        p = posed.gpos[:, pivot]
        root_delta = _smooth(_rotate_about(phi, centre, p) - p, width)
    out = _apply(posed, sets, _smooth(phi, width), root_delta, pivot)

    # ---- 3.4.2 parabolic centre of mass, on the adjusted motion
    r = link_positions(out.motion, body, fk=out[1:])
    com = np.einsum("l,flc->fc", m, r) / m.sum()
    wanted = com.copy()
    for a, b in stages:
        t = (np.arange(a, b) - a) * dt
        big_t = (b - 1 - a) * dt
        d = com[b - 1] - com[a]
        v0 = d / big_t - GRAVITY * big_t / 2.0
        wanted[a:b] = com[a] + v0 * t[:, None] + 0.5 * GRAVITY * t[:, None] ** 2
    flight = np.zeros(n, dtype=bool)
    for a, b in stages:
        flight[a:b] = True
    if np.all(sets.roles == 2):
        # S1 empty: translate the root
        delta = np.where(flight[:, None], wanted - com, 0.0)
        delta = _smooth(delta * adj.rho, width)  # zero at both ends of the flight: nothing to carry into windows
        moved = out.motion.replace(root_positions=out.motion.root_positions + delta)
        return _Posed(moved, out.grot, out.gpos + delta[:, None, :])
    # rotate S2 about the S1/S2 boundary so its centre of mass moves towards c*_M2
    centre = _flight_centre(out.motion, body, sets, r, out.gpos)
    m2 = m[in_s2].sum()
    c2 = np.einsum("l,flc->fc", m[in_s2], r[:, in_s2]) / m2
    c1m1 = com * m.sum() - c2 * m2
    c2_star = (wanted * m.sum() - c1m1) / m2
    rot = quat.log(quat.between(c2 - centre, c2_star - centre))
    rot = _hold_into_windows(np.where(flight[:, None], rot, 0.0), stages, flight_w, window) * adj.rho
    root_delta = None
    if 0 in sets.s2_tops:
        p = out.gpos[:, pivot]
        root_delta = _smooth(_rotate_about(rot, centre, p) - p, width)
    return _apply(out, sets, _smooth(rot, width), root_delta, pivot)


# ======================================================================
# footplants
# ======================================================================
def _reference_goals(reference: Motion, contacts: Contacts, *, blend: float) -> list[Goal]:
    """Goals that put each planted joint back where ``reference`` has it, frame by frame.

    One goal per contact joint (a ``"toe"`` goal when its parent is a
    contact joint too, else a ``"foot"`` goal), targets the joint's
    positions in ``reference``, weights 1 while its foot is planted (its
    ankle or its toe) blended to 0 over ``blend`` seconds on each side
    (:func:`mocaplab.refinement.blend_weights`).
    """
    sk = reference.skeleton
    names = tuple(contacts.joints)
    mask = np.asarray(contacts.mask, dtype=bool)
    feet: dict[str, list[int]] = {}  # ankle -> its contact columns (its own and its toes')
    for k, name in enumerate(names):
        p = int(sk.parents[sk.index(name)])
        feet.setdefault(sk.names[p] if p >= 0 and sk.names[p] in names else name, []).append(k)
    window = int(round(blend * reference.fps))
    pos = reference.global_positions()
    goals = []
    for ankle, cols in feet.items():
        planted = intervals_from_mask(mask[:, cols].any(axis=1))
        if not planted:
            continue
        weights = blend_weights(reference.n_frames, planted, window=window)
        for k in cols:
            kind: Literal["foot", "toe"] = "foot" if names[k] == ankle else "toe"
            goals.append(Goal(names[k], pos[:, sk.index(names[k])], weights, kind=kind))
    return goals


def _footplant_fn(
    footplants: Footplants, contacts: Contacts, reference: Motion
) -> Callable[[_Posed], _Posed] | None:
    """The footplant step of a touch-up, built once: goals met by the refinement module's IK layer."""
    if footplants is None:
        return None
    if callable(footplants):
        fn = footplants
        return lambda p: _posed(fn(p.motion, contacts, reference))
    if footplants not in ("auto", "plant", "refine", "ik"):
        raise ValueError(f"Expected `footplants` 'auto', 'plant', 'refine', 'ik', a callable or None, got {footplants!r}")
    if footplants == "refine":
        return lambda p: _posed(refine(p.motion, contacts=contacts, reference=reference))
    if footplants == "ik":
        goals = _reference_goals(reference, contacts, blend=FOOT_BLEND)
    else:  # "plant", "auto"
        goals = foot_goals(reference, contacts, reference=reference, blend=PLANT_BLEND)

    def plant(p: _Posed) -> _Posed:
        # solve_goals without root lowering; it turns the legs' joints only
        # (two-bone IK from the hips down, then the ankles) and hands back
        # the new kinematics (the legs' transforms recomputed, the rest kept)
        new, fk = _solve_goals(
            p.motion, goals, adjust_root=False, reach=0.99, max_drop=0.15, drop_window=0.15, dls_options=None,
            fk=(p.grot, p.gpos),
        )
        return _Posed(new, *fk)

    return plant


# ======================================================================
# state, stepping, history
# ======================================================================
@dataclasses.dataclass(frozen=True, eq=False)
class TouchUpState:
    """Where a touch-up stands: the current motion and what comes next.

    Attributes
    ----------
    motion : Motion
        The motion after ``index`` steps.
    reference : Motion
        The input motion (footplant positions are taken from it).
    body : Body
    contacts : Contacts
        Contact labels of the input, fixed for the whole touch-up.
    schedule : tuple of Adjustment
        Cycled through: step ``k`` applies ``schedule[k % len(schedule)]``.
    index : int
        Number of steps done.
    balance : Balance
        ZMP analysis of :attr:`motion`.
    label : str
        What produced this state (``"input"`` or the adjustment's label).
    flight_window : float
        Seconds of ground frames around a flight adjusted as flight.
    footplants : str, callable or None
        How footplants are re-enforced after each step (the option given).
    fix : callable or None
        The footplant step built from ``footplants``.
    kinematics : (ndarray (F, J, 4), ndarray (F, J, 3))
        Global rotations and positions of :attr:`motion`, computed by the
        touch-up (the same values as ``motion.global_rotations()`` and
        ``motion.global_positions()``, without recomputing them).
    roles : Roles or None
        Joint roles of the skeleton (with the overrides given to
        :func:`start`); the presets are resolved with them.
    path_joint : int
        The travelling joint (the pelvis): the part of S2 holding the root
        turns about it (:attr:`mocaplab.motion.Motion.path_joint`).
    """

    motion: Motion
    reference: Motion
    body: Body
    contacts: Contacts
    schedule: tuple[Adjustment, ...]
    index: int
    balance: Balance
    label: str = "input"
    flight_window: float = 0.5
    footplants: Footplants = "auto"
    fix: Callable[[_Posed], _Posed] | None = None
    kinematics: tuple[Array, Array] | None = None
    roles: Roles | None = None
    path_joint: int = 0

    @property
    def next_adjustment(self) -> Adjustment:
        """The adjustment the next :func:`step` applies."""
        return self.schedule[self.index % len(self.schedule)]

    @property
    def iteration(self) -> int:
        """Completed passes over the schedule."""
        return self.index // len(self.schedule)

    @property
    def zmp_distance(self) -> Array:
        """Distance of the ZMP outside the support polygon per frame (NaN in flight), shape (F,)."""
        return self.balance.distance

    @property
    def mean_zmp_distance(self) -> float:
        """Mean of :attr:`zmp_distance` over frames with a ZMP, metres."""
        return self.balance.mean_distance

    def with_schedule(self, schedule: Sequence[Adjustment]) -> TouchUpState:
        """The same state with another schedule (applied from the next step on; link sets checked)."""
        sched = _as_schedule(schedule, self.contacts)
        for adj in sched:
            link_sets(self.motion.skeleton, adj, roles=self.roles)
        return dataclasses.replace(self, schedule=sched)


def start(
    motion: Motion,
    *,
    body: Body | None = None,
    schedule: str | Adjustment | Sequence[Adjustment] = "default",
    contacts: Contacts | None = None,
    flight_window: float = 0.5,
    footplants: Footplants = "auto",
    roles: Mapping[str, Any] | None = None,
) -> TouchUpState:
    """The initial state of a touch-up (no step done).  See :func:`touch_up`."""
    if not isinstance(motion, Motion):
        raise TypeError(f"Expected `motion` to be a Motion, got {type(motion).__name__}")
    known = resolve_roles(motion, roles)
    body = Body.from_skeleton(motion.skeleton, roles=known) if body is None else body
    if not isinstance(body, Body):
        raise TypeError(f"Expected `body` to be a Body, got {type(body).__name__}")
    body.check(motion)
    contacts = default_contacts(motion, roles=known) if contacts is None else contacts
    _check_contacts(contacts, motion)
    if not (np.isfinite(flight_window) and flight_window >= 0):
        raise ValueError(f"Expected `flight_window` >= 0 seconds, got {flight_window!r}")
    fix = _footplant_fn(footplants, contacts, motion)
    sched = _as_schedule(schedule, contacts)
    for adj in sched:
        link_sets(motion.skeleton, adj, roles=known)  # validate the link sets early
    posed = _posed(motion)
    bal = balance(motion, body, contacts=contacts, fk=posed[1:])
    path = known.index("pelvis") if "pelvis" in known else motion.path_joint
    return TouchUpState(
        motion, motion, body, contacts, sched, 0, bal, "input", float(flight_window), footplants, fix, posed[1:],
        known, int(path),
    )


def step(state: TouchUpState) -> TouchUpState:
    """Apply the next adjustment of the schedule: a new state (the input is untouched)."""
    if not isinstance(state, TouchUpState):
        raise TypeError(f"Expected a TouchUpState (see mocaplab.physics.start), got {type(state).__name__}")
    adj = state.next_adjustment
    motion, body, contacts = state.motion, state.body, state.contacts
    posed = _Posed(motion, *state.kinematics) if state.kinematics is not None else _posed(motion)
    sets = link_sets(motion.skeleton, adj, roles=state.roles)
    if adj.stage == "ground":
        new = _ground_step(posed, body, adj, sets, state.balance, state.path_joint)
    elif stages := flight_stages(contacts):
        window = int(round(state.flight_window * motion.fps))
        weights = _flight_weights(motion.n_frames, stages, window)
        new = _flight_step(posed, body, adj, sets, stages, weights, window, state.path_joint)
    else:
        new = posed
    if state.fix is not None and new is not posed and _moves_contacts(motion.skeleton, sets, contacts):
        new = state.fix(new)
    if new is posed:
        bal = state.balance
    else:
        # redo the balance analysis for the links whose joints moved only
        moved = np.any(new.gpos != posed.gpos, axis=(0, 2)) | np.any(new.grot != posed.grot, axis=(0, 2))
        bal = _rebalance(state.balance, new.motion, body, contacts, new[1:], moved)
    return dataclasses.replace(
        state, motion=new.motion, index=state.index + 1, balance=bal, label=adj.label, kinematics=new[1:]
    )


def _moves_contacts(skeleton: Skeleton, sets: LinkSets, contacts: Contacts) -> bool:
    """Whether an adjustment's link sets can move a contact joint (else footplants need no repair)."""
    return any(sets.part[skeleton.index(name)] >= 0 for name in contacts.joints)


@dataclasses.dataclass(frozen=True, eq=False)
class TouchUpHistory:
    """Every state of a touch-up, index 0 the input.

    Attributes
    ----------
    states : tuple of TouchUpState
    """

    states: tuple[TouchUpState, ...]

    @property
    def motions(self) -> list[Motion]:
        """The motion after each step; index 0 is the input."""
        return [s.motion for s in self.states]

    @property
    def final(self) -> Motion:
        """The touched-up motion."""
        return self.states[-1].motion

    @property
    def labels(self) -> list[str]:
        """What each step did (index 0: ``"input"``)."""
        return [s.label for s in self.states]

    @property
    def zmp_distance(self) -> Array:
        """ZMP distance outside the support polygon, per step and frame (NaN in flight), shape (S + 1, F)."""
        return np.stack([s.zmp_distance for s in self.states])

    @property
    def mean_zmp_distance(self) -> Array:
        """Mean ZMP distance per step (Figure 9), metres, shape (S + 1,); index 0 the input."""
        return np.array([s.mean_zmp_distance for s in self.states])

    def __len__(self) -> int:
        return len(self.states)


def touch_up(
    motion: Motion,
    *,
    body: Body | None = None,
    schedule: str | Adjustment | Sequence[Adjustment] = "default",
    contacts: Contacts | None = None,
    iterations: int = 3,
    flight_window: float = 0.5,
    footplants: Footplants = "auto",
    roles: Mapping[str, Any] | None = None,
) -> TouchUpHistory:
    """Physically touch up a motion (Shin et al. 2003).

    Parameters
    ----------
    motion : Motion
        The (edited) motion; never modified.
    body : Body, optional
        Masses; default :meth:`Body.from_skeleton` (de Leva table).  Fitted
        masses (:func:`mocaplab.physics.fit_masses`) make a captured clip
        change less.
    schedule : "default", "ground", "flight", Adjustment or sequence of Adjustment
        ``"default"``: the paper's ground schedule, plus its flight schedule
        when the clip has flight frames.
    contacts : Contacts, optional
        Planted joints of the input (default
        :func:`mocaplab.contacts.foot_contacts`); they decide ground versus
        flight frames and the support polygons.
    iterations : int
        Passes over the schedule; the history has
        ``iterations * len(schedule) + 1`` states.
    flight_window : float
        Seconds of ground frames on each side of a flight adjusted as flight
        and blended to zero (0.5 s in the paper).
    footplants : "auto", "plant", "refine", "ik", callable or None
        Re-enforcement of the footplants after each step (see the module
        notes); a callable gets ``(motion, contacts, reference)``.
    roles : mapping of role names to joint names, optional
        Overrides of the inferred joint roles
        (:func:`mocaplab.roles.resolve_roles`), used for the default body,
        the default contacts, the presets and the travelling joint.

    Returns
    -------
    TouchUpHistory
        ``.motions``, ``.zmp_distance``, ``.mean_zmp_distance``, ``.final``.
    """
    if isinstance(iterations, bool) or not isinstance(iterations, (int, np.integer)) or iterations < 0:
        raise ValueError(f"Expected `iterations` to be an integer >= 0, got {iterations!r}")
    state = start(
        motion, body=body, schedule=schedule, contacts=contacts, flight_window=flight_window, footplants=footplants,
        roles=roles,
    )
    states = [state]
    for _ in range(int(iterations) * len(state.schedule)):
        state = step(state)
        states.append(state)
    return TouchUpHistory(tuple(states))


# ======================================================================
# a stateful stepper for interactive use
# ======================================================================
class TouchUpSession:
    """Step a touch-up forward and back, editing the schedule on the way.

    A thin stateful layer over :func:`start` and :func:`step` (the widget
    :class:`mocaplab.widgets.TouchUpStepper` forwards its buttons here).
    States already computed are kept, so stepping back and forward again
    costs nothing; editing the schedule drops the states after the current
    one.

    Parameters
    ----------
    motion : Motion
    **options
        As for :func:`start` (``body``, ``schedule``, ``contacts``,
        ``flight_window``, ``footplants``, ``roles``).
    """

    def __init__(self, motion: Motion, **options: object) -> None:
        self._states: list[TouchUpState] = [start(motion, **options)]  # type: ignore[arg-type]
        self._index = 0

    @property
    def index(self) -> int:
        """Index of the current state (0: the input)."""
        return self._index

    @property
    def current(self) -> TouchUpState:
        return self._states[self._index]

    @property
    def input(self) -> TouchUpState:
        return self._states[0]

    @property
    def schedule(self) -> tuple[Adjustment, ...]:
        return self.current.schedule

    @property
    def history(self) -> TouchUpHistory:
        """States from the input up to the current one."""
        return TouchUpHistory(tuple(self._states[: self._index + 1]))

    def forward(self) -> TouchUpState:
        """Go one step forward (computing it if needed)."""
        if self._index + 1 >= len(self._states):
            self._states.append(step(self._states[-1]))
        self._index += 1
        return self.current

    def back(self) -> TouchUpState:
        """Go one step back (no-op at the input)."""
        self._index = max(0, self._index - 1)
        return self.current

    def run(self, n: int) -> TouchUpState:
        """Go ``n`` steps forward."""
        for _ in range(int(n)):
            self.forward()
        return self.current

    def finish_pass(self) -> TouchUpState:
        """Go forward to the end of the current pass over the schedule (a whole pass at its start)."""
        n = len(self.schedule)
        k = self.current.index % n
        return self.run(n - k if k else n)

    def set_schedule(self, schedule: Sequence[Adjustment]) -> None:
        """Replace the schedule from the current state on."""
        self._states = self._states[: self._index + 1]
        self._states[-1] = self._states[-1].with_schedule(schedule)

    def set_adjustment(self, k: int, **changes: object) -> None:
        """Change fields (``s2``, ``s3``, ``sigma``, ``rho``...) of adjustment ``k``."""
        sched = list(self.schedule)
        if not 0 <= k < len(sched):
            raise IndexError(f"Expected an adjustment index in [0, {len(sched)}), got {k}")
        sched[k] = sched[k].replace(**changes)
        self.set_schedule(sched)
