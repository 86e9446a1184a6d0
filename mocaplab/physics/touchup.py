"""Physical touch-up of edited motions (Shin, Kovar and Gleicher 2003).

A touch-up is a sequence of **adjustments** (a *schedule*: each one names
the link sets S1, S2 and S3 of section 3.1, a time scale ``sigma`` and a
damping factor ``rho``).  One step (Figure 2):

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

Where each part lives (each module imports only the ones listed below it):

* :mod:`mocaplab.physics.touchup`, this module: :func:`touch_up` (passes,
  line search), :class:`TouchUpHistory`, :class:`TouchUpSession`;
* :mod:`mocaplab.physics.state`: :class:`TouchUpState`, :func:`start`,
  :func:`step` (Figure 2), the input checks;
* :mod:`mocaplab.physics.ground` (section 3.3), :mod:`mocaplab.physics.flight`
  (section 3.4, :func:`~mocaplab.physics.flight.flight_measures`) and
  :mod:`mocaplab.physics.footplants` (the footplant step);
* :mod:`mocaplab.physics.adjust`: Figure 2's steps 2-3 (smoothing,
  displacement maps, rotation centres);
* :mod:`mocaplab.physics.schedule` (section 3.1): adjustments, schedules,
  link sets, :func:`flight_stages`.

Choices made where the paper leaves them open
---------------------------------------------
* Convergence is kept by a line search on each pass (:func:`touch_up`),
  not by leaving frames out: a pass that raises the error is done again
  with half the step (every ``rho`` halved), down to :data:`MIN_STEP`.
  With it the walk of lesson 09 tilted 20 degrees uphill falls on every
  pass (158.9 -> 9.2 mm over 20 passes; with the zero weights it fell to
  61.4 mm and rose again on 16 of 20 passes to 145.4 mm), and the bent
  jump of lesson 10 with the paper's 0.5 s flight window improves (8.8 ->
  3.3 mm in 3 passes; a full first step raises it to 12.6 mm).
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

Examples
--------
>>> from mocaplab.data import cmu                               # doctest: +SKIP
>>> from mocaplab.physics import touch_up                       # doctest: +SKIP
>>> history = touch_up(cmu("16_15").resample(30), iterations=2)  # doctest: +SKIP
>>> history.mean_zmp_distance                                   # doctest: +SKIP
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping, Sequence
from functools import cached_property
from typing import TYPE_CHECKING, Any, Literal

import numpy as np
from numpy.typing import NDArray

from .._api import Gone
from .._checks import integer, real
from .._warnings import warn
from ..contacts import intervals_from_mask
from ..motion import Motion, readonly
from .adjust import MAX_ANGLE
from .body import Body, Inertia
from .flight import FLIGHT_WINDOW
from .footplants import Footplants
from .ground import _ground_rotation
from .schedule import Adjustment, flight_stages, link_sets
from .state import TouchUpState, TouchUpWarning, start, step

if TYPE_CHECKING:  # pragma: no cover
    from ..contacts import Contacts

__all__ = ["GroundReach", "TouchUpHistory", "ground_reach", "touch_up", "TouchUpSession"]

Array = NDArray[np.float64]

#: Default stall tolerance of :func:`touch_up`: it stops after a pass that
#: lowers the error by less than this share of it.  With 2 % the passes that
#: buy 2-5 % each on captured walks (a few tenths of a millimetre) went on
#: moving the hands by up to 6.5 cm (CMU 16_11); with 5 % they stop at
#: 5.7 cm, and walks bent by 0.4 of their length still end at a quarter of
#: their mean ZMP distance.
STALL_TOLERANCE = 0.05
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
#: How much a touch-up may raise the ground frames' mean ZMP distance above
#: its input's, metres (:func:`_admissible`): what a flight step may cost the
#: take-off and landing windows when it gives the flight its parabola (the
#: captured jump CMU 16_05: 0.63 -> 0.70 mm while the flight error halves;
#: lesson 10's bent jump 0.27 -> 2.1 mm, 3.8 without the bound).  2 mm is
#: what the quality pipeline allows a touch-up (tests/test_quality_pipeline.py).
ZMP_SLACK = 2e-3


@dataclasses.dataclass(frozen=True, eq=False)
class TouchUpHistory:
    """Every state of a touch-up, index 0 the input.

    The per-step arrays (:attr:`errors`, :attr:`zmp_distance`, ...) are
    computed once and read-only.

    Parameters
    ----------
    states : tuple of TouchUpState
    stopped : str
        Why the touch-up stopped: ``"iterations"`` (the passes asked for
        were done), ``"stalled"`` (a pass lowered the best error by less than
        the tolerance), ``"solved"`` (the error reached 0) or ``""`` (a
        history built from a session).

    Examples
    --------
    >>> import mocaplab as ml
    >>> walk = ml.cmu("16_15").resample(30)[:60]
    >>> state = ml.physics.start(walk)
    >>> history = ml.physics.TouchUpHistory((state, ml.physics.step(state)))
    >>> len(history.motions), history.stopped
    (2, '')
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
    def motion(self) -> Motion:
        """The touched-up motion: the :attr:`best` state's (more passes never make it worse)."""
        return self.states[self.best].motion

    final = Gone("read .motion (the touched-up motion, as every result in mocaplab gives its output)")

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
    contacts: Contacts | Literal["auto"] | None = "auto",
    iterations: int = ITERATIONS,
    tol: float | None = STALL_TOLERANCE,
    flight_window: float = FLIGHT_WINDOW,
    footplants: Footplants = "auto",
    roles: Mapping[str, Any] | None = None,
    inertia: Inertia = "points",
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
    contacts : "auto" or Contacts
        Planted joints of the input; they decide ground versus flight
        frames and the support polygons.  ``"auto"`` (default) detects them
        (:func:`mocaplab.contacts.foot_contacts`); ``None`` (no contacts)
        raises ValueError: nothing would stand on the ground.
    iterations : int
        Passes over the schedule, at most (default :data:`ITERATIONS`), >= 0.
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
        and blended to zero (0.5 s in the paper), from 0 to
        :data:`mocaplab.goals.MAX_WINDOW`.
    footplants : "auto", "plant", "refine", "ik", callable or None
        Re-enforcement of the footplants after each step (see the module
        notes); a callable gets ``(motion, contacts, reference)``.
    roles : mapping of role names to joint names, optional
        Overrides of the inferred joint roles
        (:func:`mocaplab.roles.resolve_roles`), used for the default body,
        the default contacts, the presets and the travelling joint.
    inertia : "points" or "segments"
        What the flight adjustments keep the angular momentum of (equations
        8-9): ``"points"`` (default), the paper's point masses at the link
        centres; ``"segments"``, each link a rigid segment with de Leva's
        radii of gyration (:attr:`Body.inertia`), whose own spin is 7-42 %
        of the angular momentum on the CMU flights (the paper reckons it
        under 2 %) and which the point masses leave out.  The body must have
        segment inertia (the default body has).

    Returns
    -------
    TouchUpHistory
        Every state, the input first (``.motions``, ``.zmp_distance``,
        ``.mean_zmp_distance``, ``.errors``) along the accepted passes (the
        passes the line search rejected are not recorded), so the error at
        the end of each pass is lower than at the end of the one before;
        ``.motion`` is the best complete pass (``.best``: the last one, or
        the input when no pass helped), ``.last`` the last state.
        ``.interior_errors`` and ``.mean_zmp_distance_interior`` are the
        same means without the first and last
        :attr:`~TouchUpState.edge_frames`, which no adjustment corrects:
        report them beside the whole, since those frames keep what the
        input had there.

    Examples
    --------
    Two passes over two seconds of a walk: the mean ZMP distance outside the
    support polygon (mm) before and after.

    >>> import mocaplab as ml
    >>> history = ml.physics.touch_up(ml.cmu("16_15").resample(30)[:60], iterations=2)
    >>> history.passes, history.stopped
    (2, 'iterations')
    >>> before, after = history.mean_zmp_distance[[0, history.best]]
    >>> round(1000 * float(before), 1), round(1000 * float(after), 1)
    (12.5, 7.2)
    """
    iterations = integer(iterations, "iterations", low=0, why="passes over the schedule")
    if tol is not None:
        tol = real(tol, "tol", low=0.0, unit="(a share of the error) or None")
    state = start(
        motion, body=body, schedule=schedule, contacts=contacts, flight_window=flight_window, footplants=footplants,
        roles=roles, inertia=inertia,
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
    out_of_balance = (state.balance.distance > 0) & state.interior
    reach = [
        f"{ground_reach(state, adj).n_closest} for {'+'.join(adj.s2)}"
        for adj in dict.fromkeys(a for a in state.schedule if a.stage == "ground")
    ]
    limits = (
        f"; of the {int(out_of_balance.sum())} ground frames out of balance between the clip's ends, no rotation within "
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


@dataclasses.dataclass(frozen=True, eq=False)
class GroundReach:
    """Which out-of-balance frames a ground adjustment balances exactly, and which take the closest approach.

    Made by :func:`ground_reach`, not by hand; the masks are read-only.  Both masks cover the frames the
    adjustment corrects that are out of balance: ground frames with a ZMP
    outside the support polygon, between the clip's
    :attr:`~TouchUpState.edge_frames` (no adjustment corrects those).

    Parameters
    ----------
    adjustment : Adjustment
        The ground adjustment the frames were solved for.
    exact : ndarray of bool, shape (F,)
        Frames where a rotation of S2 within :data:`~mocaplab.physics.adjust.MAX_ANGLE` puts
        the ZMP on the support polygon (equation 7 has a solution).
    closest : ndarray of bool, shape (F,)
        Frames where none does: S2 turns by the angle that brings the ZMP
        closest to the polygon (section 3.3, ``cos(theta + phi) = +-1``),
        clamped to ``MAX_ANGLE``; these frames are corrected too, towards
        the polygon.

    Examples
    --------
    >>> import mocaplab as ml
    >>> state = ml.physics.start(ml.cmu("16_15").resample(30)[:60])
    >>> reach = ml.physics.ground_reach(state, ml.physics.GROUND_SCHEDULE[2])  # the arms
    >>> reach.adjustment.label, reach.n_exact, reach.n_closest
    ('ground: arms (S2)', 8, 16)
    """

    adjustment: Adjustment
    exact: NDArray[np.bool_]
    closest: NDArray[np.bool_]

    def __post_init__(self) -> None:
        object.__setattr__(self, "exact", readonly(np.asarray(self.exact, dtype=bool)))
        object.__setattr__(self, "closest", readonly(np.asarray(self.closest, dtype=bool)))

    @property
    def n_exact(self) -> int:
        """Number of :attr:`exact` frames."""
        return int(self.exact.sum())

    @property
    def n_closest(self) -> int:
        """Number of :attr:`closest` frames."""
        return int(self.closest.sum())


def ground_reach(state: TouchUpState, adjustment: Adjustment | None = None) -> GroundReach:
    """Which out-of-balance frames of a state a ground adjustment balances exactly, which only get closer.

    On each ground frame the closed form of equations 6-7 gives the
    rotation of S2 that puts the ZMP on the support polygon; where no
    rotation (within :data:`~mocaplab.physics.adjust.MAX_ANGLE`) does, the
    touch-up applies the one that brings the ZMP closest (section 3.3).
    This tells the two kinds of frame apart, before the step is taken.

    Parameters
    ----------
    state : TouchUpState
        Where the touch-up stands (:func:`start`, :func:`step`, or any of
        :attr:`TouchUpHistory.states`).
    adjustment : Adjustment, optional
        A ground adjustment; default the state's
        :attr:`~TouchUpState.next_adjustment`, the one :func:`step` applies
        next.  For a history, ``ground_reach(h.states[k])`` is what step
        ``k + 1`` worked with.  The step size (``rho``) does not matter.

    Returns
    -------
    GroundReach
        Per-frame masks ``exact`` and ``closest`` with their counts.

    Raises
    ------
    TypeError
        When ``state`` is not a TouchUpState or ``adjustment`` not an Adjustment.
    ValueError
        When the adjustment is a flight adjustment (flight frames have no ZMP).

    Examples
    --------
    Two seconds of a captured walk: the lower body balances every frame
    out of balance exactly, the arms a third of them.

    >>> import mocaplab as ml
    >>> from mocaplab.physics import GROUND_SCHEDULE, ground_reach, start
    >>> state = start(ml.cmu("16_15").resample(30)[:60])
    >>> [(ground_reach(state, adj).n_exact, ground_reach(state, adj).n_closest) for adj in GROUND_SCHEDULE]
    [(24, 0), (19, 5), (8, 16)]
    """
    if not isinstance(state, TouchUpState):
        raise TypeError(
            f"Expected `state` to be a TouchUpState (see mocaplab.physics.start), got {type(state).__name__}"
        )
    adj = state.next_adjustment if adjustment is None else adjustment
    if not isinstance(adj, Adjustment):
        raise TypeError(f"Expected `adjustment` to be an Adjustment or None, got {type(adj).__name__}")
    if adj.stage != "ground":
        raise ValueError(
            f"Expected a ground adjustment, got the flight adjustment {adj.label!r}: flight frames have no ZMP to "
            "balance. Pass one of the schedule's ground adjustments as `adjustment`"
        )
    sets = link_sets(state.motion.skeleton, adj, roles=state.roles)
    gpos = state.kinematics[1] if state.kinematics is not None else None
    corrected = state.interior.astype(float)
    _, _, exact = _ground_rotation(state.motion, state.body, sets, state.balance, corrected, gpos)
    out = (state.balance.distance > 0) & state.interior  # NaN (flight, no ZMP) compares False
    return GroundReach(adj, out & exact, out & ~exact)


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
        ``flight_window``, ``footplants``, ``roles``, ``inertia``).

    Examples
    --------
    >>> import mocaplab as ml
    >>> session = ml.physics.TouchUpSession(ml.cmu("16_15").resample(30)[:60])
    >>> session.forward().label
    'ground: lower body (S2), upper body (S3)'
    >>> session.back().index, session.index
    (0, 0)
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
