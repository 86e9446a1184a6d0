"""Locating staggered poses in dense motion (Coleman et al. 2008, section 4.1).

The pipeline, one function per step:

1. :func:`motion_trails`: for every joint rotation and every child ``j``, the
   local-space trails ``m1(j, t)`` (the tip of the unit axis toward the child)
   and ``m2(j, t)`` (the tip of a unit axis orthogonal to it, which sees twist
   about the limb); one trail of the root position for the root translation,
   and one of the local translation for each translation variable (a pelvis
   travelling below a static joint 0 gives the same trail as a travelling
   root).
2. :func:`laplacian_smooth`: iterated Laplacian smoothing of the trails
   (discrete curvature is very sensitive to capture noise), computed in
   closed form with a sine transform, so its cost does not grow with the
   number of iterations (the square of the frame rate).
3. :func:`bounded_curvature`: the modified Taubin measure
   ``kappa_hat_i = n_i . e_i / |e_i|`` in ``[0, 1]``, averaged over the two
   edges at a sample weighted by their lengths.  With the Frenet normal taken
   along the change of unit tangent, both edges give the same value,
   ``sin(phi / 2)`` for a turning angle ``phi``: 0 on a straight trail, 1 on
   a reversal.  The local probability of a variable is the maximum over its
   trails, ``p(t) = max_{i, j} kappa_hat(m_i(j, t))``.
4. Global evidence: a binary signal that is 1 on the frames where a contact
   starts or ends (:func:`contact_events`).
5. :func:`pose_probability`: ``P(t) = f(sum_i w_i p_i(t) / sum_i w_i)`` with
   ``w_i = sum_j |x_i - x_j| |m_j|`` (bone length times trail arc length) and a
   tent low-pass filter ``f`` of width 0.15 s.
6. :func:`candidate_poses`, :func:`pose_priorities`, :func:`cull_poses`:
   candidates at the *distinct* local maxima of ``P`` plus the first and
   last frames (see "Sparse poses" below); priorities
   ``w_k = P(t_k) (t_{k+1} - t_{k-1})``; culling by count, by fraction or
   by a time interval, greedily (the lowest priority goes, its neighbours'
   priorities are recomputed, and so on).
7. :func:`timing_refinements`: for each pose and variable, the highest local
   maximum of the variable's curvature on its dominant trail
   (:func:`dominant_trail_signals`) within 0.25 s of the pose time and
   within a third of the gap to either neighbouring pose (so a variable's
   knots stay at least a third of the pose gap apart); zero when there is
   none.

:func:`analyze` runs steps 1-6 once and returns a :class:`PoseAnalysis` whose
:meth:`~PoseAnalysis.select` culls and refines without recomputing signals.

Sparse poses
------------
The paper applies the tent filter "to combine closely-clustered peaks" into
one, and expects "very sparse poses" for physical motion.  On capture data
the filtered ``P`` still ripples: a sum of many saturating curvature signals
has small wiggles on the flanks of its peaks, and every wiggle is a local
maximum.  Taken literally, 7 % of the gaps between candidates over the 17
CMU clips of the mirror (11 % on the walk 16_15) are under 50 ms (maxima 2
to 5 frames apart), and a walk has as many poses per second as a dance (7.1
against 7.1).  Two rules make the candidates the
distinct maxima the filter is meant to leave (:func:`candidate_poses`):

* **merge** maxima closer than the filter's half-width (0.075 s): of two
  such maxima the lower one goes (``scipy.signal.find_peaks(distance=...)``);
  a maximum that close to the first or last frame merges into that forced
  pose;
* **prominence**: a maximum counts only if ``P`` falls by at least
  ``min_prominence = 0.1`` of its value on both sides before rising to a
  higher maximum (its topographic prominence, ``scipy.signal.peak_prominences``,
  is at least ``0.1 P(t_k)``).  Over the CMU clips the relative prominences
  of the maxima split into ripples (39 % below 0.05) and the peaks of feature
  clusters (52 % above 0.1), with few in between (9 %).

No two poses are then closer than 0.075 s (between interior poses the
smallest gap over the 17 CMU clips of the mirror is 108 ms; the literal rule
gives 17 ms).  Both the tent and the separation are in seconds, not frames:
the tent falls to zero 75 ms from its centre at any rate, and the
separation is rounded *up* to whole frames, so the same clip at 24, 30, 60
and 120 fps keeps its poses at least 75 ms apart and about as many per second
(the walk 16_15: 3.3, 3.1, 2.8, 2.8 at 120, 60, 30, 24 fps; the dance
05_02: 4.2, 4.0, 4.0, 3.9).
Measured at 120 fps (``benchmarks/bench_staggered.py``), interior poses per
second, every maximum -> distinct maxima: walk 16_15 7.1 -> 3.3, walk 02_01
4.2 -> 3.5, broad jump 16_05 6.9 -> 4.1, vertical jump 16_01 7.9 -> 2.2,
hops 49_03 6.5 -> 4.3, dance 05_02 7.1 -> 4.2, runs 09_06 and 16_35 9.4 and
8.2 -> 5.1 and 4.5.  That is the paper's picture: "physical motion tends to
have very sparse poses, as muscle activations are correlated with contact
events" -- a walk gets about two poses per step (the peaks of P sit near
foot strike and toe-off), a jump in place a handful in all; "looser motion often has
more candidate poses, although it remains a sparse set" -- the dance has a
quarter more than the walk.  A run's contact changes come faster (a stride
lasts about 0.7 s), so it keeps more poses per second than a walk.

Longer than 800 lines because the module is one pipeline (the seven steps
above feed each other and :class:`PoseAnalysis` keeps their signals) and
these notes keep the measurements that chose its rules.  Within the package it
imports only the representation's variable naming (:mod:`~mocaplab.staggered.representation`);
the filter (:mod:`~mocaplab.staggered.noise`) and the fit
(:mod:`~mocaplab.staggered.fit`) build on it.
"""

