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
   * **flight frames** (section 3.4): first the rotation giving a constant
     angular momentum (equations 8-9), then the translation and rotation
     putting the centre of mass on the parabola with ``v0 = d / T - g T / 2``;

2. scale it by ``rho`` and smooth it over time with a Gaussian kernel of
   width ``sigma`` (the rotation as a world rotation vector, i.e. the
   logarithm of the displacement relative to the identity, which is how
   Lee and Shin filter orientation displacements; the root translation
   linearly);
3. apply it as a displacement map (S2's top joint rotated, S3's top joint
   counter-rotated) and re-enforce the footplants.

:func:`touch_up` repeats passes over the schedule, each one a line search
on its error measure (:attr:`TouchUpState.error`: a pass that raises it is
redone with smaller steps), and stops when a pass no longer pays
(``tol``); :func:`start` and :func:`step` are the same one
adjustment at a time, and every state is recorded for the stepper.

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
  below switched off: mean ZMP distance 6.4 cm, 1.6 cm after 3 passes and
  2.7 cm after 12 with the 2-std cut, 1.6 and 1.0 cm with the 4-std one;
  the frame weights alone also stop that drift, and both are kept).  Near the ends
  of the clip the kernel is cut at the first or last frame and renormalised
  (a weighted mean over the frames that exist): extending the edge value
  instead (``mode="nearest"``) gives an end frame up to half the kernel's
  weight, so one badly balanced end frame leaned the whole start or end
  of a captured walk by many centimetres.
* Frames without an exact solution get the closest-approach rotation, as
  in section 3.3 (the arms cannot balance most frames of a curved walk,
  the lower body cannot balance a steep slope in one step; giving those
  frames no correction, as an earlier version did, left the arm
  adjustment with 5-13 of 58-79 frames to work on and the error at half
  the input's).  In a ground adjustment a frame's own correction counts
  with a weight (:func:`_ground_weights`): 0 for the clip's first and
  last frames, whose accelerations come from a one-sided window, and on
  ground frames without a ZMP; a spike the kernel cannot follow (the few
  frames before a heel strike, whose smoothed accelerations already feel
  the impact) in proportion to the share of its correction that survives
  the smoothing, up to :data:`SPIKE_SHARE`.
* Convergence is kept by a line search on each pass (:func:`touch_up`),
  not by leaving frames out: a pass that raises the error is done again
  with half the step (every ``rho`` halved), down to :data:`MIN_STEP`.
  With it the walk of lesson 09 tilted 20 degrees uphill falls on every
  pass (158.9 -> 9.2 mm over 20 passes; with the zero weights it fell to
  61.4 mm and rose again on 16 of 20 passes to 145.4 mm), and the bent
  jump of lesson 10 with the paper's 0.5 s flight window improves (8.8 ->
  3.3 mm in 3 passes; a full first step raises it to 12.6 mm).
* Equation 9 relates consecutive frames; the angular-velocity correction
  ``I^-1 (D - h)`` is therefore **integrated** over the flight to give each
  frame's rotation, so that the corrected motion really has the constant
  angular momentum ``D``.  The paper's target ``D`` is the flight's mean;
  here it is the constant for which the integrated rotation vanishes at
  take-off and landing (:func:`_momentum_rotation`), so that the body
  leaves and meets the ground oriented as it was and no rotation has to be
  carried into the ground frames.  The paper's footnote writes the inertia
  of point masses as ``sum m r r^T``; the inertia tensor
  ``sum m (|r|^2 I - r r^T)`` is used here.
* The centre of mass is put on its parabola by **translation first**: every
  flight adjustment translates the whole body by ``rho`` times the
  distance to the parabola (a translation leaves the angular momentum
  about the centre of mass unchanged, and it needs no large turn: moving
  the centre of mass 10 cm by turning the legs alone takes some 40
  degrees); an adjustment with a non-empty S1 then turns S2 about the
  S1/S2 boundary (equation 10) towards what is left, clamped like the rest.
* The flight adjustments keep the take-off and landing points, so they
  change the velocities there.  Ground frames within ``flight_window`` of
  a flight (and no further than half-way to the next flight) take that
  change (Figure 4): each flight field (the translation and both
  rotations) is continued with its boundary value and slope, faded out
  with the one blend ramp (:func:`_carry_into_windows`), so the change of
  take-off velocity is pushed off over the window instead of in one
  frame.  The default window is 0.1 s (:data:`FLIGHT_WINDOW`), shorter than
  the paper's 0.5 s: a velocity change over a longer window needs a
  counter-movement whose ZMP excursions unbalance the whole window (CMU
  16_05 at 30 fps, its flight bent 15 cm sideways: with 0.5 s no pass beats
  the input's error of 8.8 mm, with 0.1 s it falls to 3.9 mm), and without
  a window the change lands on the take-off frame (CMU 16_01 at 120 fps
  with its flight slowed x1.4: the angular momentum's spread over the
  flight 0.19 -> 0.28 kg m^2/s with no window, 0.32 with 0.5 s, 0.06 with
  0.1 s).
* Stretches without contact that touch the first or last frame of the clip
  are no flights (their take-off or landing is outside the clip:
  :func:`flight_stages`); a clip with no planted frame is an error.
* The default schedule for a clip with flights is the flight schedule and
  then the ground one (:func:`default_schedule`), so every pass ends with
  a ground pass that balances the take-off and landing windows again.
* Footplants are re-enforced after every step that can move a contact
  joint (an adjustment of the upper body or the arms leaves the feet
  alone on ground frames; a flight adjustment translates the whole body),
  per frame like the paper's choice (Kovar et al. 2002, "because of its
  efficiency").  There is one correction layer: footplants are goals
  (:class:`mocaplab.goals.Goal`), built once from the input's
  contacts in :func:`start`, and met after each step by the refinement
  module's IK layer (:func:`mocaplab.goals.solve_goals`: two-bone IK
  of the legs, then each foot turned about its ankle toward its toe goal),
  lowering the root (smoothly, at most 15 cm) where a leg would have to
  stretch beyond 99 % of its length or beyond what the input already
  stretches it: without it a hip turned away from a planted ankle snapped
  the knee straight in a frame or two (a PyMO walk: ``RightLeg`` 304 ->
  2,890 rad/s^2).  Every goal's weight is 0 on flight frames and fades in
  and out over :data:`PLANT_BLEND` on the ground frames next to them (a
  goal reaching into a flight pulls the airborne legs back after the
  flight adjustments; :func:`_outside_flights`).  The goals hold only where a step moved a
  planted joint (:func:`_need_gate`, a smooth gate): the IK layer carries
  a knee bent against its hinge over to the hinge's side, and redone on
  frames no step touched it flipped near-straight knees back and forth
  (an OptiTrack walk: ``LeftLeg`` 879 -> 1,978 rad/s^2).  The options
  differ in the goals only:

  - ``"ik"`` (what ``"auto"`` picks): each planted joint back where the
    input motion had it, frame by frame (targets the input's positions,
    weights :func:`mocaplab.goals.blend_weights` over 0.2 s around the
    frames where its foot is planted); the ankle's orientation is the IK
    layer's (the foot keeps its turn about the ankle-to-toe axis).  On the
    input itself it changes nothing, so a touch-up of a good motion starts
    from that motion;
  - ``"plant"``: the plant goals of :func:`mocaplab.goals.foot_goals`,
    one plant position per contact interval of the input.  It re-plants
    the input's feet as well: on the captured walk CMU 16_15 the step alone
    moves the knees by up to 8 cm at heel-off (the ankle held on one spot
    while the captured heel rolls) and raises the mean ZMP distance from
    1.26 to 1.61 cm, so it is no longer the default; plant an edited
    motion's feet with :func:`mocaplab.editing.refinement.refine` first;
  - ``"refine"``: the foot planting of :func:`mocaplab.refine` (Kim et al.'s
    s4.3: :func:`mocaplab.goals.foot_goals` met by
    :func:`mocaplab.goals.enforce_goals`), which also
    lowers the root where a leg cannot reach and smooths the corrections
    with a displacement map; both leak into flight frames and bend the
    ballistic centre-of-mass path again;
  - ``None`` skips the step.

