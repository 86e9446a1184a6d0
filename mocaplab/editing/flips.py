"""Tangent flips and the heading of an edited path (Kim et al. 2009, section 4.2).

A path deformed by :mod:`~mocaplab.editing.spatial` can fold: a stretch of
its tangents turns round, and a character following its deformed tangent
would spin.  This module decides, after the solve, which way each frame of
the edited path faces; it never changes the positions, so the solver's
matrices never depend on the flips.  :func:`heading_changes` is what
:mod:`~mocaplab.editing.scene` calls for every edited character.

Tangent flips (section 4.2)
    detected after the solve from jumps of ``phi_i = angle(t_i, that_i)``
    between successive frames faster than ``flip_rate`` (degrees per second;
    900 by default, the paper's 30 degrees per frame at 30 fps, so a clip
    gives the same answer at any frame rate); a jump and a later one that
    brings ``phi`` back within ``flip_window`` seconds bound a whole
    reversed stretch, and a jump within ``flip_window`` of the clip's first
    or last frame starts a reversed run reaching that end; the heading is
    repaired by linear interpolation over the flagged frames (held at the
    ends), which grow until it turns at most ``flip_rate``
    (:func:`detect_tangent_flips`).
Heading (our choice)
    moving frames follow the deformed tangent; flipped and degenerate ones
    are interpolated, a stationary segment turns as one, and the turn added
    by the edit is rate-limited to :data:`TURN_RATE` where the heading is
    not a steady walk's tangent (:func:`heading_changes`).
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from numpy.typing import NDArray

from .paths import MotionPath, central_tangents, ground_angle, rot90, wrap_angle

__all__ = [
    "FLIP_RATE",
    "flip_step",
    "detect_tangent_flips",
    "heading_changes",
    "TURN_RATE",
    "STEADY_SPEED",
]

Array = NDArray[np.float64]


def _interpolated_angles(phi: Array, good: NDArray[np.bool_], F: int, where: NDArray[np.int64]) -> Array:
    """``phi`` (given at frames ``where``) unwrapped over the ``good`` ones and interpolated at every frame 0..F-1."""
    idx = where[good]
    return np.interp(np.arange(F), idx, np.unwrap(phi[good]))


#: Default flip rate, degrees per second: the paper's 30 degrees per frame at its 30 fps.
FLIP_RATE = 900.0
#: How close (radians) ``phi`` must come back to its value before a jump for a later jump to close a reversed run.
_RETURN_TOLERANCE = np.pi / 6


def flip_step(rate: float | None, fps: float, *, name: str = "rate") -> float:
    """The per-frame jump (radians) that a flip rate in degrees per second allows at ``fps``.

    ``rate / fps`` in radians, at most pi (no jump of a wrapped angle is
    larger, so a rate beyond ``180 fps`` finds no flip); ``None`` switches
    the repair off (pi).  ``name`` is the argument named in the error.
    """
    if not (np.isfinite(fps) and fps > 0):
        raise ValueError(f"Expected `fps` > 0, got {fps!r}")
    if rate is None:
        return float(np.pi)
    if not (isinstance(rate, (int, float, np.floating, np.integer)) and np.isfinite(rate) and rate > 0):
        raise ValueError(f"Expected `{name}` > 0 degrees per second (default {FLIP_RATE}), or None, got {rate!r}")
    return float(min(np.radians(float(rate)) / fps, np.pi))


def detect_tangent_flips(
    tangents: Array,
    new_tangents: Array,
    *,
    fps: float,
    rate: float | None = FLIP_RATE,
    window: float = 1.0,
    valid: NDArray[np.bool_] | None = None,
) -> NDArray[np.bool_]:
    """Frames whose deformed tangent flipped (section 4.2, Figure 4), shape (F,) bool.

    Parameters
    ----------
    tangents, new_tangents : ndarray, shape (F, 2)
        Undeformed and deformed tangents.
    fps : float
        Frame rate (``rate`` and ``window`` are per second).
    rate : float or None
        Degrees per second (default :data:`FLIP_RATE`, 900: the paper's 30
        degrees per frame at 30 fps): a flip is reported where
        ``|phi_{i+1} - phi_i|`` exceeds ``rate / fps``, ``phi_i`` the signed
        angle from the undeformed tangent to the deformed one.  In seconds,
        so a clip finds the same flips at 30, 60 or 120 fps (a fold that
        turns the tangent round over 4 frames at 30 fps takes 16 at 120 fps,
        each step a quarter as large).  ``None``: no flip is detected.
    window : float
        Seconds: the longest reversed stretch repaired as one.
    valid : ndarray of bool, shape (F,), optional
        Frames to examine (default all; degenerate tangents are left out by
        the caller); the others are never flipped.

    Notes
    -----
    Which frames around the jumps are the flipped ones:

    1. *Reversed runs.*  A jump and a later one, at most ``window`` seconds
       apart, that bring ``phi`` back to within 30 degrees of its value
       before the first (a stretch of tangents turned round and back,
       Figure 4) flag every frame between them, however many.
    2. *Reversed ends.*  A jump with no such partner, at most ``window``
       seconds from the first or the last examined frame, starts (or ends)
       a reversed run that reaches the clip's end (or start): every frame
       from the jump to that end is flagged (the shorter side when both are
       that close).  The repair then holds the last good heading change up
       to the end.
    3. *Lone jumps* flag the two frames of the jump.
    4. *Repair until smooth.*  The repair replaces the flagged frames' ``phi``
       by linear interpolation over the unflagged ones (unwrapped, held
       constant beyond the first and last of them); while the repaired
       ``phi`` still turns by more than ``rate / fps`` between two frames,
       the nearest unflagged frame on each side of that step is flagged too.
       So the repaired heading never turns faster than ``rate`` more than
       the input did.

    Deformed tangents of (almost) zero length count as flipped.

    Examples
    --------
    >>> t0 = np.tile([0.0, 1.0], (60, 1)); t1 = t0.copy(); t1[20:35] *= -1   # a 15-frame fold
    >>> np.flatnonzero(detect_tangent_flips(t0, t1, fps=30.0)).tolist() == list(range(20, 35))
    True
    >>> t1 = t0.copy(); t1[50:] *= -1   # the last 10 frames turned round
    >>> np.flatnonzero(detect_tangent_flips(t0, t1, fps=30.0)).tolist() == list(range(50, 60))
    True
    """
    tangents = np.asarray(tangents, dtype=float)
    new_tangents = np.asarray(new_tangents, dtype=float)
    if tangents.shape != new_tangents.shape or tangents.ndim != 2 or tangents.shape[1] != 2:
        raise ValueError(
            f"Expected `tangents` and `new_tangents` of one shape (F, 2), got {tangents.shape} and {new_tangents.shape}"
        )
    threshold = flip_step(rate, fps)
    if not window >= 0:
        raise ValueError(f"Expected `window` >= 0 seconds, got {window!r}")
    F = len(tangents)
    valid = np.ones(F, bool) if valid is None else np.asarray(valid, bool)
    out = np.zeros(F, bool)
    ln = np.linalg.norm(new_tangents, axis=1)
    tiny = ln < 1e-9 * max(1.0, float(np.max(np.linalg.norm(tangents, axis=1), initial=0.0)))
    out[valid & tiny] = True
    idx = np.flatnonzero(valid & ~tiny)
    if len(idx) < 3 or rate is None:
        return out
    phi = wrap_angle(ground_angle(new_tangents[idx]) - ground_angle(tangents[idx]))
    step = wrap_angle(np.diff(phi))
    jumps = np.flatnonzero(np.abs(step) > threshold)  # jump m: between idx[m] and idx[m + 1]
    flag = np.zeros(len(idx), bool)
    span = max(1, int(round(window * fps)))
    used = np.zeros(len(jumps), bool)
    for q, m in enumerate(jumps):
        if used[q]:
            continue
        # 1. the first later jump within the window that brings phi back to where it was before m
        for r in range(q + 1, len(jumps)):
            m2 = jumps[r]
            if idx[m2] - idx[m] > span:
                break
            if abs(wrap_angle(phi[m2 + 1] - phi[m])) <= _RETURN_TOLERANCE:
                flag[m + 1 : m2 + 1] = True
                used[q : r + 1] = True
                break
        if used[q]:
            continue
        used[q] = True
        # 2. a reversed run reaching an end of the clip: from the jump to that end
        head, tail = idx[m + 1] - idx[0], idx[-1] - idx[m]  # frames on each side, counted as in `span`
        if min(head, tail) <= span:
            # with the cusp's tail: the frames next to the jump still turning at over half the rate
            settling = np.abs(step) > 0.5 * threshold
            if tail <= head:
                k = m
                while k > 0 and settling[k - 1]:
                    k -= 1
                flag[k + 1 :] = True
            else:
                k = m
                while k + 1 < len(step) and settling[k + 1]:
                    k += 1
                flag[: k + 1] = True
        else:  # 3. a lone jump
            flag[m] = flag[m + 1] = True
    # 4. grow the flagged stretches until the interpolated phi is smooth
    for _ in range(len(idx)):
        good = ~flag
        if good.sum() < 2:
            break
        rep = _interpolated_angles(phi, good, F, idx)
        bad = np.flatnonzero(np.abs(np.diff(rep)) > threshold + 1e-12)
        if not len(bad):
            break
        gidx = idx[good]
        before = np.searchsorted(gidx, bad, side="right") - 1  # last good frame at or before the step
        after = np.searchsorted(gidx, bad + 1, side="left")  # first good frame at or after it
        grow = np.concatenate([before[before >= 0], after[after < len(gidx)]])
        flag[np.flatnonzero(good)[grow]] = True
    out[idx[flag]] = True
    return out


def _procrustes_angle(orig: Array, new: Array) -> float:
    """Yaw angle of the best rotation taking centred ``orig`` onto centred ``new``."""
    x = orig - orig.mean(axis=0)
    y = new - new.mean(axis=0)
    return float(np.arctan2(np.sum(y * rot90(x)), np.sum(y * x)))


#: Default fastest turn (degrees per second) a path edit adds to a character's heading where the heading is
#: not the deformed tangent's own: across stationary segments, gaps and jitter (:func:`heading_changes`).
TURN_RATE = 60.0


#: Speed (m/s) above which a frame's deformed tangent sets the heading unblended (both before and after the edit):
#: slower, the direction of a central difference is mostly sway and capture noise.
STEADY_SPEED = 0.5


def _rate_limited(d: Array, step: float, movable: NDArray[np.bool_]) -> tuple[Array, NDArray[np.bool_]]:
    """``d`` with movable frames around each step larger than ``step`` re-interpolated until none is (held at the ends).

    Each pass flags, on each side of every step still too large, the
    nearest movable frame not yet flagged (never past an unmovable one), and
    interpolates the flagged frames from the others: a blend widens one
    frame per side per pass, so it ends as narrow as the rate allows.  A
    step between unmovable frames (the tangents of a steady walk) is kept.
    Returns the smoothed values and the frames that were interpolated.
    """
    F = len(d)
    flag = np.zeros(F, bool)
    out = d
    stuck = np.zeros(max(F - 1, 0), bool)
    for _ in range(F):
        bad = np.flatnonzero((np.abs(np.diff(out)) > step + 1e-12) & ~stuck)
        if not len(bad):
            break
        for i in bad:
            grew = False
            for j, side in ((int(i), -1), (int(i) + 1, 1)):
                while 0 <= j < F and flag[j]:
                    j += side
                if 0 <= j < F and movable[j]:
                    flag[j] = grew = True
            if not grew:
                stuck[i] = True
        good = ~flag
        idx = np.flatnonzero(good)
        if len(idx) < 2:
            out = np.full(F, float(np.mean(d[idx])) if len(idx) else float(np.mean(d)))
            break
        out = np.interp(np.arange(F), idx, d[idx])
    return out, flag


def heading_changes(
    path: MotionPath,
    new_positions: Array,
    *,
    segments: Sequence[tuple[int, int]] = (),
    flip_rate: float | None = FLIP_RATE,
    flip_window: float = 1.0,
    turn_rate: float | None = TURN_RATE,
) -> tuple[Array, NDArray[np.bool_], Array]:
    """Turn of the tangent direction per frame after a deformation.

    Parameters
    ----------
    path : MotionPath
        The undeformed path.
    new_positions : ndarray, shape (F, 2)
        The deformed positions.
    segments : sequence of (start, stop)
        Rigid stationary segments (half-open): each turns as one (a constant
        heading change, so planted feet stay planted).
    flip_rate : float or None
        Degrees per second (:func:`detect_tangent_flips`); ``None``: no
        repair (neither of flips nor of the turn rate).
    flip_window : float
        Seconds: the longest reversed stretch repaired as one.
    turn_rate : float or None
        Degrees per second (default :data:`TURN_RATE`): the heading change
        never turns faster than this between two frames; where it would (a
        stationary segment meeting the moving path, the noisy tangents of a
        slow stretch), the frames around the step are interpolated from
        their neighbours until it does not.  ``None``: no limit.

    Returns
    -------
    dtheta : ndarray, shape (F,)
        Yaw change (radians) of the path direction at each frame, continuous
        (unwrapped).
    flipped : ndarray of bool, shape (F,)
        Frames whose tangent flipped and was repaired.
    tangents : ndarray, shape (F, 2)
        Unit directions of the deformed path the heading follows.

    Notes
    -----
    Where the heading comes from, per frame:

    * moving frames (tangent not degenerate, not flipped, outside the
      stationary segments): the turn of the deformed tangent against the
      undeformed one (section 4.1);
    * degenerate and flipped frames: interpolated from the moving ones;
    * a stationary segment: one constant, the mean of the interpolated
      values at the moving frames on either side of it.  A standing
      character's path is millimetres of sway: the rotation the solver gives
      its rigid segment (and the direction of its tangents) is set by that
      noise, and followed it turned a standing person round in one frame.
      A clip with no moving frame keeps the best-fit rotation of its whole
      path;
    * then the turn-rate limit blends every step faster than ``turn_rate``
      (segment boundaries, gaps, jitter), moving only frames whose heading
      is not a steady tangent's: frames in segments, degenerate, flipped,
      or slower than :data:`STEADY_SPEED` before or after the edit (a
      walk's own sharp turn is followed as it is).
    """
    new_positions = np.asarray(new_positions, dtype=float)
    t0 = path.tangents
    t1 = central_tangents(new_positions)
    valid = ~path.degenerate
    flipped = detect_tangent_flips(t0, t1, fps=path.fps, rate=flip_rate, window=flip_window, valid=valid)
    F = path.n_frames
    inside = np.zeros(F, bool)
    segs = [(int(a), int(b)) for a, b in segments if b - a >= 2]
    for a, b in segs:
        inside[a:b] = True
    good = valid & ~flipped & ~inside
    if good.any():
        idx = np.flatnonzero(good)
        d = np.unwrap(wrap_angle(ground_angle(t1[idx]) - ground_angle(t0[idx])))
        dtheta = np.interp(np.arange(F), idx, d)
        for a, b in segs:
            ends = [dtheta[i] for i in (a - 1, b) if 0 <= i < F]
            dtheta[a:b] = float(np.mean(ends)) if ends else float(np.mean(dtheta[a:b]))
    else:
        dtheta = np.full(F, _procrustes_angle(path.positions, new_positions))
    if turn_rate is not None and flip_rate is not None:
        step = flip_step(turn_rate, path.fps, name="turn_rate")
        steady = 2.0 * STEADY_SPEED / path.fps
        fast = np.minimum(np.linalg.norm(t0, axis=1), np.linalg.norm(t1, axis=1)) >= steady
        dtheta, _ = _rate_limited(dtheta, step, ~(good & fast))
    c, s = np.cos(dtheta), np.sin(dtheta)
    u = t0 / np.linalg.norm(t0, axis=1, keepdims=True)
    tang = c[:, None] * u + s[:, None] * rot90(u)
    return dtheta, flipped, tang