from __future__ import annotations

import dataclasses
import heapq
from collections.abc import Mapping, Sequence
from typing import Any, Literal

import numpy as np
from numpy.typing import NDArray

from .. import quat
from .._checks import integer, real
from .._warnings import warn
from ..contacts import stillness_contacts
from ..motion import Motion
from ..roles import RolesError
from .representation import translation_joints, variable_names

__all__ = [
    "Trails",
    "PoseAnalysis",
    "NoContactsWarning",
    "motion_trails",
    "laplacian_smooth",
    "bounded_curvature",
    "contact_events",
    "tent_filter",
    "signal_weights",
    "dominant_trail_signals",
    "pose_probability",
    "local_maxima",
    "candidate_poses",
    "MIN_PROMINENCE",
    "pose_priorities",
    "cull_poses",
    "timing_refinements",
    "analyze",
    "check_rates",
    "MAX_FPS",
    "MAX_FILTER_SECONDS",
]

Array = NDArray[np.float64]

MAX_FPS = 1000.0
"""Highest frame rate the staggered analysis, fitting and filters take (frames per second).

The filters' widths are fixed in seconds, so their work per frame grows with
the rate; 1000 fps is well above any capture the lessons use (120 fps).
Resample a faster clip first (:meth:`mocaplab.motion.Motion.sample`)."""

MAX_FILTER_SECONDS = 1.0
"""Longest filter width or sigma, seconds: the trail smoothing, ``filter_width``, ``filter_sigma``.

The defaults are 0.03 to 0.15 s; a second already averages away whole steps."""


def check_rates(fps: float, **widths: float | None) -> None:
    """Check a frame rate and filter widths before any work is sized by them.

    Parameters
    ----------
    fps : float
        Must be finite, > 0 and at most :data:`MAX_FPS`.
    **widths : float or None
        Seconds, each finite, >= 0 and at most :data:`MAX_FILTER_SECONDS`
        (None: not used), named by its keyword in the error.

    Raises
    ------
    ValueError
        Naming the first value out of bounds and its limit.

    Examples
    --------
    >>> check_rates(120.0, filter_sigma=0.03)
    >>> check_rates(10_000.0)
    Traceback (most recent call last):
    ...
    ValueError: Expected the clip's frame rate from 0 to MAX_FPS = 1000 frames per second for the staggered poses' \
filters (whose widths are in seconds), got 10000.0: resample the clip first, e.g. motion.sample(times, fps=120.0)
    """
    if not 0.0 < fps <= MAX_FPS:  # NaN fails too
        raise ValueError(
            f"Expected the clip's frame rate from 0 to MAX_FPS = {MAX_FPS:g} frames per second for the staggered "
            f"poses' filters (whose widths are in seconds), got {fps!r}: resample the clip first, e.g. "
            "motion.sample(times, fps=120.0)"
        )
    for name, width in widths.items():
        if width is not None and not 0.0 <= width <= MAX_FILTER_SECONDS:
            raise ValueError(
                f"Expected `{name}` from 0 to MAX_FILTER_SECONDS = {MAX_FILTER_SECONDS:g} seconds, got {width!r}"
            )

class NoContactsWarning(UserWarning):
    """Contact detection found no contact in a clip: no global evidence, an empty constraint layer.

    Parameters
    ----------
    *args
        The message, as for any warning.

    Examples
    --------
    >>> from mocaplab.staggered import NoContactsWarning
    >>> issubclass(NoContactsWarning, UserWarning)
    True
    """


MAX_REFINEMENT = 0.25
"""Bound on timing refinements in seconds (section 4.1: clusters are about 0.5 s wide)."""

FILTER_WIDTH = 0.15
"""Width of the tent filter combining nearby peaks, seconds (section 4.1)."""


@dataclasses.dataclass(frozen=True, eq=False)
class Trails:
    """Motion trails of a clip.

    Attributes
    ----------
    points : ndarray, shape (F, n, 3)
        Trail samples: unit-axis tips in the parent frame of the joint for
        rotation trails, world root positions (metres) for the root trail,
        local translations (metres, parent frame) for translation variables.
    variable : ndarray of int, shape (n,)
        Control variable of each trail (0 = root translation, ``1 + j`` =
        rotation of joint ``j``, ``J + 1 + m`` = translation variable ``m``).
    kind : ndarray of int, shape (n,)
        1 for ``m1`` (axis toward the child), 2 for ``m2`` (orthogonal axis),
        0 for the root and translation trails.
    bone_length : ndarray, shape (n,)
        ``|x_i - x_j|``: the length from the joint to the child the trail
        follows (metres; 0 for the translation trails).
    """

    points: Array
    variable: NDArray[np.int64]
    kind: NDArray[np.int64]
    bone_length: Array


