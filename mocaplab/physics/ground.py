"""Ground frames of a physical touch-up (Shin, Kovar and Gleicher 2003, section 3.3).

On every ground frame independently, the rotation of S2 that brings the
ZMP onto its projection on the support polygon, about a horizontal axis
perpendicular to the correction, by the closed form of equations 6-7
(coefficients of the Appendix, computed here as per-link sums:
:func:`_ground_rotation`).  :func:`_ground_step` weighs each frame's own
correction (:func:`_ground_weights`), scales it by ``rho``, smooths it and
applies it with the shared machinery of :mod:`mocaplab.physics.adjust`.
The link sets come from :mod:`mocaplab.physics.schedule`, the ZMP analysis
from :mod:`mocaplab.physics.zmp`; :func:`mocaplab.physics.step` calls
:func:`_ground_step` for each ground adjustment.

Choices made where the paper leaves them open
---------------------------------------------
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
"""

from __future__ import annotations

from functools import lru_cache

import numpy as np
from numpy.typing import NDArray

from ..motion import Motion, readonly
from .adjust import MAX_ANGLE, _apply, _Posed, _root_pivot, _rotate_about, _smooth
from .body import GRAVITY, Body, paper_width
from .schedule import Adjustment, LinkSets
from .zmp import _LEVEL, Balance

Array = NDArray[np.float64]

#: A frame whose need survives the smoothing with less than this share of
#: itself (a spike the kernel cannot follow) is down-weighted in proportion.
SPIKE_SHARE = 0.3


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
    line search of :func:`mocaplab.physics.touch_up` keeps such frames from winding the
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