* The error measure (:attr:`TouchUpState.error`) is the mean over frames of
  the distance of the ZMP outside the support polygon (ground frames) and
  of the centre of mass from its parabola (flight frames), in metres; on a
  walk it is the mean ZMP distance of Figure 9.  A pass is accepted (and
  can be the best) only when the ground frames' mean ZMP distance is at
  most :data:`ZMP_SLACK` (2 mm) above the input's (:func:`_admissible`): the error trades ground
  frames for flight frames, and a flight step can buy its parabola with
  the balance of the take-off and landing windows.  Ground frames without a
  ZMP (negative vertical ground force) are counted (``dropped``), never
  silently left out: the input warns about them, and a pass that drops
  more of them than the input cannot be the best.  The clip's first and
  last frames (:attr:`TouchUpState.edge_frames`, 0.1 s) are in that mean
  though no adjustment corrects them; :attr:`TouchUpState.interior_error`
  and :attr:`TouchUpState.mean_zmp_distance_interior` leave them out.

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
from functools import cached_property, lru_cache
from typing import TYPE_CHECKING, Any, Literal, NamedTuple

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.ndimage import gaussian_filter1d, maximum_filter1d

from .. import quat
from .._warnings import warn
from ..contacts import intervals_from_mask
from ..displacement import blend_ramp
from ..goals import Goal, blend_weights, enforce_goals, foot_goals, solve_goals
from ..motion import Motion, Skeleton, _owned, readonly
from ..roles import Roles, RolesError, resolve_roles
from .body import GRAVITY, Body, angular_momentum, center_of_mass, link_positions, paper_width, smoothed_derivatives
from .zmp import _LEVEL, Balance, _check_contacts, _rebalance, balance, default_contacts

if TYPE_CHECKING:  # pragma: no cover
    from ..contacts import Contacts