def motion_trails(motion: Motion) -> Trails:
    """Local-space motion trails ``m1``/``m2`` of every joint and the root trail.

    Each joint's children are its child joints and its BVH end sites with a
    non-zero offset.  A joint with none (rare) gets trails of its local x and
    y axes with unit length.  The orthogonal axis of ``m2`` is the cross
    product of the limb axis with the coordinate axis least aligned with it.

    Parameters
    ----------
    motion : Motion

    Returns
    -------
    Trails
    """
    sk = motion.skeleton
    J = sk.n_joints
    rows: list[tuple[int, int, NDArray[np.float64], float]] = []  # (joint, kind, axis, length)
    child_offsets: list[list[NDArray[np.float64]]] = [[] for _ in range(J)]
    for c in range(1, J):
        child_offsets[int(sk.parents[c])].append(sk.offsets[c])
    for p, off in zip(sk.end_site_parents, sk.end_site_offsets, strict=True):
        child_offsets[int(p)].append(off)
    for j in range(J):
        offs = [o for o in child_offsets[j] if np.linalg.norm(o) > 1e-9]
        if not offs:
            rows.append((j, 1, np.array([1.0, 0.0, 0.0]), 1.0))
            rows.append((j, 2, np.array([0.0, 1.0, 0.0]), 1.0))
            continue
        for o in offs:
            length = float(np.linalg.norm(o))
            a = o / length
            e = np.eye(3)[int(np.argmin(np.abs(a)))]
            b = np.cross(a, e)
            b /= np.linalg.norm(b)
            rows.append((j, 1, a, length))
            rows.append((j, 2, b, length))
    joints = np.array([r[0] for r in rows], dtype=np.int64)
    axes = np.array([r[2] for r in rows])
    pts = quat.rotate(motion.rotations[:, joints], axes)  # (F, n, 3)
    tj = list(translation_joints(motion))
    moved = np.asarray(motion.translations)[:, tj] if tj else np.zeros((motion.n_frames, 0, 3))
    points = np.concatenate([np.asarray(motion.root_positions)[:, None, :], pts, moved], axis=1)
    T = len(tj)
    return Trails(
        points=points,
        variable=np.concatenate([[0], joints + 1, J + 1 + np.arange(T)]).astype(np.int64),
        kind=np.concatenate([[0], [r[1] for r in rows], np.zeros(T)]).astype(np.int64),
        bone_length=np.concatenate([[0.0], [r[3] for r in rows], np.zeros(T)]),
    )


def laplacian_smooth(x: Array, *, iterations: int, lam: float = 0.5) -> Array:
    """Iterated Laplacian smoothing along axis 0 (end samples held fixed), computed in closed form.

    One iteration moves every interior sample a fraction ``lam`` toward the
    mean of its two neighbours, the end samples held.  That is a linear map
    on the interior whose eigenvectors are the sine modes ``sin(pi k i / (F -
    1))`` with eigenvalues ``1 - lam + lam cos(pi k / (F - 1))``, so
    ``iterations`` passes are one type-I discrete sine transform of the
    signal's departure from the straight line between its ends, each mode
    scaled by its eigenvalue to the power ``iterations``, and the inverse
    transform (:func:`scipy.fft.dst`).  The cost is ``O(F log F)`` whatever
    the number of iterations: at 1000 fps :func:`analyze`'s default is 1,667
    iterations, which explicit passes paid for in full.  The result is that
    of the passes to rounding (about 1e-12 of the signal's range); straight
    lines and constant signals are kept exactly.

    Parameters
    ----------
    x : ndarray, shape (F, ...)
    iterations : int
        ``>= 0``; as many as wanted (many passes tend to the straight line).
    lam : float in (0, 1]

    Returns
    -------
    ndarray, shape (F, ...)

    Examples
    --------
    >>> import numpy as np
    >>> y = laplacian_smooth(np.array([0.0, 0.0, 1.0, 0.0, 0.0]), iterations=1)
    >>> [round(float(v), 12) for v in y]
    [0.0, 0.25, 0.5, 0.25, 0.0]
    """
    from scipy.fft import dst

    if not 0.0 < lam <= 1.0:
        raise ValueError(f"Expected `lam` in (0, 1], got {lam!r}")
    if not iterations >= 0:
        raise ValueError(f"Expected `iterations` >= 0, got {iterations!r}")
    y = np.array(x, dtype=float, copy=True)
    F = y.shape[0]
    if F < 3 or iterations == 0:
        return y
    ramp = (np.arange(F) / (F - 1.0)).reshape((F,) + (1,) * (y.ndim - 1))
    line = y[0] + (y[-1] - y[0]) * ramp  # held by every pass; a constant signal is its own line, exactly
    interior = y[1:-1] - line[1:-1]
    gain = 1.0 - lam + lam * np.cos(np.pi * np.arange(1, F - 1) / (F - 1.0))
    with np.errstate(under="ignore"):
        gain = np.sign(gain) ** (int(iterations) % 2) * np.abs(gain) ** float(iterations)
    modes = dst(interior, type=1, axis=0, norm="ortho") * gain.reshape((F - 2,) + (1,) * (y.ndim - 1))
    y[1:-1] = line[1:-1] + dst(modes, type=1, axis=0, norm="ortho")
    return y


def bounded_curvature(points: Array, *, eps: float = 1e-12) -> Array:
    """The bounded curvature ``kappa_hat`` of polylines, in ``[0, 1]``.

    Parameters
    ----------
    points : ndarray, shape (F, ..., 3)
        Polylines sampled along axis 0.
    eps : float
        Edges shorter than this (a standing trail) give 0.

    Returns
    -------
    ndarray, shape (F, ...)
        ``sin(phi / 2)`` of the turning angle ``phi`` at every interior
        sample (the Taubin-style ``n . e / |e|`` of both edges, length
        weighted); 0 at the two ends.
    """
    p = np.asarray(points, dtype=float)
    out = np.zeros(p.shape[:-1])
    if p.shape[0] < 3:
        return out
    e_in = p[1:-1] - p[:-2]
    e_out = p[2:] - p[1:-1]
    n_in = np.linalg.norm(e_in, axis=-1)
    n_out = np.linalg.norm(e_out, axis=-1)
    ok = (n_in > eps) & (n_out > eps)
    c = np.einsum("...i,...i->...", e_in, e_out) / np.where(ok, n_in * n_out, 1.0)
    out[1:-1] = np.where(ok, np.sqrt(np.clip(0.5 * (1.0 - c), 0.0, 1.0)), 0.0)
    return out


