"""Flight frames of a physical touch-up (Shin, Kovar and Gleicher 2003, section 3.4).

In the air only gravity acts: the centre of mass flies a parabola and the
angular momentum about it is constant (equations 1 and 2);
:func:`flight_measures` says how well a motion obeys both.  On the flight
frames (:func:`mocaplab.physics.schedule.flight_stages`) :func:`_flight_step`
first computes the rotation of S2 giving a constant angular momentum
(equations 8-9, :func:`_momentum_rotation`), then the translation and
rotation putting the centre of mass on the parabola with
``v0 = d / T - g T / 2`` (:func:`_ballistic`, equation 10); each is
scaled, smoothed and applied with the shared machinery of
:mod:`mocaplab.physics.adjust`, and carried into the ground frames next to
the flight (:func:`_carry_into_windows`).  :func:`mocaplab.physics.step`
calls :func:`_flight_step` for each flight adjustment.

Choices made where the paper leaves them open
---------------------------------------------
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
* The paper's point masses leave out each link's own spin.  With
  ``inertia="segments"`` the links are rigid segments
  (:attr:`~mocaplab.physics.Body.inertia`): their spin is part of ``h`` and
  their own inertia part of ``I`` in equation 8, so the rigid body's angular
  momentum is what becomes constant.  On the 62 flights of eight CMU clips at
  30 and 120 fps the point-mass touch-up let the rigid body's spread grow on
  4 (the jog 16_35) while its own fell on all; with segments the rigid
  body's falls on all 62 (mean 0.39 -> 0.26 kg m^2/s on 16_35 at 120 fps,
  where the point masses gave 0.40).
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
"""

from __future__ import annotations

from typing import TYPE_CHECKING, NamedTuple

import numpy as np
from numpy.typing import ArrayLike, NDArray

from .. import quat
from ..displacement import blend_ramp
from ..motion import Motion
from .adjust import MAX_ANGLE, _apply, _Posed, _root_pivot, _rotate_about, _smooth
from .body import (
    GRAVITY,
    Body,
    Inertia,
    _segment_spin,
    angular_momentum,
    center_of_mass,
    check_inertia,
    link_positions,
    paper_width,
    smoothed_derivatives,
)
from .schedule import Adjustment, LinkSets, _subtree, flight_stages

if TYPE_CHECKING:  # pragma: no cover
    from ..contacts import Contacts

__all__ = ["FLIGHT_WINDOW", "FlightMeasure", "flight_measures"]

Array = NDArray[np.float64]

#: Default ``flight_window``: seconds of ground frames on each side of a
#: flight that take the flight adjustments' changes of velocity (see the
#: module notes; the paper used 0.5 s).
FLIGHT_WINDOW = 0.1
#: Fewest frames of a flight a parabola is fitted to (:func:`flight_measures`);
#: three points fix one exactly, fewer leave its curvature free.
MIN_FIT_FRAMES = 3


