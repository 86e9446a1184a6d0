"""The state of a physical touch-up and its one step (Shin, Kovar and Gleicher 2003, Figure 2).

:class:`TouchUpState` is where a touch-up stands: the motion with its
forward kinematics and ZMP analysis, the input's contacts and footplant
step, the schedule and how far along it is.  :func:`start` checks the input
(:class:`TouchUpWarning` for suspicious input) and builds the first state;
:func:`step` applies the next adjustment of the schedule
(:mod:`mocaplab.physics.schedule`): the ground step of
:mod:`mocaplab.physics.ground` or the flight step of
:mod:`mocaplab.physics.flight`, then the footplant step of
:mod:`mocaplab.physics.footplants`.  :mod:`mocaplab.physics.touchup` drives
the steps (passes, line search, history, the interactive session); the two
are separate modules so that each stays under 800 lines.

Choices made where the paper leaves them open
---------------------------------------------
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
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable, Mapping, Sequence
from functools import cached_property
from typing import TYPE_CHECKING, Any, Literal

import numpy as np
from numpy.typing import NDArray

from .._checks import real
from .._warnings import warn
from ..goals import MAX_WINDOW
from ..motion import Motion, Skeleton, readonly
from ..roles import Roles, resolve_roles
from .adjust import _Posed, _posed
from .body import Body, Inertia, check_inertia
from .flight import FLIGHT_WINDOW, FlightMeasure, _ballistic, _flight_step, flight_measures
from .footplants import Footplants, _footplant_fn
from .ground import _edge_frames, _edge_width, _ground_step
from .schedule import Adjustment, LinkSets, _as_schedule, check_schedule, flight_stages, link_sets
from .zmp import Balance, _check_contacts, _rebalance, balance, ground_contacts

if TYPE_CHECKING:  # pragma: no cover
    from ..contacts import Contacts

__all__ = ["TouchUpWarning", "TouchUpState", "start", "step"]

Array = NDArray[np.float64]

#: Flights longer than this (seconds) are suspicious (contacts missing?): a warning.
LONG_FLIGHT = 1.5
#: A median slide of the planted joints over their contact intervals above
#: this (metres) warns that the feet slide ("run refine first").
SLIDE_WARNING = 0.05


class TouchUpWarning(UserWarning):
    """Suspicious input to a touch-up (long flights, sliding feet, frames without a ZMP).

    Parameters
    ----------
    *args
        The message, as for any warning.

    Examples
    --------
    >>> from mocaplab.physics import TouchUpWarning
    >>> issubclass(TouchUpWarning, UserWarning)
    True
    """


@dataclasses.dataclass(frozen=True, eq=False)
class TouchUpState:
    """Where a touch-up stands: the current motion and what comes next.

    Every array it holds or computes (kinematics, violation, the balance's)
    is read-only for good: a view of a read-only owner.  Made by
    :func:`start` and :func:`step`, not by hand.

    Parameters
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
        from this state on (the step size of :func:`mocaplab.physics.touch_up`'s line search;
        1 applies the schedule as written).
    inertia : "points" or "segments"
        The angular momentum the flight adjustments keep constant and
        :attr:`flights` measures: the paper's point masses or rigid segments
        (see :func:`mocaplab.physics.touch_up`).

    Examples
    --------
    >>> import mocaplab as ml
    >>> walk = ml.cmu("16_15").resample(30)[:60]
    >>> state = ml.physics.start(walk)
    >>> state.index, state.label, len(state.schedule)
    (0, 'input', 3)
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
    inertia: Inertia = "points"

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
        corrections count with weight 0 (see :mod:`mocaplab.physics.ground`); they keep
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
        return flight_measures(self.motion, self.body, self.contacts, com=self.balance.com, inertia=self.inertia)

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
    contacts: Contacts | Literal["auto"] | None = "auto",
    flight_window: float = FLIGHT_WINDOW,
    footplants: Footplants = "auto",
    roles: Mapping[str, Any] | None = None,
    inertia: Inertia = "points",
) -> TouchUpState:
    """The initial state of a touch-up (no step done).  See :func:`mocaplab.physics.touch_up`.

    Parameters
    ----------
    motion : Motion
        The motion to touch up; never modified.
    body : Body, optional
        Masses; default :meth:`Body.from_skeleton` of the motion.
    schedule : "default", "ground", "flight", Adjustment or sequence of Adjustment
        The adjustments, cycled through (see :func:`mocaplab.physics.touch_up`).
    contacts : "auto" or Contacts
        Planted joints of the input, fixed for the whole touch-up (``"auto"``:
        :func:`mocaplab.contacts.foot_contacts`).
    flight_window : float, default 0.1
        Seconds of ground frames around a flight adjusted as flight.
    footplants : "auto", callable or None
        How footplants are re-enforced after each step (see :func:`mocaplab.physics.touch_up`).
    roles : mapping, optional
        Joint-role overrides (:func:`mocaplab.roles.resolve_roles`).
    inertia : "points" or "segments"
        Point masses (the paper's, default) or rigid segments in flight
        (see :func:`mocaplab.physics.touch_up`).

    Returns
    -------
    TouchUpState
        ``index`` 0, the input's balance measured.

    Raises
    ------
    ValueError
        When no frame has a planted joint (nothing to balance, no take-off or
        landing to fit a flight to) and when the clip has no frame between its
        uncorrected ends (fewer than 7 frames at 30 fps, 21 at 120 fps:
        :attr:`TouchUpState.edge_frames`).

    Warns
    -----
    TouchUpWarning
        About flights longer than :data:`LONG_FLIGHT`, feet that slide during
        their contacts (more than :data:`SLIDE_WARNING` over a median contact:
        the touch-up keeps the feet where the input has them, so plant them
        first with :func:`mocaplab.editing.refinement.refine`) and ground
        frames without a ZMP.

    Examples
    --------
    >>> import mocaplab as ml
    >>> walk = ml.cmu("16_15").resample(30)[:60]
    >>> state = ml.physics.start(walk, schedule="ground")
    >>> state.index, state.next_adjustment.label
    (0, 'ground: lower body (S2), upper body (S3)')
    """
    if not isinstance(motion, Motion):
        raise TypeError(f"Expected `motion` to be a Motion, got {type(motion).__name__}")
    # the options first, before any role, body or contact is worked out
    check_schedule(schedule)
    flight_window = real(flight_window, "flight_window", low=0.0, high=MAX_WINDOW, unit="seconds")
    inertia = check_inertia(inertia)
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
    check_inertia(inertia, body)
    contacts = ground_contacts(contacts, motion, roles=known)
    _check_contacts(contacts, motion)
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
        known, int(path), inertia=inertia,
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
    """Apply the next adjustment of the schedule: a new state (the input is untouched).

    Parameters
    ----------
    state : TouchUpState
        From :func:`start` or an earlier :func:`step`.

    Returns
    -------
    TouchUpState
        ``index`` one higher, labelled with the adjustment applied.

    Raises
    ------
    TypeError
        When ``state`` is not a TouchUpState.

    Examples
    --------
    >>> import mocaplab as ml
    >>> walk = ml.cmu("16_15").resample(30)[:60]
    >>> first = ml.physics.step(ml.physics.start(walk))
    >>> first.index, first.label
    (1, 'ground: lower body (S2), upper body (S3)')
    """
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
        new = _flight_step(posed, body, adj, sets, stages, window, state.path_joint, state.inertia)
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