def contact_events(contacts: Any, n_frames: int) -> Array:
    """Binary global evidence: 1 where any contact starts or ends, shape (F, C).

    One column per contact joint; a contact starting on the first frame or
    running to the end of the clip gives no event there.  ``contacts`` is a
    :class:`mocaplab.contacts.Contacts`.
    """
    joints = tuple(contacts.joints)
    out = np.zeros((n_frames, len(joints)))
    for c, name in enumerate(joints):
        for start, stop in contacts.intervals(name):
            if 0 < start < n_frames:
                out[start, c] = 1.0
            if 0 < stop < n_frames:
                out[stop, c] = 1.0
    return out


def tent_filter(signal: Array, width: float, fps: float) -> Array:
    """Low-pass tent (triangle) filter of total width ``width`` seconds along axis 0.

    The tent is built in continuous time: it falls to zero ``width / 2``
    seconds either side of its centre whatever the frame rate, and each
    frame's weight is the tent's area over that frame's interval
    ``[(i - 1/2) / fps, (i + 1/2) / fps]``.  Rounding the half-width to whole
    frames instead would make the support 83 ms at 120 fps and 125 ms at
    24 fps.  The kernel sums to 1 and is renormalised near the ends of the
    clip so a constant signal stays constant.

    Parameters
    ----------
    signal : ndarray, shape (F, ...)
    width : float
        Total width of the tent, seconds (> 0).
    fps : float
        Frame rate of ``signal``.

    Returns
    -------
    ndarray, shape (F, ...)

    Examples
    --------
    >>> import numpy as np
    >>> tent_filter(np.ones(5), 0.15, 30.0).tolist()
    [1.0, 1.0, 1.0, 1.0, 1.0]
    """
    from scipy.ndimage import convolve1d

    x = np.asarray(signal, dtype=float)
    h = 0.5 * float(width) * float(fps)  # the half-width, in frames (not rounded)
    n = int(np.ceil(h + 0.5))
    edges = np.arange(-n, n + 2) - 0.5  # frame i covers [i - 1/2, i + 1/2]

    def area(u: NDArray[np.floating[Any]]) -> Array:
        # the tent's integral from -h to u (its cumulative distribution), total 1
        v = np.clip(u / h, -1.0, 1.0)
        return np.where(v < 0.0, 0.5 * (1.0 + v) ** 2, 1.0 - 0.5 * (1.0 - v) ** 2)

    k = np.diff(area(edges))
    k = k[k > 0.0]  # symmetric: the same number of frames drop from either side
    out = convolve1d(x, k, axis=0, mode="constant", cval=0.0)
    ones = convolve1d(np.ones(x.shape[0]), k, mode="constant", cval=0.0)
    return out / ones.reshape((-1,) + (1,) * (x.ndim - 1))


def signal_weights(trails: Trails, n_variables: int, *, root_weight: float = 1.0) -> Array:
    """Weights ``w_i = sum_j |x_i - x_j| |m_j|`` of the local signals, shape (V,).

    ``|m_j|`` is the arc length of the ``m1`` trail toward child ``j`` (the
    limb's swept angle; its product with the bone length is the distance the
    child sweeps).  The root translation, and every translation variable,
    gets the arc length of its trail (the distance the joint travels, also
    metres) times ``root_weight``.  Arc lengths are measured on the smoothed
    trails passed in.
    """
    sweep = _sweeps(trails)
    w = np.zeros(n_variables)
    m1 = trails.kind == 1
    np.add.at(w, trails.variable[m1], sweep[m1])
    m0 = trails.kind == 0
    w[trails.variable[m0]] = root_weight * sweep[m0]
    return w


def _sweeps(trails: Trails) -> Array:
    """The distance each trail's tip sweeps, metres, shape (n,): its arc length, times the bone length for the
    rotation trails (``m1``, ``m2``), alone for the root and translation trails."""
    arc = np.linalg.norm(np.diff(trails.points, axis=0), axis=-1).sum(axis=0)
    return np.where(trails.kind == 0, arc, trails.bone_length * arc)


def dominant_trail_signals(trails: Trails, kappa: Array, n_variables: int) -> Array:
    """Each variable's bounded curvature on its dominant trail, shape (F, V).

    The dominant trail of a variable is the one whose tip sweeps the longest
    distance (bone length times arc length; arc length alone for the root
    and translation trails; as :func:`signal_weights` measures it).  ``p_i`` (the
    maximum over all trails) saturates at 1 on every reversal of any trail,
    however small: a walk's hip twists back and forth by a few degrees
    while the thigh swings through 40, so the timing refinements found the
    twist's wiggles as often as the swing's extremes.  Over the walks 16_15
    and 02_01 and the run 16_35 at 120 fps, the hips' knots lay within 25 ms
    of 10 of their 26 swing extremes with ``p_i`` and 18 with this (within
    50 ms: 15 and 18; at 24, 30 and 60 fps, 14-16 and 20-21).
    ``p_i`` still makes the pose probability: a pose is where anything
    about the body turns.
    """
    sweep = _sweeps(trails)
    # by variable, then sweep: each variable's largest comes last (of equal sweeps, the later trail)
    order = np.lexsort((sweep, trails.variable))
    last = order[np.r_[np.diff(trails.variable[order]) != 0, True]] if order.size else order
    out = np.zeros((kappa.shape[0], n_variables))
    out[:, trails.variable[last]] = kappa[:, last]
    return out