__all__ = [
    "Adjustment",
    "TouchUpWarning",
    "GROUND_SCHEDULE",
    "FLIGHT_SCHEDULE",
    "default_schedule",
    "LinkSets",
    "link_sets",
    "preset_mask",
    "flight_stages",
    "FlightMeasure",
    "flight_measures",
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

#: Largest per-frame rotation of one adjustment, radians (20 degrees), on
#: ground and flight frames alike: a guard against frames with absurd
#: accelerations or momenta.
MAX_ANGLE = 0.35
#: Width of the smoothing kernels in standard deviations on each side (see
#: the module notes: a kernel cut at 2 std let frame-to-frame noise of the
#: per-frame corrections into the accelerations, and passes diverged).
KERNEL_TRUNCATE = 4.0
#: A frame whose need survives the smoothing with less than this share of
#: itself (a spike the kernel cannot follow) is down-weighted in proportion.
SPIKE_SHARE = 0.3
#: Default stall tolerance of :func:`touch_up`: it stops after a pass that
#: lowers the error by less than this share of it.  With 2 % the passes that
#: buy 2-5 % each on captured walks (a few tenths of a millimetre) went on
#: moving the hands by up to 6.5 cm (CMU 16_11); with 5 % they stop at
#: 5.7 cm, and walks bent by 0.4 of their length still end at a quarter of
#: their mean ZMP distance.
STALL_TOLERANCE = 0.05
#: Default ``flight_window``: seconds of ground frames on each side of a
#: flight that take the flight adjustments' changes of velocity (see the
#: module notes; the paper used 0.5 s).
FLIGHT_WINDOW = 0.1
#: Default number of passes of :func:`touch_up` (at most; the stall
#: tolerance usually stops it earlier).  Passes are cheap (a few tens of
#: milliseconds on a walk of 20 s at 120 fps) and the line search makes each
#: accepted one lower the error, so more passes only cost time: three left a
#: walk bent by 0.4 of its length at half its input's mean ZMP distance,
#: twelve at a quarter.
ITERATIONS = 12
#: Smallest step of :func:`touch_up`'s line search, a share of each
#: adjustment's ``rho``: a pass that raises the error is retried with half
#: the step, down to this; below it the touch-up stops.
MIN_STEP = 1.0 / 16.0
#: Flights longer than this (seconds) are suspicious (contacts missing?): a warning.
LONG_FLIGHT = 1.5
#: A median slide of the planted joints over their contact intervals above
#: this (metres) warns that the feet slide ("run refine first").
SLIDE_WARNING = 0.05
#: Blend window of the ``"ik"`` footplant goals on each side of a plant, seconds.
FOOT_BLEND = 0.2
#: Blend window of the ``"plant"`` goals on each side of a contact, and the
#: ramp by which every footplant goal fades out on the ground frames next to
#: a flight (goal weights are 0 on flight frames), seconds.
PLANT_BLEND = 0.05
#: How much a touch-up may raise the ground frames' mean ZMP distance above
#: its input's, metres (:func:`_admissible`): what a flight step may cost the
#: take-off and landing windows when it gives the flight its parabola (the
#: captured jump CMU 16_05: 0.63 -> 0.70 mm while the flight error halves;
#: lesson 10's bent jump 0.27 -> 2.1 mm, 3.8 without the bound).  2 mm is
#: what the quality pipeline allows a touch-up (tests/test_quality_pipeline.py).
ZMP_SLACK = 2e-3
#: A planted joint within this distance of its footplant goal (metres) needs
#: no correction (:func:`_need_gate`); the goals hold fully from twice it.
PLANT_TOLERANCE = 5e-4


class TouchUpWarning(UserWarning):
    """Suspicious input to a touch-up (long flights, sliding feet, frames without a ZMP)."""



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
        Width of the smoothing kernel in seconds, > 0 (the paper's 40 frames at
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
        if not (np.isfinite(self.sigma) and self.sigma > 0):
            raise ValueError(
                f"Expected `sigma` > 0 seconds (the width of the smoothing kernel), got {self.sigma!r}: without "
                "smoothing the per-frame corrections jump from frame to frame, their accelerations throw the ZMP "
                "about and frames lose it (negative vertical force)"
            )
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

    ``stage="both"`` gives the flight schedule followed by the ground one,
    so that every pass ends by balancing the ground frames, the take-off
    and landing windows that the flight adjustments moved included; with
    ``contacts`` given, the flight part is left out when the clip has no
    flight frame.
    """
    if stage == "ground":
        return GROUND_SCHEDULE
    if stage == "flight":
        return FLIGHT_SCHEDULE
    if stage != "both":
        raise ValueError(f"Expected `stage` 'ground', 'flight' or 'both', got {stage!r}")
    if contacts is not None and not flight_stages(contacts):
        return GROUND_SCHEDULE
    return FLIGHT_SCHEDULE + GROUND_SCHEDULE


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
    # cached and handed out: read-only for good
    return LinkSets(readonly(roles), tuple(tops), tuple(carried), tuple(carried_s1), readonly(part), readonly(carried_top))


# ======================================================================
# stages
# ======================================================================
def flight_stages(contacts: Contacts, *, min_frames: int = 2, at_ends: bool = False) -> list[tuple[int, int]]:
    """Half-open frame intervals with no joint planted (at least ``min_frames`` long).

    With ``at_ends=False`` (default) a stretch without contact that touches
    the clip's first or last frame is left out: its take-off or its landing
    lies outside the clip, so there is no flight between known ends to fit
    a parabola to (a clip that starts or stops in the air, or a contact
    detection gap there).  The touch-up adjusts neither ground nor flight
    constraints on such frames.
    """
    ground = np.asarray(contacts.mask, dtype=bool).any(axis=1)
    edges = np.diff(np.concatenate(([0], (~ground).astype(np.int8), [0])))
    starts, stops = np.flatnonzero(edges == 1), np.flatnonzero(edges == -1)
    n = ground.shape[0]
    return [
        (int(a), int(b))
        for a, b in zip(starts, stops, strict=True)
        if b - a >= min_frames and (at_ends or (a > 0 and b < n))
    ]


#: Fewest frames of a flight a parabola is fitted to (:func:`flight_measures`);
#: three points fix one exactly, fewer leave its curvature free.
MIN_FIT_FRAMES = 3


class FlightMeasure(NamedTuple):
    """How well one flight ``[start, stop)`` obeys the two laws of section 3.4 (:func:`flight_measures`)."""

    #: First frame of the flight.
    start: int
    #: One past its last frame.
    stop: int
    #: Gravity fitted to the centre of mass's height, m/s^2 (9.81 when it flies a parabola; equation 1).
    gravity: float
    #: Mean distance of ``h_CM`` from its mean over the flight, kg m^2/s (0 when constant; equation 2).
    momentum_spread: float

    @property
    def frames(self) -> int:
        """Frames in the flight."""
        return self.stop - self.start

    @property
    def fitted(self) -> bool:
        """Whether :attr:`gravity` was fitted (a parabola needs :data:`MIN_FIT_FRAMES` frames)."""
        return self.frames >= MIN_FIT_FRAMES

    def gravity_text(self) -> str:
        """:attr:`gravity` for people: ``"9.81 m/s²"``, or ``"too short to fit (2 frames)"`` when not :attr:`fitted`."""
        return f"{self.gravity:.2f} m/s²" if self.fitted else f"too short to fit ({self.frames} frames)"


def flight_measures(
    motion: Motion, body: Body, contacts: Contacts, *, com: ArrayLike | None = None
) -> tuple[FlightMeasure, ...]:
    """The flight measures of every flight of ``motion`` (:func:`flight_stages` of ``contacts``).

    In the air only gravity acts, so the centre of mass flies a parabola
    (equation 1) and the angular momentum about it is constant (equation
    2).  For each flight, ``gravity`` is minus twice the leading coefficient
    of the least-squares parabola through the centre of mass's height over
    the flight's frames (NaN for a flight shorter than :data:`MIN_FIT_FRAMES`,
    3: :attr:`FlightMeasure.fitted` is then False and
    :meth:`FlightMeasure.gravity_text` says "too short to fit"), and
    ``momentum_spread`` is the mean over those frames of the distance of
    :func:`~mocaplab.physics.angular_momentum` (about the centre of mass,
    kg m^2/s) from its mean over the flight.

    Parameters
    ----------
    motion : Motion
    body : Body
    contacts : Contacts
        Contact labels of ``motion`` (a touch-up's, fixed for all its steps).
    com : array_like, shape (F, 3), optional
        The centre of mass of ``motion`` if already computed
        (:func:`~mocaplab.physics.center_of_mass`).

    Returns
    -------
    tuple of FlightMeasure
        Empty when the clip has no flight.
    """
    stages = flight_stages(contacts)
    if not stages:
        return ()
    c = center_of_mass(motion, body) if com is None else np.asarray(com, dtype=float)
    if c.shape != (motion.n_frames, 3):
        raise ValueError(f"Expected `com` of shape ({motion.n_frames}, 3), got {c.shape}")
    h = angular_momentum(motion, body)
    out = []
    for a, b in stages:
        t = np.arange(b - a) / motion.fps
        g = -2.0 * float(np.polyfit(t, c[a:b, 1], 2)[0]) if b - a >= MIN_FIT_FRAMES else float("nan")
        hf = h[a:b]
        spread = float(np.linalg.norm(hf - hf.mean(axis=0), axis=1).mean())
        out.append(FlightMeasure(a, b, g, spread))
    return tuple(out)


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


# ======================================================================
# displacement maps
# ======================================================================
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
    lq = _left_matrix(q).transpose(0, 2, 1)  # (F, 4, 4): g @ lq = q g
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
    return readonly(moving), readonly(part), readonly(slots), readonly(tops)


def _ground_rotation(
    motion: Motion, body: Body, sets: LinkSets, bal: Balance, weight: Array, gpos: Array | None = None
) -> tuple[Array, Array, NDArray[np.bool_]]:
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
    as per-link sums).  Where no angle puts the ZMP on the polygon
    (``|want| > hypot(a1, a2)``), the angle that brings it closest is used
    (section 3.3: ``cos(theta + phi) = +-1``); every angle is then clamped
    to :data:`MAX_ANGLE`.  The third value marks the frames solved exactly
    within the clamp (the others get their closest approach).
    """
    n = motion.n_frames
    gpos = motion.global_positions() if gpos is None else gpos
    # equations 6 and 7 are written for the ground y = 0: work in the frame of
    # the ground the balance measured on (the estimated floor), then turn back
    ground = bal.__dict__.get("_ground", _LEVEL)
    z = ground.to_plane(bal.zmp)
    target = ground.to_plane(bal.projection)
    todo = (bal.distance > 0) & (weight > 0)  # NaN (flight) compares False
    omega = np.zeros((n, 3))
    root_centre = np.zeros((n, 3))
    if not np.any(todo):
        return omega, root_centre, np.zeros(n, dtype=bool)
    idx = np.flatnonzero(todo)
    # x': horizontal unit vector towards the polygon, (cx, 0, cz)
    dx = target[idx, 0] - z[idx, 0]
    dz = target[idx, 2] - z[idx, 2]
    h = np.hypot(dx, dz)
    cx, cz = (dx / h)[:, None], (dz / h)[:, None]

    r = ground.to_plane(bal.positions[idx])  # (f, L, 3) smoothed link centres
    acc = bal.accelerations[idx]
    acc = acc - GRAVITY if ground.identity else acc @ ground.rotation.T - ground.rotation @ GRAVITY  # a - g
    m = body.masses
    alpha = m * acc[..., 1]  # (f, L)
    beta = m * (acc[..., 0] * cx + acc[..., 2] * cz)
    total = alpha * (r[..., 0] * cx + r[..., 2] * cz) - beta * r[..., 1]

    # rotation centres of the S2 parts: the boundary joint, or the ZMP's
    # projection on the ground for a part holding the root
    tops = sets.s2_tops
    local = ground.to_plane(gpos[idx])
    centres = local[:, list(tops)]  # (f, parts, 3)
    if tops[0] == 0:
        centres[:, 0] = target[idx]
        centres[:, 0, 1] = 0.0
        root_centre[idx] = ground.to_world(centres[:, 0])
    moving, part, slots, carried_tops = _lever_layout(sets, body)
    lever = r[:, moving]
    if slots.size:
        lever[:, slots] = local[:, carried_tops]
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
    exact = np.zeros(n, dtype=bool)
    exact[idx] = (radius > 0) & (np.abs(want) <= radius) & (np.abs(theta) <= MAX_ANGLE)
    theta = np.where(radius > 0, np.clip(theta, -MAX_ANGLE, MAX_ANGLE), 0.0) * weight[idx]
    # z' = x' x y = (-cz, 0, cx): +theta turns x' into y
    omega[idx, 0] = -cz[:, 0] * theta
    omega[idx, 2] = cx[:, 0] * theta
    if not ground.identity:
        omega = omega @ ground.rotation  # back to world axes
    return omega, root_centre, exact


def _edge_frames(n: int, fps: float) -> int:
    """Frames at each end of a clip whose accelerations come from a one-sided window.

    The radius of the ZMP's acceleration kernel (5 frames at 30 fps, see
    :func:`mocaplab.physics.body.smoothed_derivatives`): within it the
    kernel reaches past the clip's end, into the extrapolated padding.
    """
    return min(_edge_width(fps), n // 2)


def _edge_width(fps: float) -> int:
    """:func:`_edge_frames` of a clip long enough to have frames between its two ends."""
    return int(2.0 * paper_width(5.0, fps) / 4.0 + 0.5)


def _ground_weights(bal: Balance, omega: Array, width: float, fps: float) -> Array:
    """How much each frame's own ground correction counts, in [0, 1], shape (F,).

    0 for the frames whose accelerations should not be trusted: the clip's
    first and last frames, whose accelerations come from a one-sided window
    (:func:`_edge_frames`), and ground frames without a ZMP.  A frame whose
    closed form has no exact solution (or none within :data:`MAX_ANGLE`)
    counts fully with its closest-approach rotation (section 3.3); the
    line search of :func:`touch_up` keeps such frames from winding the
    motion up.  Then a spike the
    kernel cannot follow (a frame whose smoothed correction keeps less than
    :data:`SPIKE_SHARE` of its own, like the few frames before a heel
    strike whose smoothed accelerations already feel the impact) counts
    that share divided by :data:`SPIKE_SHARE`.  Frames inside the polygon
    count fully, with a correction of zero.
    """
    n = omega.shape[0]
    w = np.ones(n)
    edge = _edge_frames(n, fps)
    w[:edge] = 0.0
    w[n - edge :] = 0.0
    w[bal.ground & ~np.isfinite(bal.distance)] = 0.0
    need = np.linalg.norm(omega, axis=1)
    asked = need > 0
    if np.any(asked):
        kept = np.sum(_smooth(omega * w[:, None], width) * omega, axis=1)  # smoothed correction along the need
        share = kept[asked] / (SPIKE_SHARE * need[asked] ** 2)
        w[asked] *= np.clip(share, 0.0, 1.0)
    return w


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
    n = motion.n_frames
    width = adj.width(motion.fps)
    omega, centre, _ = _ground_rotation(motion, body, sets, bal, np.ones(n), posed.gpos)
    w = _ground_weights(bal, omega, width, motion.fps)[:, None] * adj.rho
    root_delta = None
    pivot = _root_pivot(sets, path_joint)
    if 0 in sets.s2_tops:
        p = posed.gpos[:, pivot]
        root_delta = np.where(np.any(omega != 0, axis=1)[:, None], _rotate_about(omega * adj.rho, centre, p) - p, 0.0)
        root_delta = _smooth(root_delta * (w / adj.rho), width)
    return _apply(posed, sets, _smooth(omega * w, width), root_delta, pivot)


# ======================================================================
# flight frames (section 3.4)
# ======================================================================
def _ballistic(c0: Array, c1: Array, n: int, dt: float) -> Array:
    """The ballistic path over ``n`` frames from ``c0`` (first frame) to ``c1`` (last), shape (n, 3).

    Section 3.4.2: ``c*(t) = c0 + v0 t + g t^2 / 2`` with ``v0 = d / T - g T / 2``,
    ``d = c1 - c0`` and ``T = (n - 1) dt``.
    """
    t = np.arange(n)[:, None] * dt
    if n < 2:
        return np.broadcast_to(c0, (n, 3)).copy()
    big_t = (n - 1) * dt
    v0 = (c1 - c0) / big_t - GRAVITY * big_t / 2.0
    return c0 + v0 * t + 0.5 * GRAVITY * t**2


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


def _clamp_angle(omega: Array) -> Array:
    """Rotation vectors (F, 3) with their angles clamped to :data:`MAX_ANGLE`."""
    angle = np.linalg.norm(omega, axis=1, keepdims=True)
    return omega * np.minimum(1.0, MAX_ANGLE / np.where(angle > 0, angle, 1.0))


def _carry_into_windows(field: Array, stages: list[tuple[int, int]], window: int, fps: float) -> Array:
    """Continue a flight's field (F, 3) into the ground windows around it (:func:`_flight_windows`).

    On a window frame at ``t`` frames from the flight's boundary frame the
    field is ``(f_b + f'_b t) R(u)``: the boundary value ``f_b`` and slope
    ``f'_b`` (over the flight's first or last 0.05 s) continued, times the
    one blend ramp ``R`` (:func:`mocaplab.displacement.blend_ramp`) falling
    from 1 at the flight to 0 at the window's far end.  The field keeps its
    value and velocity across take-off and landing (a changed take-off
    velocity is pushed off over the window, not in one frame) and fades
    out with no velocity or acceleration jump.  Frames outside flights and
    windows get 0.
    """
    n = field.shape[0]
    out = np.zeros_like(field)
    k = max(2, int(round(0.05 * fps)))
    for lo, a, b, hi in _flight_windows(n, stages, window):
        out[a:b] = field[a:b]
        q = min(k, b - a)
        if lo < a:
            slope = (field[a + q - 1] - field[a]) / (q - 1) if q > 1 else np.zeros(3)
            t = np.arange(lo, a) - a
            ramp = blend_ramp((np.arange(lo, a) - (lo - 1)) / (a - lo + 1))
            out[lo:a] = (field[a] + slope * t[:, None]) * ramp[:, None]
        if b < hi:
            slope = (field[b - 1] - field[b - q]) / (q - 1) if q > 1 else np.zeros(3)
            t = np.arange(b, hi) - (b - 1)
            ramp = blend_ramp((hi - np.arange(b, hi)) / (hi - b + 1))
            out[b:hi] = (field[b - 1] + slope * t[:, None]) * ramp[:, None]
    return out


def _momentum_rotation(q: Array, masses: Array, h: Array, dt: float) -> Array:
    """Rotations (n, 3) of S2 over one flight that make its angular momentum constant (section 3.4.1).

    ``q`` (n, L, 3) are S2's link centres relative to the rotation centre,
    ``h`` (n, 3) the angular momentum of the flight's frames.  Equation 8
    gives the angular-velocity change ``I^-1 (D - h)`` on each frame (``I``
    the inertia tensor of S2's point masses about the centre); integrated
    over the flight (trapezoids) it is the rotation of each frame.  The
    constant ``D`` is the one for which the rotation is zero at take-off and
    at landing, ``D = (sum w I^-1)^-1 sum w I^-1 h`` (trapezoid weights
    ``w``): the flight's angular momentum becomes constant, as equation 2
    asks, while the body leaves and meets the ground as oriented as it was
    (the paper's target, the flight's mean, turns the landing pose and
    leaves a rotation to carry into the ground).
    """
    n = q.shape[0]
    qq = np.einsum("l,flc,flc->f", masses, q, q)
    inertia = qq[:, None, None] * np.eye(3) - np.einsum("l,flc,fld->fcd", masses, q, q) + 1e-9 * np.eye(3)
    inv = np.linalg.inv(inertia)  # (n, 3, 3)
    w = np.full(n, dt)
    if n > 1:
        w[[0, -1]] = dt / 2.0
    target = np.linalg.solve(np.einsum("f,fij->ij", w, inv), np.einsum("f,fij,fj->i", w, inv, h))
    domega = np.einsum("fij,fj->fi", inv, target - h)  # equation 8, minus the current angular velocity
    out = np.zeros((n, 3))
    if n > 1:
        out[1:] = np.cumsum(0.5 * (domega[1:] + domega[:-1]), axis=0) * dt
    return out


def _flight_mask(n: int, stages: list[tuple[int, int]]) -> NDArray[np.bool_]:
    out = np.zeros(n, dtype=bool)
    for a, b in stages:
        out[a:b] = True
    return out


def _flight_step(
    posed: _Posed,
    body: Body,
    adj: Adjustment,
    sets: LinkSets,
    stages: list[tuple[int, int]],
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
    fps = motion.fps
    width = adj.width(fps)
    # S3 is empty in flight: S2 links rotate, S1 links (above or below) stay
    in_s2 = sets.roles[body.owners] == 2
    m = body.masses

    # ---- 3.4.1 angular momentum: average of the flight, by rotating S2
    width5 = paper_width(5.0, fps)
    s, v, _ = smoothed_derivatives(link_positions(motion, body, fk=posed[1:]), fps, width=width5)
    com = np.einsum("l,flc->fc", m, s) / m.sum()
    h = np.einsum("l,flc->fc", m, np.cross(s - com[:, None], v))
    centre = _flight_centre(motion, body, sets, s, posed.gpos)
    phi = np.zeros((n, 3))
    for a, b in stages:
        phi[a:b] = _momentum_rotation(s[a:b][:, in_s2] - centre[a:b, None], m[in_s2], h[a:b], dt)
    phi = _clamp_angle(_carry_into_windows(_clamp_angle(phi), stages, window, fps)) * adj.rho
    root_delta = None
    if 0 in sets.s2_tops:
        p = posed.gpos[:, pivot]
        root_delta = _smooth(_rotate_about(phi, centre, p) - p, width)
    out = _apply(posed, sets, _smooth(phi, width), root_delta, pivot)

    # ---- 3.4.2 parabolic centre of mass: translation first (the whole body,
    # which leaves the angular momentum about the centre of mass as it is)
    r = link_positions(out.motion, body, fk=out[1:])
    com = np.einsum("l,flc->fc", m, r) / m.sum()
    error = np.zeros((n, 3))
    for a, b in stages:
        error[a:b] = _ballistic(com[a], com[b - 1], b - a, dt) - com[a:b]
    delta = _smooth(_carry_into_windows(error, stages, window, fps) * adj.rho, width)
    moved = out.motion.transformed(translation=delta)  # at the pelvis below a static reference root
    carrier = out.motion.carrier_joint
    shift = delta[:, None, :] if carrier == 0 else delta[:, None, :] * _subtree(motion.skeleton, carrier)[:, None]
    out = _Posed(moved, out.grot, out.gpos + shift)
    if np.all(sets.roles == 2):
        return out
    # then rotate S2 about the S1/S2 boundary so its centre of mass moves
    # towards c*_M2 (equation 10) for what the translation left
    r = link_positions(out.motion, body, fk=out[1:])
    com = np.einsum("l,flc->fc", m, r) / m.sum()
    wanted = com.copy()
    for a, b in stages:
        wanted[a:b] = _ballistic(com[a], com[b - 1], b - a, dt)
    centre = _flight_centre(out.motion, body, sets, r, out.gpos)
    m2 = m[in_s2].sum()
    c2 = np.einsum("l,flc->fc", m[in_s2], r[:, in_s2]) / m2
    c2_star = c2 + (wanted - com) * m.sum() / m2
    rot = np.where(_flight_mask(n, stages)[:, None], quat.log(quat.between(c2 - centre, c2_star - centre)), 0.0)
    rot = _clamp_angle(_carry_into_windows(_clamp_angle(rot), stages, window, fps)) * adj.rho
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
    (:func:`mocaplab.goals.blend_weights`).
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


def _outside_flights(goals: Sequence[Goal], contacts: Contacts, fps: float) -> list[Goal]:
    """The goals with weights 0 on flight frames, fading in and out over :data:`PLANT_BLEND` next to them.

    A footplant goal that reaches into a flight pulls the airborne feet
    back toward the input after the flight adjustments and breaks the
    conserved angular momentum and the parabola they made; the fade lies
    on the ground frames (the one blend ramp, through
    :func:`mocaplab.goals.blend_weights`).  A foot planted up to
    take-off can slide there (CMU 16_05 bent by a quarter of its chord,
    refined and touched up: the toes 14.8 mm in the frame before take-off,
    2.0 in the input); fading inside the flight instead held it, but
    bent the flights off their parabolas (issue 24, open).
    """
    stages = flight_stages(contacts)
    if not stages:
        return list(goals)
    n = contacts.n_frames
    keep = 1.0 - blend_weights(n, stages, window=int(round(PLANT_BLEND * fps)))
    return [dataclasses.replace(g, weights=np.asarray(g.weights) * keep) for g in goals]


def _footplant_fn(
    footplants: Footplants, contacts: Contacts, reference: Motion
) -> Callable[[_Posed], _Posed] | None:
    """The footplant step of a touch-up, built once: goals met by the goal layer (:func:`mocaplab.goals.solve_goals`)."""
    if footplants is None:
        return None
    if callable(footplants):
        fn = footplants
        return lambda p: _posed(fn(p.motion, contacts, reference))
    if footplants not in ("auto", "plant", "refine", "ik"):
        raise ValueError(f"Expected `footplants` 'auto', 'plant', 'refine', 'ik', a callable or None, got {footplants!r}")
    if footplants == "refine":
        # Kim et al.'s s4.3 refinement without end effectors (mocaplab.refine's defaults), from the shared goal
        # layer: a paper package does not import another's
        return lambda p: _posed(enforce_goals(p.motion, foot_goals(p.motion, contacts, reference=reference, blend=0.1)))
    if footplants == "plant":
        goals = foot_goals(reference, contacts, reference=reference, blend=PLANT_BLEND)
    else:  # "ik", "auto"
        goals = _reference_goals(reference, contacts, blend=FOOT_BLEND)
    goals = _outside_flights(goals, contacts, reference.fps)
    sk = reference.skeleton
    columns = np.array([g.joint if isinstance(g.joint, int) else sk.index(g.joint) for g in goals], dtype=np.int64)
    gate_width = 4.0 * PLANT_BLEND * reference.fps

    def plant(p: _Posed) -> _Posed:
        # the goals hold only where the step moved a planted joint (_need_gate),
        # then solve_goals turns the legs' joints only (two-bone IK from the hips
        # down, then the ankles), lowering the root where a leg cannot reach, and
        # hands back the new kinematics (the legs' transforms recomputed, the rest kept)
        gate = _need_gate(p.gpos[:, columns], goals, gate_width)
        if not np.any(gate > 0):
            return p
        gated = [dataclasses.replace(g, weights=np.asarray(g.weights) * gate) for g in goals]
        new, fk = solve_goals(
            p.motion, gated, adjust_root=True, reach=0.99, max_drop=0.15, drop_window=0.15, dls_options=None,
            fk=(p.grot, p.gpos), return_fk=True,
        )
        return _Posed(new, *fk)

    return plant


def _need_gate(positions: Array, goals: Sequence[Goal], width: float) -> Array:
    """Where the footplant goals must hold, in [0, 1] per frame (F,): 1 where a step moved a planted joint.

    ``positions`` (F, G, 3) are the goals' joints now.  A frame whose planted
    joints are within :data:`PLANT_TOLERANCE` of their targets (weighted by
    the goals' weights) needs no correction; from there the gate rises with
    the blend ramp to 1 at twice that, is widened by ``width`` frames on each
    side and smoothed over ``width`` (:func:`_smooth`), so it changes with no
    jump.  The IK layer is not the identity on a pose that already meets its
    goals (a knee bent a fraction of a degree against its clip-wide hinge is
    carried over to the hinge's side): without the gate every footplant step
    redid that on frames the step never moved, and near-straight knees
    flipped back and forth between passes (a captured OptiTrack walk:
    ``LeftLeg`` 879 -> 1,978 rad/s^2 at a frame 120 frames from any change).
    """
    targets = np.stack([np.asarray(g.targets) for g in goals], axis=1)
    weights = np.stack([np.asarray(g.weights) for g in goals], axis=1)
    miss = (np.linalg.norm(positions - targets, axis=-1) * weights).max(axis=1)
    gate = blend_ramp(miss / PLANT_TOLERANCE - 1.0)
    if not np.any(gate > 0):
        return gate
    half = int(np.ceil(width))
    gate = maximum_filter1d(gate, size=2 * half + 1, mode="nearest")
    return np.clip(_smooth(gate, width), 0.0, 1.0)


# ======================================================================
# state, stepping, history
# ======================================================================
@dataclasses.dataclass(frozen=True, eq=False)
class TouchUpState:
    """Where a touch-up stands: the current motion and what comes next.

    Every array it holds or computes (kinematics, violation, the balance's)
    is read-only for good: a view of a read-only owner.

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
    step_scale : float
        Share in (0, 1] of each adjustment's ``rho`` that :func:`step` uses
        from this state on (the step size of :func:`touch_up`'s line search;
        1 applies the schedule as written).
    """

    motion: Motion
    reference: Motion
    body: Body
    contacts: Contacts
    schedule: tuple[Adjustment, ...]
    index: int
    balance: Balance
    label: str = "input"
    flight_window: float = FLIGHT_WINDOW
    footplants: Footplants = "auto"
    fix: Callable[[_Posed], _Posed] | None = None
    kinematics: tuple[Array, Array] | None = None
    roles: Roles | None = None
    path_joint: int = 0
    step_scale: float = 1.0

    def __post_init__(self) -> None:
        if not (np.isfinite(self.step_scale) and 0 < self.step_scale <= 1):
            raise ValueError(f"Expected `step_scale` in (0, 1] (a share of each adjustment's rho), got {self.step_scale!r}")
        # states share their kinematics with the next step: read-only for good
        # (the arrays are the touch-up's own, made read-only in place)
        if self.kinematics is not None:
            grot, gpos = self.kinematics
            object.__setattr__(self, "kinematics", (readonly(grot), readonly(gpos)))

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
        """Mean of :attr:`zmp_distance` over the ground frames with a ZMP, metres (Figure 9).

        All ground frames, the :attr:`edge_frames` that no adjustment
        corrects included (:attr:`mean_zmp_distance_interior` leaves them out).

        :attr:`dropped` ground frames without a ZMP are left out (never NaN:
        see :attr:`mocaplab.physics.Balance.mean_distance`).
        """
        return self.balance.mean_distance

    @property
    def dropped(self) -> int:
        """Ground frames without a ZMP (negative vertical ground force), left out of the means."""
        return self.balance.dropped

    @cached_property
    def violation(self) -> Array:
        """How far each frame is from its physical law, metres, shape (F,).

        Ground frames: the ZMP's distance outside the support polygon
        (:attr:`zmp_distance`; NaN where there is no ZMP, see
        :attr:`dropped`).  Flight frames: the distance of the centre of mass
        from the flight's ballistic path with the same take-off and landing
        points (the target of section 3.4.2).
        """
        out = np.array(self.balance.distance, copy=True)
        com, dt = self.balance.com, self.motion.dt
        for a, b in flight_stages(self.contacts):
            out[a:b] = np.linalg.norm(com[a:b] - _ballistic(com[a], com[b - 1], b - a, dt), axis=1)
        return readonly(out)

    @property
    def error(self) -> float:
        """The touch-up's error measure: the mean of :attr:`violation`, metres.

        Frames without a ZMP (:attr:`dropped`) are left out; on a clip
        without flights it is :attr:`mean_zmp_distance`.  The clip's
        :attr:`edge_frames` count too, though no adjustment corrects them:
        after a touch-up they can hold a large share of what is left (CMU
        16_15 and 02_01 at 120 fps, bent by 0.25-0.4 of their length and
        refined: their 20 end frames, 4-6 % of the clip, hold 18-32 % of the
        best pass's error, 9.1 mm whole vs 7.3 mm without them on 16_15
        bent by 0.25); :attr:`interior_error` is the same mean without them.
        """
        v = self.violation
        ok = np.isfinite(v)
        return float(v[ok].mean()) if ok.any() else float("inf")

    @property
    def edge_frames(self) -> int:
        """Frames at each end of the clip that no ground adjustment corrects (3 at 30 fps, 10 at 120 fps).

        Their accelerations come from a one-sided window, so their own
        corrections count with weight 0 (see the module notes); they keep
        about what the input had and can hold much of what is left of
        :attr:`error` (:attr:`interior_error` leaves them out).
        """
        return _edge_frames(self.motion.n_frames, self.motion.fps)

    @cached_property
    def interior(self) -> NDArray[np.bool_]:
        """Frames between the :attr:`edge_frames` at each end, shape (F,), read-only."""
        out = np.zeros(self.motion.n_frames, dtype=bool)
        e = self.edge_frames
        out[e : self.motion.n_frames - e] = True
        return readonly(out)

    @property
    def mean_zmp_distance_interior(self) -> float:
        """:attr:`mean_zmp_distance` over the :attr:`interior` frames only, metres.

        The frames a ground adjustment can correct: the difference from
        :attr:`mean_zmp_distance` is what the :attr:`edge_frames` keep.
        0.0 without interior ground frames, infinity when none has a ZMP.
        """
        d = self.balance.distance[self.interior]
        ok = np.isfinite(d)
        if ok.any():
            return float(d[ok].mean())
        return float("inf") if self.balance.ground[self.interior].any() else 0.0

    @property
    def interior_error(self) -> float:
        """:attr:`error` over the :attr:`interior` frames only, metres (see :attr:`edge_frames`)."""
        v = self.violation[self.interior]
        ok = np.isfinite(v)
        return float(v[ok].mean()) if ok.any() else float("inf")

    @cached_property
    def flights(self) -> tuple[FlightMeasure, ...]:
        """:func:`flight_measures` of :attr:`motion` over the input's flights (empty without flights).

        The ground frames' measure is :attr:`mean_zmp_distance` (flight
        frames have no ZMP): a flight step can raise it, since the ground
        frames next to a flight take the flight's change of velocity.
        """
        return flight_measures(self.motion, self.body, self.contacts, com=self.balance.com)

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
    flight_window: float = FLIGHT_WINDOW,
    footplants: Footplants = "auto",
    roles: Mapping[str, Any] | None = None,
) -> TouchUpState:
    """The initial state of a touch-up (no step done).  See :func:`touch_up`.

    Raises ValueError when no frame has a planted joint (nothing to balance,
    no take-off or landing to fit a flight to) and when the clip has no
    frame between its uncorrected ends (fewer than 7 frames at 30 fps, 21
    at 120 fps: :attr:`TouchUpState.edge_frames`); warns
    (:class:`TouchUpWarning`) about flights longer than :data:`LONG_FLIGHT`,
    feet that slide during their contacts (more than :data:`SLIDE_WARNING`
    over a median contact: the touch-up keeps the feet where the input has
    them, so plant them first with :func:`mocaplab.editing.refinement.refine`) and
    ground frames without a ZMP.
    """
    if not isinstance(motion, Motion):
        raise TypeError(f"Expected `motion` to be a Motion, got {type(motion).__name__}")
    edge = _edge_width(motion.fps)
    if motion.n_frames < 2 * edge + 1:
        raise ValueError(
            f"Expected `motion` of at least {2 * edge + 1} frames ({(2 * edge + 1) / motion.fps:.2f} s at "
            f"{motion.fps:g} fps), got {motion.n_frames}: the first and last {edge} frames of a clip are never "
            "corrected (their accelerations come from a one-sided window), so a shorter clip has no frame to touch "
            "up. Touch up the longer clip it was cut from"
        )
    known = resolve_roles(motion, roles)
    body = Body.from_skeleton(motion, roles=known) if body is None else body
    if not isinstance(body, Body):
        raise TypeError(f"Expected `body` to be a Body, got {type(body).__name__}")
    body.check(motion)
    contacts = default_contacts(motion, roles=known) if contacts is None else contacts
    _check_contacts(contacts, motion)
    if not (np.isfinite(flight_window) and flight_window >= 0):
        raise ValueError(f"Expected `flight_window` >= 0 seconds, got {flight_window!r}")
    _check_stages(motion, contacts)
    fix = _footplant_fn(footplants, contacts, motion)
    sched = _as_schedule(schedule, contacts)
    for adj in sched:
        link_sets(motion.skeleton, adj, roles=known)  # validate the link sets early
    posed = _posed(motion)
    bal = balance(motion, body, contacts=contacts, fk=posed[1:])
    _check_input(motion, contacts, bal, posed.gpos)
    path = known.index("pelvis") if "pelvis" in known else motion.path_joint
    return TouchUpState(
        motion, motion, body, contacts, sched, 0, bal, "input", float(flight_window), footplants, fix, posed[1:],
        known, int(path),
    )


def _check_stages(motion: Motion, contacts: Contacts) -> None:
    """No planted frame at all is an error; flights longer than :data:`LONG_FLIGHT` warn."""
    ground = np.asarray(contacts.mask, dtype=bool).any(axis=1)
    if not ground.any():
        raise ValueError(
            f"Expected `contacts` with a planted joint on at least one frame, got none on any of the "
            f"{motion.n_frames} frames: without ground frames there is no ZMP to balance and no take-off or "
            "landing to fit a flight to. Check the contact detection (mocaplab.contacts.foot_contacts: its "
            "`height` and `speed` thresholds, the clip's units) or pass `contacts=`"
        )
    long = [(a, b) for a, b in flight_stages(contacts, at_ends=True) if (b - a) / motion.fps > LONG_FLIGHT]
    if long:
        spans = ", ".join(f"frames {a}-{b - 1} ({(b - a) / motion.fps:.2f} s)" for a, b in long)
        warn(
            f"Flights longer than {LONG_FLIGHT:g} s: {spans}. A human jump lasts well under a second; are the "
            "contacts right (a walk whose feet are not detected as planted)? Each is touched up as one "
            "ballistic flight (one that touches the first or last frame is left alone)",
            TouchUpWarning,
        )


def _median_slide(gpos: Array, skeleton: Skeleton, contacts: Contacts) -> float:
    """Median horizontal slide of the planted joints over a contact interval, metres.

    Measured over the middle half of each interval of at least 4 frames and
    scaled to the whole interval: the detected intervals include the slow
    ends of a foot's landing and take-off, where even a captured foot still
    moves a few centimetres; its middle stays put.
    """
    slides = []
    for name in contacts.joints:
        j = skeleton.index(name)
        for a, b in contacts.intervals(name):
            if b - a < 4:
                continue
            q1, q3 = a + (b - a) // 4, a + (3 * (b - a)) // 4
            step_xz = (gpos[q3, j] - gpos[q1, j])[[0, 2]]
            slides.append(float(np.linalg.norm(step_xz)) * (b - a) / (q3 - q1))
    return float(np.median(slides)) if slides else 0.0


def _check_input(motion: Motion, contacts: Contacts, bal: Balance, gpos: Array) -> None:
    """Warn about sliding feet and ground frames without a ZMP."""
    slide = _median_slide(gpos, motion.skeleton, contacts)
    if slide > SLIDE_WARNING:
        warn(
            f"The planted joints slide by {100 * slide:.0f} cm over a median contact (more than "
            f"{100 * SLIDE_WARNING:.0f} cm): the touch-up keeps the feet where the input has them and measures "
            "balance against where they are. Run refine first: mocaplab.refine(edited, reference=original)",
            TouchUpWarning,
        )
    if bal.dropped:
        warn(
            f"{bal.dropped} of {int(bal.ground.sum())} ground frames have no ZMP (the vertical ground force "
            "would be negative: the body accelerates down faster than gravity); they are left out of the mean "
            "ZMP distance and of the corrections (TouchUpState.dropped counts them)",
            TouchUpWarning,
        )


def step(state: TouchUpState) -> TouchUpState:
    """Apply the next adjustment of the schedule: a new state (the input is untouched)."""
    if not isinstance(state, TouchUpState):
        raise TypeError(f"Expected a TouchUpState (see mocaplab.physics.start), got {type(state).__name__}")
    adj = state.next_adjustment
    if state.step_scale != 1.0:
        adj = adj.replace(rho=adj.rho * state.step_scale, label=adj.label)
    motion, body, contacts = state.motion, state.body, state.contacts
    posed = _Posed(motion, *state.kinematics) if state.kinematics is not None else _posed(motion)
    sets = link_sets(motion.skeleton, adj, roles=state.roles)
    if adj.stage == "ground":
        new = _ground_step(posed, body, adj, sets, state.balance, state.path_joint)
    elif stages := flight_stages(contacts):
        window = int(round(state.flight_window * motion.fps))
        new = _flight_step(posed, body, adj, sets, stages, window, state.path_joint)
    else:
        new = posed
    # a flight adjustment translates the whole body (section 3.4.2 here), so
    # it can move the feet whatever its link sets
    moves_feet = adj.stage == "flight" or _moves_contacts(motion.skeleton, sets, contacts)
    if state.fix is not None and new is not posed and moves_feet:
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
    stopped : str
        Why the touch-up stopped: ``"iterations"`` (the passes asked for
        were done), ``"stalled"`` (a pass lowered the best error by less than
        the tolerance), ``"solved"`` (the error reached 0) or ``""`` (a
        history built from a session).

    The per-step arrays (:attr:`errors`, :attr:`zmp_distance`, ...) are
    computed once and read-only.
    """

    states: tuple[TouchUpState, ...]
    stopped: str = ""

    @property
    def motions(self) -> list[Motion]:
        """The motion after each step; index 0 is the input."""
        return [s.motion for s in self.states]

    @property
    def best(self) -> int:
        """Index of the best state: the complete pass (or the input) with the lowest :attr:`TouchUpState.error`.

        Only states that end a pass over the schedule are candidates (inside
        a pass some link sets are not adjusted yet), and only those with no
        more ground frames without a ZMP than the input (dropping a frame
        must not pass for fixing it) and a mean ZMP distance over the
        ground frames at most :data:`ZMP_SLACK` (2 mm) above the input's (a
        touch-up never leaves the ground frames worse balanced).  The earliest wins a tie.
        """
        first = self.states[0]
        best, err = 0, first.error
        for k, st in enumerate(self.states[1:], start=1):
            if st.index % len(st.schedule) == 0 and _admissible(st, first) and st.error < err:
                best, err = k, st.error
        return best

    @property
    def final(self) -> Motion:
        """The touched-up motion: the :attr:`best` state's (more passes never make it worse)."""
        return self.states[self.best].motion

    @property
    def last(self) -> Motion:
        """The motion of the last state (what the stepper shows after the last step)."""
        return self.states[-1].motion

    @property
    def passes(self) -> int:
        """Complete passes over the schedule in the history."""
        return self.states[-1].iteration

    @property
    def labels(self) -> list[str]:
        """What each step did (index 0: ``"input"``)."""
        return [s.label for s in self.states]

    # the arrays below are computed once and read-only (motion.readonly): a
    # history is a record, and widgets read these on every redraw

    @cached_property
    def zmp_distance(self) -> Array:
        """ZMP distance outside the support polygon, per step and frame (NaN in flight), shape (S + 1, F)."""
        return readonly(np.stack([s.zmp_distance for s in self.states]))

    @cached_property
    def mean_zmp_distance(self) -> Array:
        """Mean ZMP distance per step (Figure 9), metres, shape (S + 1,); index 0 the input."""
        return readonly(np.array([s.mean_zmp_distance for s in self.states]))

    @cached_property
    def mean_zmp_distance_interior(self) -> Array:
        """:attr:`TouchUpState.mean_zmp_distance_interior` per step (the end frames left out), metres, shape (S + 1,)."""
        return readonly(np.array([s.mean_zmp_distance_interior for s in self.states]))

    @cached_property
    def errors(self) -> Array:
        """:attr:`TouchUpState.error` per step, metres, shape (S + 1,); index 0 the input."""
        return readonly(np.array([s.error for s in self.states]))

    @cached_property
    def interior_errors(self) -> Array:
        """:attr:`TouchUpState.interior_error` per step (the end frames left out), metres, shape (S + 1,)."""
        return readonly(np.array([s.interior_error for s in self.states]))

    @cached_property
    def dropped(self) -> NDArray[np.int64]:
        """Ground frames without a ZMP per step (left out of the means), shape (S + 1,)."""
        return readonly(np.array([s.dropped for s in self.states], dtype=np.int64))

    def __len__(self) -> int:
        return len(self.states)


def touch_up(
    motion: Motion,
    *,
    body: Body | None = None,
    schedule: str | Adjustment | Sequence[Adjustment] = "default",
    contacts: Contacts | None = None,
    iterations: int = ITERATIONS,
    tol: float | None = STALL_TOLERANCE,
    flight_window: float = FLIGHT_WINDOW,
    footplants: Footplants = "auto",
    roles: Mapping[str, Any] | None = None,
) -> TouchUpHistory:
    """Physically touch up a motion (Shin et al. 2003).

    Parameters
    ----------
    motion : Motion
        The (edited) motion; never modified.  Its feet should be planted
        (:func:`mocaplab.editing.refinement.refine`): the touch-up keeps them where
        they are and warns when they slide.
    body : Body, optional
        Masses; default :meth:`Body.from_skeleton` of the motion (de Leva table;
        measured in the motion's standing pose when the rest pose does not stand).  Fitted
        masses (:func:`mocaplab.physics.fit_masses`) make a captured clip
        change less.
    schedule : "default", "ground", "flight", Adjustment or sequence of Adjustment
        ``"default"``: the paper's flight schedule followed by its ground
        schedule when the clip has flight frames (each pass ends balancing
        the ground frames, landings included), else the ground schedule.
    contacts : Contacts, optional
        Planted joints of the input (default
        :func:`mocaplab.contacts.foot_contacts`); they decide ground versus
        flight frames and the support polygons.
    iterations : int
        Passes over the schedule, at most (default :data:`ITERATIONS`).
        Each pass is a line search: a pass that would raise
        :attr:`TouchUpState.error`, or leave the ground frames' mean ZMP
        distance more than :data:`ZMP_SLACK` above the input's, is done again with every ``rho`` halved,
        down to :data:`MIN_STEP` of it (the states record the step used,
        :attr:`TouchUpState.step_scale`); the next pass may double the step
        again.  When no step lowers the error the touch-up stops there, and
        when that happens on the first pass the input is returned with a
        :class:`TouchUpWarning` naming the worst frames and the limits hit.
    tol : float or None
        Stall tolerance: stop after a pass (the second or a later one) that
        lowers the error by less than ``tol`` times it (default :data:`STALL_TOLERANCE`, 5 %: a pass
        then buys less than a millimetre on a walk balanced to a few
        centimetres).  ``None`` runs all ``iterations`` passes (still
        stopping when no step lowers the error).
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
        Every state, the input first (``.motions``, ``.zmp_distance``,
        ``.mean_zmp_distance``, ``.errors``) along the accepted passes (the
        passes the line search rejected are not recorded), so the error at
        the end of each pass is lower than at the end of the one before;
        ``.final`` is the best complete pass (``.best``: the last one, or
        the input when no pass helped), ``.last`` the last state.
        ``.interior_errors`` and ``.mean_zmp_distance_interior`` are the
        same means without the first and last
        :attr:`~TouchUpState.edge_frames`, which no adjustment corrects:
        report them beside the whole, since those frames keep what the
        input had there.

    Examples
    --------
    >>> history = touch_up(bent_walk)                          # doctest: +SKIP
    >>> history.passes, history.stopped, history.errors[history.best]  # doctest: +SKIP
    """
    if isinstance(iterations, bool) or not isinstance(iterations, (int, np.integer)) or iterations < 0:
        raise ValueError(f"Expected `iterations` to be an integer >= 0, got {iterations!r}")
    if tol is not None and not (np.isfinite(tol) and tol >= 0):
        raise ValueError(f"Expected `tol` >= 0 (a share of the error) or None, got {tol!r}")
    state = start(
        motion, body=body, schedule=schedule, contacts=contacts, flight_window=flight_window, footplants=footplants,
        roles=roles,
    )
    states = [state]
    current = state.error
    stopped = "iterations"
    scale = 1.0
    rejected: list[tuple[float, float]] = []
    for k in range(int(iterations)):
        if current == 0.0:
            stopped = "solved"
            break
        trial, err, scale = _line_search(state, current, scale, states[0], rejected)
        if trial is None:
            stopped = "stalled"
            break
        states.extend(trial)
        state = trial[-1]
        before, current = current, err
        scale = min(1.0, 2.0 * scale)  # the next pass may take a longer step again
        # the first pass is not judged by its gain: around flights it can buy
        # little while the windows take the new take-off and landing
        # velocities, and the next passes much more (lesson 10)
        if tol is not None and k > 0 and before - err < tol * before:
            stopped = "stalled"
            break
    if len(states) == 1 and rejected:
        warn(_no_progress_message(state, rejected), TouchUpWarning)
    return TouchUpHistory(tuple(states), stopped)


def _run_pass(state: TouchUpState, scale: float) -> list[TouchUpState]:
    """One pass over the schedule from ``state`` with steps of ``scale`` times each ``rho``."""
    out = []
    state = dataclasses.replace(state, step_scale=scale)
    for _ in range(len(state.schedule)):
        state = step(state)
        out.append(state)
    return out


def _admissible(state: TouchUpState, first: TouchUpState) -> bool:
    """Whether ``state`` may stand for a touch-up of ``first`` (the input): no worse balanced on the ground.

    It must have no more ground frames without a ZMP than the input
    (dropping a frame must not pass for fixing it) and a mean ZMP distance
    over the ground frames at most :data:`ZMP_SLACK` above the input's.
    The error mixes ground and flight frames, and a flight step buys its
    parabola with the take-off and landing windows' balance: on CMU 16_05
    bent and refined, the error fell from 26.7 to 13.0 mm while the ground
    frames' mean ZMP distance rose from 6.3 to 15.8 mm, a touch-up that
    unbalanced the ground frames it was asked to balance.  On a clip
    without flights the error is that mean, so an accepted pass lowers it.
    """
    if state.dropped > first.dropped:
        return False
    return state.mean_zmp_distance <= first.mean_zmp_distance + ZMP_SLACK


def _line_search(
    state: TouchUpState, current: float, scale: float, first: TouchUpState, rejected: list[tuple[float, float]]
) -> tuple[list[TouchUpState] | None, float, float]:
    """A pass that lowers the error: the step halved from ``scale`` until it does, down to :data:`MIN_STEP`.

    Returns the pass's states, its error and the step used; ``(None, current,
    scale)`` when no step down to :data:`MIN_STEP` lowers the error.  A pass
    that is not :func:`_admissible` against the input ``first`` does not
    count as lower.  Rejected tries are appended to ``rejected`` as
    ``(step, error)``.
    """
    while scale >= MIN_STEP:
        trial = _run_pass(state, scale)
        end = trial[-1]
        err = end.error if _admissible(end, first) else float("inf")
        if err < current:
            return trial, err, scale
        rejected.append((scale, err))
        scale /= 2.0
    return None, current, scale


def _no_progress_message(state: TouchUpState, rejected: Sequence[tuple[float, float]]) -> str:
    """Why a touch-up returned its input: the steps tried, the worst frames, the frames out of reach."""
    tries = ", ".join(f"x{s:g}: {1000 * e:.1f} mm" if np.isfinite(e) else f"x{s:g}: frames lost their ZMP"
                      for s, e in rejected)
    v = np.nan_to_num(state.violation, nan=0.0)
    worst = intervals_from_mask(v >= 0.5 * v.max()) if v.max() > 0 else []
    spans = ", ".join(f"{a}-{b - 1}" if b - a > 1 else f"{a}" for a, b in worst[:6])
    out_of_balance = state.balance.distance > 0
    reach = []
    for adj in dict.fromkeys(a for a in state.schedule if a.stage == "ground"):
        sets = link_sets(state.motion.skeleton, adj, roles=state.roles)
        gpos = state.kinematics[1] if state.kinematics is not None else None
        _, _, exact = _ground_rotation(state.motion, state.body, sets, state.balance, np.ones(state.motion.n_frames), gpos)
        reach.append(f"{int(np.sum(out_of_balance & ~exact))} for {'+'.join(adj.s2)}")
    limits = (
        f"; of the {int(out_of_balance.sum())} ground frames out of balance, no rotation within "
        f"{np.degrees(MAX_ANGLE):.0f} degrees (MAX_ANGLE) puts the ZMP on the support polygon on "
        + ", ".join(reach) if reach else ""
    )
    flights = flight_stages(state.contacts)
    flight_text = (
        "; flights " + ", ".join(f"{a}-{b - 1}" for a, b in flights) + f" (flight_window {state.flight_window:g} s)"
        if flights else ""
    )
    return (
        f"The touch-up returns its input unchanged: no pass over the schedule lowered its error of "
        f"{1000 * state.error:.1f} mm, at any step from x{rejected[0][0]:g} down to x{MIN_STEP:g} of each rho "
        f"(MIN_STEP; errors after one pass: {tries}). The worst frames are {spans} (at least half the largest "
        f"violation, {1000 * v.max():.1f} mm){limits}{flight_text}. Try another schedule, a smaller sigma or, "
        "around flights, a shorter flight_window"
    )


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