class FlightMeasure(NamedTuple):
    """How well one flight ``[start, stop)`` obeys the two laws of section 3.4 (:func:`flight_measures`).

    Parameters
    ----------
    start : int
        First frame of the flight.
    stop : int
        One past its last frame.
    gravity : float
        Gravity fitted to the centre of mass's height, m/s^2 (NaN when too short to fit).
    momentum_spread : float
        Mean distance of the angular momentum from its mean over the flight, kg m^2/s.
    spin_share : float or None, optional
        With ``inertia="segments"``: the links' own spin as a share of the
        angular momentum over the flight (mean magnitudes); None with point
        masses, which have none.

    Examples
    --------
    >>> from mocaplab.physics import FlightMeasure
    >>> hop = FlightMeasure(start=10, stop=20, gravity=9.7, momentum_spread=0.5)
    >>> hop.frames, hop.fitted
    (10, True)
    """

    #: First frame of the flight.
    start: int
    #: One past its last frame.
    stop: int
    #: Gravity fitted to the centre of mass's height, m/s^2 (9.81 when it flies a parabola; equation 1).
    gravity: float
    #: Mean distance of ``h_CM`` from its mean over the flight, kg m^2/s (0 when constant; equation 2).
    momentum_spread: float
    #: The links' own spin as a share of ``h_CM`` over the flight (``inertia="segments"``; None for point masses).
    spin_share: float | None = None

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
    motion: Motion, body: Body, contacts: Contacts, *, com: ArrayLike | None = None, inertia: Inertia = "points"
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
    inertia : "points" or "segments"
        The angular momentum of the paper's point masses (default) or of
        rigid segments (:func:`~mocaplab.physics.angular_momentum`); with
        segments each flight also says how much of it the links' own spin
        is (:attr:`FlightMeasure.spin_share`).

    Returns
    -------
    tuple of FlightMeasure
        Empty when the clip has no flight.

    Examples
    --------
    A walk always has a foot down:

    >>> import mocaplab as ml
    >>> walk = ml.cmu("16_15").resample(30)[:60]
    >>> body = ml.physics.Body.from_skeleton(walk.skeleton)
    >>> ml.physics.flight_measures(walk, body, ml.contacts.foot_contacts(walk))
    ()

    A standing vertical jump, its body as rigid segments: the segments' own
    spin is a fifth of its angular momentum in the air (the point masses
    of the paper leave it out):

    >>> jump = ml.cmu("16_01").resample(30)
    >>> (hop,) = ml.physics.flight_measures(jump, body, ml.contacts.foot_contacts(jump), inertia="segments")
    >>> round(hop.spin_share, 2)
    0.22
    """
    inertia = check_inertia(inertia, body)
    stages = flight_stages(contacts)
    if not stages:
        return ()
    c = center_of_mass(motion, body) if com is None else np.asarray(com, dtype=float)
    if c.shape != (motion.n_frames, 3):
        raise ValueError(f"Expected `com` of shape ({motion.n_frames}, 3), got {c.shape}")
    h = angular_momentum(motion, body, inertia=inertia)
    spin = h - angular_momentum(motion, body) if inertia == "segments" else None
    out = []
    for a, b in stages:
        t = np.arange(b - a) / motion.fps
        g = -2.0 * float(np.polyfit(t, c[a:b, 1], 2)[0]) if b - a >= MIN_FIT_FRAMES else float("nan")
        hf = h[a:b]
        spread = float(np.linalg.norm(hf - hf.mean(axis=0), axis=1).mean())
        share = None
        if spin is not None:
            share = float(np.linalg.norm(spin[a:b], axis=1).mean() / max(np.linalg.norm(hf, axis=1).mean(), 1e-12))
        out.append(FlightMeasure(a, b, g, spread, share))
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


def _momentum_rotation(q: Array, masses: Array, h: Array, dt: float, own: Array | None = None) -> Array:
    """Rotations (n, 3) of S2 over one flight that make its angular momentum constant (section 3.4.1).

    ``q`` (n, L, 3) are S2's link centres relative to the rotation centre,
    ``h`` (n, 3) the angular momentum of the flight's frames.  Equation 8
    gives the angular-velocity change ``I^-1 (D - h)`` on each frame (``I``
    the inertia tensor of S2's point masses about the centre, plus ``own``
    (n, 3, 3), the links' own inertia in world axes, for rigid segments); integrated
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
    if own is not None:
        inertia = inertia + own
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
    inertia: Inertia = "points",
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
    own = None
    if inertia == "segments" and body.inertia is not None:
        # rigid segments: their own spin is angular momentum too, and S2's own inertia turns with it
        h = h + _segment_spin(motion, body, width5, fk=posed[1:])
        turn = quat.to_matrix(posed.grot[:, body.owners[in_s2]])  # (F, L2, 3, 3)
        own = np.einsum("flij,ljk,flmk->fim", turn, body.inertia[in_s2], turn)
    centre = _flight_centre(motion, body, sets, s, posed.gpos)
    phi = np.zeros((n, 3))
    for a, b in stages:
        extra = None if own is None else own[a:b]
        phi[a:b] = _momentum_rotation(s[a:b][:, in_s2] - centre[a:b, None], m[in_s2], h[a:b], dt, extra)
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