def pose_probability(
    signals: Array,
    weights: Array,
    fps: float,
    *,
    events: Array | None = None,
    event_weight: float = 0.0,
    width: float = FILTER_WIDTH,
) -> Array:
    """The aggregate pose probability ``P(t) = f(sum_i w_i p_i / sum_i w_i)``.

    Parameters
    ----------
    signals : ndarray, shape (F, V)
        Local probabilities ``p_i(t)``.
    weights : ndarray, shape (V,)
    fps : float
    events : ndarray, shape (F, C), optional
        Global evidence signals, each weighted ``event_weight``.
    width : float
        Tent filter width in seconds.

    Returns
    -------
    ndarray, shape (F,)
    """
    num = signals @ weights
    den = float(weights.sum())
    if events is not None and events.size:
        num = num + event_weight * events.sum(axis=1)
        den += event_weight * events.shape[1]
    if den <= 0:
        return np.zeros(signals.shape[0])
    return tent_filter(num / den, width, fps)


def local_maxima(x: Array) -> NDArray[np.int64]:
    """Indices of interior local maxima of a 1-D signal (``x[i-1] < x[i] >= x[i+1]``)."""
    x = np.asarray(x, dtype=float)
    if x.size < 3:
        return np.zeros(0, dtype=np.int64)
    m = (x[1:-1] > x[:-2]) & (x[1:-1] >= x[2:])
    return np.flatnonzero(m) + 1


MIN_PROMINENCE = 0.1
"""Least prominence of a candidate maximum of ``P``, relative to its value (see "Sparse poses")."""


def candidate_poses(
    probability: Array, *, separation: int = 0, min_prominence: float = 0.0
) -> NDArray[np.int64]:
    """Candidate pose frames: the distinct local maxima of ``P`` plus the first and last frames.

    Parameters
    ----------
    probability : ndarray, shape (F,)
        The pose probability ``P``.
    separation : int
        Maxima closer than this many frames merge into the higher one
        (``scipy.signal.find_peaks(distance=separation)``), and maxima closer
        than this to the first or last frame merge into that forced pose.
        0 keeps every maximum.
    min_prominence : float
        Keep a maximum only if its prominence is at least this fraction of
        its value (``scipy.signal.peak_prominences``): ``P`` has to fall by
        that much on both sides before a higher maximum.  0 keeps every one.

    Returns
    -------
    ndarray of int, shape (C,)
        Sorted frames; no two interior ones (nor an interior one and an end)
        closer than ``separation`` frames.

    Examples
    --------
    >>> import numpy as np
    >>> P = np.array([0.0, 0.3, 0.5, 0.48, 0.49, 0.2, 0.1, 0.3, 0.6, 0.3, 0.2, 0.1, 0.0])
    >>> candidate_poses(P).tolist()  # every local maximum
    [0, 2, 4, 8, 12]
    >>> candidate_poses(P, min_prominence=0.1).tolist()  # 4 is a ripple on the flank of 2
    [0, 2, 8, 12]
    >>> candidate_poses(P, separation=3).tolist()  # 4 merges into 2, 2 into the first frame
    [0, 8, 12]
    """
    from scipy.signal import find_peaks, peak_prominences

    p = np.asarray(probability, dtype=float)
    n = p.size
    if not 0.0 <= min_prominence <= 1.0:
        raise ValueError(f"Expected `min_prominence` in [0, 1] (a fraction of the peak's value), got {min_prominence!r}")
    if int(separation) != separation or separation < 0:
        raise ValueError(f"Expected `separation` to be an integer >= 0 frames, got {separation!r}")
    sep = int(separation)
    peaks = local_maxima(p)
    if peaks.size and min_prominence > 0.0:
        prom = peak_prominences(p, peaks)[0]
        peaks = peaks[prom >= min_prominence * p[peaks]]
    if peaks.size and sep > 1:
        # merge close maxima: keep the higher of any two closer than `sep`
        # (find_peaks' distance rule, applied to the surviving maxima only)
        masked = np.full(n, -np.inf)
        masked[peaks] = p[peaks]
        peaks, _ = find_peaks(masked, distance=sep)
    if sep > 0:
        peaks = peaks[(peaks >= sep) & (peaks <= n - 1 - sep)]
    return np.unique(np.concatenate([[0], peaks, [n - 1]])).astype(np.int64)


def pose_priorities(probability: Array, frames: NDArray[np.int64], fps: float) -> Array:
    """Priorities ``w_k = P(t_k) (t_{k+1} - t_{k-1})``; ``inf`` for the first and last poses."""
    t = np.asarray(frames, dtype=float) / fps
    w = np.full(t.size, np.inf)
    if t.size > 2:
        w[1:-1] = probability[frames[1:-1]] * (t[2:] - t[:-2])
    return w


