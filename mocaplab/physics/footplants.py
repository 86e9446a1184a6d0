"""Footplants of a physical touch-up (Shin, Kovar and Gleicher 2003, section 3.1).

The contacts the input is labelled with are kinematic constraints that
must still hold after the touch-up (section 3.1).  This module builds the
footplant step once, from the input (:func:`_footplant_fn`): goals of the
shared goal layer (:mod:`mocaplab.goals`; a paper package never imports
another, so not :mod:`mocaplab.editing`), kept off the flights
(:func:`_outside_flights`, with :func:`mocaplab.physics.schedule.flight_stages`)
and gated to the frames a step moved (:func:`_need_gate`, smoothed like the
adjustments of :mod:`mocaplab.physics.adjust`).  :func:`mocaplab.physics.start`
builds it and :func:`mocaplab.physics.step` runs it after every step that
can move a contact joint.

Choices made where the paper leaves them open
---------------------------------------------
* Footplants are re-enforced after every step that can move a contact
  joint (an adjustment of the upper body or the arms leaves the feet
  alone on ground frames; a flight adjustment translates the whole body),
  per frame like the paper's choice (Kovar et al. 2002, "because of its
  efficiency").  There is one correction layer: footplants are goals
  (:class:`mocaplab.goals.Goal`), built once from the input's
  contacts in :func:`mocaplab.physics.start`, and met after each step by the goal
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
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable, Sequence
from typing import TYPE_CHECKING, Literal

import numpy as np
from numpy.typing import NDArray
from scipy.ndimage import maximum_filter1d

from ..contacts import intervals_from_mask
from ..displacement import blend_ramp
from ..goals import Goal, blend_weights, enforce_goals, foot_goals, solve_goals
from ..motion import Motion
from .adjust import _Posed, _posed, _smooth
from .schedule import flight_stages

if TYPE_CHECKING:  # pragma: no cover
    from ..contacts import Contacts

Array = NDArray[np.float64]
Footplants = Literal["auto", "plant", "refine", "ik"] | Callable[[Motion, "Contacts", Motion], Motion] | None

#: Blend window of the ``"ik"`` footplant goals on each side of a plant, seconds.
FOOT_BLEND = 0.2
#: Blend window of the ``"plant"`` goals on each side of a contact, and the
#: ramp by which every footplant goal fades out on the ground frames next to
#: a flight (goal weights are 0 on flight frames), seconds.
PLANT_BLEND = 0.05
#: A planted joint within this distance of its footplant goal (metres) needs
#: no correction (:func:`_need_gate`); the goals hold fully from twice it.
PLANT_TOLERANCE = 5e-4


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
        weights = blend_weights(reference.n_frames, planted, window_frames=window)
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
    keep = 1.0 - blend_weights(n, stages, window_frames=int(round(PLANT_BLEND * fps)))
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