def cull_poses(
    frames: NDArray[np.int64],
    priorities: Array,
    fps: float,
    *,
    max_poses: int | None = None,
    fraction: float | None = None,
    interval: tuple[float, float] | None = None,
) -> NDArray[np.int64]:
    """Keep the highest-priority candidates (section 4.1, 'Prioritized Pose Extraction').

    Greedy: the interior pose of lowest priority goes first, and its two
    neighbours' priorities are recomputed before the next one goes.  A
    priority ``w_k = P(t_k) (t_{k+1} - t_{k-1})`` depends on the neighbours,
    so removing a pose raises theirs; ranking once by the candidates'
    priorities instead removed runs of neighbours together (the hops 49_03
    with ``max_poses=4`` kept no pose for 10.4 of its 12.5 s; greedily the
    longest stretch is 5.1 s, with 6 poses 6.7 -> 3.5 s).

    Parameters
    ----------
    frames : ndarray of int, shape (C,)
        Candidate frames, sorted, first and last frames included.
    priorities : ndarray, shape (C,)
        ``w_k`` of the candidates, neighbours taken in ``frames``
        (:func:`pose_priorities`); ``P(t_k)`` is recovered from them.
    fps : float
    max_poses : int, optional
        Keep at most this many poses in total (first and last included, so
        at least 2).
    fraction : float in [0, 1], optional
        Keep this fraction of the interior candidates (rounded to nearest).
    interval : (float, float), optional
        Keep only interior candidates whose time lies in ``[t0, t1]`` seconds.

    Returns
    -------
    ndarray of int, shape (K,)
        Kept frames, sorted; the first and last frames always.

    Examples
    --------
    Two strong poses and a weak one near the start of a long clip: the weak
    one goes first, which widens the span (and the priority) of the pose
    beside it, so of the two strong ones the one nearer the middle stays
    (ranked once by the candidates' priorities, 10 and 20 tie and 10 stays):

    >>> import numpy as np
    >>> P = np.zeros(101)
    >>> P[[10, 20, 30]] = [1.0, 1.0, 0.2]
    >>> frames = np.array([0, 10, 20, 30, 100])
    >>> cull_poses(frames, pose_priorities(P, frames, 1.0), 1.0, max_poses=3).tolist()
    [0, 20, 100]
    """
    frames = np.asarray(frames, dtype=np.int64)
    C = frames.size
    keep = np.ones(C, dtype=bool)
    interior = np.arange(C)[1:-1]
    if interval is not None:
        t0, t1 = (float(v) for v in interval)
        if not t0 <= t1:
            raise ValueError(f"Expected `interval` (t0, t1) with t0 <= t1, got {interval!r}")
        t = frames[interior] / fps
        keep[interior[(t < t0) | (t > t1)]] = False
    interior = interior[keep[interior]]
    n_keep = interior.size
    if fraction is not None:
        fraction = real(fraction, "fraction", low=0.0, high=1.0)
        n_keep = min(n_keep, int(round(fraction * interior.size)))
    if max_poses is not None:
        max_poses = integer(max_poses, "max_poses", low=2, why="the first and last frames and the poses between")
        n_keep = min(n_keep, max_poses - 2)
    if n_keep >= interior.size:
        return frames[keep]
    t = frames / float(fps)
    w = np.asarray(priorities, dtype=float)
    strength = np.zeros(C)  # P(t_k), from w_k over the candidates' own spans
    if C > 2:
        strength[1:-1] = w[1:-1] / (t[2:] - t[:-2])
    alive = np.flatnonzero(keep)
    prev = np.full(C, -1)
    nxt = np.full(C, -1)
    prev[alive[1:]] = alive[:-1]
    nxt[alive[:-1]] = alive[1:]

    def priority(k: int) -> float:
        return float(strength[k] * (t[nxt[k]] - t[prev[k]]))

    # a heap with lazy deletion: an entry is current while its priority is the pose's own; on ties the later
    # pose goes first, so the earlier stays (the order of a stable ranking)
    current = {int(k): priority(int(k)) for k in interior}
    heap = [(p, -k) for k, p in current.items()]
    heapq.heapify(heap)
    for _ in range(interior.size - n_keep):
        while True:
            p, neg = heapq.heappop(heap)
            k = -neg
            if current.get(k) == p:
                break
        del current[k]
        keep[k] = False
        a, b = int(prev[k]), int(nxt[k])
        nxt[a], prev[b] = b, a
        for n in (a, b):
            if n in current:
                current[n] = priority(n)
                heapq.heappush(heap, (current[n], -n))
    return frames[keep]


def timing_refinements(
    signals: Array,
    frames: NDArray[np.int64],
    fps: float,
    *,
    max_refinement: float = MAX_REFINEMENT,
) -> Array:
    """Timing refinements from local extrema of the feature signals (section 4.1).

    For pose ``k`` (interior poses only: the first and last poses keep zero
    refinements so the clip's ends are reproduced) and variable ``i``, among
    the local maxima of ``p_i`` that lie within ``max_refinement`` seconds of
    ``t_k`` and within a third of the gap to ``t_{k-1}`` and to ``t_{k+1}``
    (whole frames, rounded down), the highest one gives ``r_{k,i}`` (a whole
    number of frames; peaks within 1e-3 of each other count as tied and the
    one nearest ``t_k`` wins, since the bounded curvature saturates at 1 on
    every reversal); none gives 0.  Refined knots are therefore ordered, and
    two consecutive knots of a variable are at least a third of their poses'
    gap apart: an edit's blend between them (section 5.1) is never squeezed
    into a few frames.  The paper only asks for the knot to be nearer its own
    pose than the neighbours; with that bound the walk 16_15 had right-arm
    knots 42 ms apart where the poses were 308 ms apart, and a 20-degree
    true-pose edit there ramped back in 5 frames (3.3 times the input's
    local angular acceleration).  Knots may instead reach up to half the gap
    as long as consecutive ones stay a third apart: measured, that puts the
    hips' knots within 50 ms of 25 of the 26 swing extremes of 16_15, 02_01
    and 16_35 (18 this way), but spreads the arms' knots too, and an arm
    succession then whips the hands (one-frame moves 1.6-1.8x the input's
    on 05_02 and two exporters' files, against 1.0-1.45x).

    Parameters
    ----------
    signals : ndarray, shape (F, V)
    frames : ndarray of int, shape (K,)
        Pose frames, sorted.
    fps : float
    max_refinement : float
        Seconds.

    Returns
    -------
    ndarray, shape (K, V)
        Refinements in seconds.
    """
    F, V = signals.shape
    frames = np.asarray(frames, dtype=np.int64)
    K = frames.size
    x = signals
    peak = np.zeros_like(x, dtype=bool)
    if F >= 3:
        peak[1:-1] = (x[1:-1] > x[:-2]) & (x[1:-1] >= x[2:])
    score = np.where(peak, x, -np.inf)
    R = int(np.floor(max_refinement * fps + 1e-9))
    out = np.zeros((K, V))
    for k in range(1, K - 1):
        f = int(frames[k])
        # a third of the gap to each neighbour: the knots of pose k and k + 1 stay >= gap / 3 apart
        lo = max(f - R, f - (f - int(frames[k - 1])) // 3)
        hi = min(f + R, f + (int(frames[k + 1]) - f) // 3)
        if hi < lo:
            continue
        # the highest peak; near-ties (bounded curvature saturates at 1 on
        # reversals) go to the peak nearest the pose time
        near = 1e-3 * np.abs(np.arange(lo, hi + 1) - f)[:, None] / max(R, 1)
        win = score[lo : hi + 1]
        best = np.argmax(win - near, axis=0)
        found = np.isfinite(win[best, np.arange(V)])
        out[k] = np.where(found, (lo + best - f) / fps, 0.0)
    return out


@dataclasses.dataclass(frozen=True, eq=False)
class PoseAnalysis:
    """Everything :func:`analyze` computes for a clip (the signals of Figure 5).

    Parameters
    ----------
    fps : float
    variables : tuple of str, length V
    signals : ndarray, shape (F, V)
        Local probabilities ``p_i(t)`` (smoothed bounded curvature).
    weights : ndarray, shape (V,)
        ``w_i`` of the local signals.
    events : ndarray, shape (F, C)
        Contact start/end events (global evidence), one column per contact joint.
    event_joints : tuple of str, length C
    event_weight : float
        Weight of each event signal in ``P``.
    probability : ndarray, shape (F,)
        The pose probability signal ``P(t)``.
    candidates : ndarray of int, shape (C,)
        Candidate pose frames (maxima of ``P`` plus the first and last frames).
    priorities : ndarray, shape (C,)
        ``w_k`` of the candidates (``inf`` at the ends).
    contacts : Contacts or None
        The contacts used as global evidence.
    timing_signals : ndarray, shape (F, V), optional
        The signals the timing refinements look for extrema in: each
        variable's bounded curvature on its dominant trail
        (:func:`dominant_trail_signals`); default ``signals``.

    Examples
    --------
    >>> import mocaplab as ml
    >>> analysis = ml.staggered.analyze(ml.cmu("16_15").resample(30)[:60])
    >>> analysis.signals.shape, analysis.event_joints
    ((60, 32), ('LeftFoot', 'LeftToeBase', 'RightFoot', 'RightToeBase'))
    """

    fps: float
    variables: tuple[str, ...]
    signals: Array
    weights: Array
    events: Array
    event_joints: tuple[str, ...]
    event_weight: float
    probability: Array
    candidates: NDArray[np.int64]
    priorities: Array
    contacts: Any = None
    timing_signals: Array | None = None

    @property
    def n_frames(self) -> int:
        return int(self.probability.size)

    @property
    def times(self) -> Array:
        """Time of each frame, seconds, shape (F,)."""
        return np.arange(self.n_frames) / self.fps

    def select(
        self,
        *,
        max_poses: int | None = None,
        fraction: float | None = None,
        interval: tuple[float, float] | None = None,
    ) -> NDArray[np.int64]:
        """Culled pose frames (see :func:`cull_poses`)."""
        return cull_poses(
            self.candidates, self.priorities, self.fps, max_poses=max_poses, fraction=fraction, interval=interval
        )

    def priorities_of(self, frames: NDArray[np.int64]) -> Array:
        """Priorities ``w_k`` of a chosen pose set (neighbours taken within the set)."""
        return pose_priorities(self.probability, np.asarray(frames, dtype=np.int64), self.fps)

    def refinements(self, frames: NDArray[np.int64], *, max_refinement: float = MAX_REFINEMENT) -> Array:
        """Timing refinements of a chosen pose set, seconds, shape (K, V)."""
        x = self.signals if self.timing_signals is None else self.timing_signals
        return timing_refinements(x, frames, self.fps, max_refinement=max_refinement)


def analyze(
    motion: Motion,
    *,
    contacts: Any = "auto",
    smoothing: int | None = None,
    filter_width: float = FILTER_WIDTH,
    root_weight: float = 1.0,
    event_weight: float | Literal["auto"] = "auto",
    contact_joints: Sequence[str] | None = None,
    roles: Mapping[str, Any] | None = None,
    min_separation: float | None = None,
    min_prominence: float = MIN_PROMINENCE,
) -> PoseAnalysis:
    """Signals, pose probability and prioritised candidate poses of a clip.

    Parameters
    ----------
    motion : Motion
    contacts : Contacts, "auto" or None
        Environmental contacts for the global evidence.  ``"auto"`` detects
        them with :func:`mocaplab.contacts.stillness_contacts` (Coleman
        Appendix B) on ``contact_joints`` (default: the feet), with the
        minimum still time scaled to the gait (``min_duration="gait"``: the
        paper's 0.25 s up to a brisk walk, shorter in a run, where a foot is
        planted for 0.07-0.13 s and 0.25 s finds nothing); a
        :class:`NoContactsWarning` says when a clip gets none.  ``None``
        uses local evidence only.
    smoothing : int, optional
        Iterations of Laplacian smoothing (``lam = 0.5``) applied to every
        trail (:func:`laplacian_smooth`; their effect is a smoothing of
        deviation ``sqrt(smoothing / 2)`` frames, at most
        :data:`MAX_FILTER_SECONDS`).
        Default ``round(24 (fps / 120)^2)``: a Gaussian of about 3.5
        frames (29 ms) whatever the frame rate, set once for the CMU
        collection by watching the signals settle, as the paper suggests.
    filter_width : float
        Tent filter width in seconds (0.15 s in the paper).
    root_weight : float
        Multiplier of the weights of the translation signals (the root's and
        the translation variables').
    event_weight : float or "auto"
        Weight of each contact-event signal.  ``"auto"``: the largest local
        signal weight, so a contact change counts as much as the strongest
        moving limb (the paper only asks for a non-zero value).
    contact_joints : sequence of str, optional
        Joints for ``contacts="auto"`` (default: the ankles and toes of the
        joint roles, :func:`mocaplab.contacts.default_foot_joints`).
    roles : mapping, optional
        Joint-role overrides (:func:`mocaplab.roles.resolve_roles`) for the
        default contact joints.
    min_separation : float, optional
        Maxima of ``P`` closer than this (seconds) merge into the higher one
        (:func:`candidate_poses`; rounded up to whole frames, so no two
        poses are closer at any frame rate); default half the filter width,
        the tent filter's own half-width (0.075 s).  0 keeps every maximum.
    min_prominence : float
        Least prominence of a candidate maximum, as a fraction of its value
        (0.1; 0 keeps every maximum).  See "Sparse poses" in the module notes.

    Returns
    -------
    PoseAnalysis

    Examples
    --------
    The candidate poses of two seconds of a walk (frames at 30 fps; the first
    and last frames are always candidates):

    >>> import mocaplab as ml
    >>> ml.staggered.analyze(ml.cmu("16_15").resample(30)[:60]).candidates.tolist()
    [0, 16, 27, 33, 50, 59]
    """
    if not isinstance(motion, Motion):
        raise TypeError(f"Expected `motion` to be a Motion, got {type(motion).__name__}")
    if filter_width <= 0:
        raise ValueError(f"Expected `filter_width` > 0 seconds, got {filter_width!r}")
    fps = motion.fps
    iters = int(round(24 * (fps / 120.0) ** 2)) if smoothing is None else int(smoothing)
    check_rates(fps, filter_width=filter_width)
    most = int(2.0 * (MAX_FILTER_SECONDS * fps) ** 2)  # iterations smooth over sqrt(iters / 2) frames
    if not 0 <= iters <= most:
        raise ValueError(
            f"Expected `smoothing` from 0 to {most} iterations at {fps:g} fps (a smoothing over at most "
            f"MAX_FILTER_SECONDS = {MAX_FILTER_SECONDS:g} s), got {smoothing!r}"
        )
    tj = translation_joints(motion)
    V = motion.n_joints + 1 + len(tj)
    trails = motion_trails(motion)
    # continuous quaternion signs do not matter here: trails are rotated vectors
    pts = laplacian_smooth(trails.points, iterations=iters)
    kappa = bounded_curvature(pts)  # (F, T)
    signals = np.zeros((motion.n_frames, V))
    np.maximum.at(signals.T, trails.variable, kappa.T)
    smoothed_trails = dataclasses.replace(trails, points=pts)
    timing = dominant_trail_signals(smoothed_trails, kappa, V)
    weights = signal_weights(smoothed_trails, V, root_weight=root_weight)
    if isinstance(contacts, str):
        if contacts != "auto":
            raise ValueError(f"Expected `contacts` to be a Contacts, 'auto' or None, got {contacts!r}")
        try:
            contacts = stillness_contacts(motion, joints=contact_joints, roles=roles, min_duration="gait")
        except RolesError as err:
            raise RolesError(
                f"{err}. Without feet there are no foot contacts to find: pass contacts=None (poses from the "
                "motion alone, no constraint layer) or name the joints that touch the environment "
                "(contact_joints=[...])"
            ) from err
        if not contacts.mask.any():
            label = f" {motion.name!r}" if motion.name else ""
            warn(
                f"No environmental contacts found in the clip{label} on {list(contacts.joints)} "
                "(Appendix B: no joint still within 3 cm long enough): contact changes add no pose "
                "evidence and a constraint layer would hold nothing. Pass `contacts` (for example "
                "mocaplab.contacts.foot_contacts(motion)) or contacts=None to silence this.",
                NoContactsWarning,
            )
    if contacts is None:
        events = np.zeros((motion.n_frames, 0))
        event_joints: tuple[str, ...] = ()
    else:
        events = contact_events(contacts, motion.n_frames)
        event_joints = tuple(contacts.joints)
    ew = float(weights.max()) if event_weight == "auto" else float(event_weight)
    if ew < 0:
        raise ValueError(f"Expected `event_weight` >= 0, got {event_weight!r}")
    P = pose_probability(signals, weights, fps, events=events, event_weight=ew, width=filter_width)
    if min_separation is None:
        min_separation = 0.5 * filter_width  # the tent filter's half-width
    elif not (np.isfinite(min_separation) and min_separation >= 0):
        raise ValueError(f"Expected `min_separation` >= 0 seconds, got {min_separation!r}")
    # whole frames, rounded up: no two maxima closer than `min_separation` seconds at any rate
    # (rounding to nearest made 75 ms two frames at 30 fps, 66.7 ms)
    sep = int(np.ceil(float(min_separation) * fps - 1e-9))
    cand = candidate_poses(P, separation=sep, min_prominence=min_prominence)
    return PoseAnalysis(
        fps=fps,
        variables=variable_names(motion.skeleton, tj),
        signals=signals,
        weights=weights,
        events=events,
        event_joints=event_joints,
        event_weight=ew,
        probability=P,
        candidates=cand,
        priorities=pose_priorities(P, cand, fps),
        contacts=contacts,
        timing_signals=timing,
    )
