"""Fitting splines and displacement maps to dense motion (section 4.1.1, Appendix A).

Given pose times and refinements, every variable's knots are its values at
its refined knot times.  Between two knots:

* **Translations:** the two inner Bezier control points minimise the squared
  distance to the samples, a linear least-squares problem solved in closed
  form for all segments at once (:func:`fit_translation_tangents`).
* **Rotations (Appendix A):** the tangent orientations ``q2, q3`` of the
  recursive-slerp cubic minimise the fitting term
  ``f_f = mean_k arccos(q_k . s(t_k))^2`` over the interior samples
  (:func:`fit_rotation_tangents`).  The paper adds the unit-length penalty
  ``f_c = | |q2|^2 + |q3|^2 - 2 |`` (``w_f = 1000 w_c``) because it moves raw
  quaternion components with Nelder-Mead; that method is kept
  (``method="nelder-mead"``, :func:`rotation_objective`), but the default
  moves the tangents on the rotation group itself, where they stay unit and
  ``f_c`` is zero by construction (see below).
* **Displacements:** ``d = v (-) s`` on every sample (:func:`fit_representation`).

Because the displacement maps absorb whatever the splines miss, the fit
quality never affects reconstruction, only how edits look (and how much the
displacement maps must carry: lessons 11-13 check that the splines carry the
motion, so a broken fit fails them).

How the tangents are found
--------------------------
1. **Start** (``start="tangent"``, default): a *tangent-space
   least-squares* solution.  The samples are mapped to rotation vectors
   relative to the segment's first knot, a Euclidean cubic Bezier is fitted
   there by the same linear least squares as translations, and its control
   points are mapped back with ``exp``.  ``start="linear"`` is the paper's
   linear (slerp) spline, ``start="ease"`` the ease-in/out spline (identity
   tangents); unpolished, these two are the baselines a fit must beat, since
   they ignore the samples (lessons 11-13 assert that the fit needs much
   smaller displacements than both).
2. **Polish** (``method="gauss-newton"``, default): Gauss-Newton steps on the
   spherical residuals ``log(s(t_k)^-1 q_k)`` of every segment at once.  A
   step solves the same 2 x 2 Bernstein least squares as the start, now for
   corrections ``q2 <- q2 exp(da)``, ``q3 <- q3 exp(db)`` (the Jacobian of
   the Euclidean cubic, exact to first order for the arcs between poses); a
   segment takes its step only if its squared error goes down, else the step
   is halved for the next iteration, so no segment ever fits worse than its
   start.  ``maxiter`` (default 2) steps.
3. ``method="nelder-mead"``: the paper's optimiser on ``w_f f_f + w_c f_c``
   (``scipy.optimize.minimize``, ``adaptive=True``, which converges in 8
   dimensions where the classic coefficients stall), renormalised, kept only
   if it fits all the segment's samples better.  From the tangent start it
   runs only on segments whose RMS error exceeds ``polish_tol`` (2 degrees),
   from a small simplex, on at most ``max_samples`` (16) samples, for
   ``maxiter`` (default 30) iterations.

Measured on the hops 49_03 (``benchmarks/bench_staggered.py``; fit error:
the mean RMS angle between the samples and their segment's spline over the
segments that move, degrees; extraction time on this machine):

==================================================  =========  ===========
extraction of 49_03                                 fit error  time
==================================================  =========  ===========
former default (every maximum of P, no filter,      0.958      977 ms
Nelder-Mead polish)
the same poses and data, Gauss-Newton polish        0.928      133 ms
default (distinct poses, filtered, Gauss-Newton)    0.726      186 ms
  without the polish                                0.781      118 ms
  with Nelder-Mead instead                          0.758      641 ms
==================================================  =========  ===========

Nelder-Mead also left the run 09_06 and the walk 16_15 unchanged (0.917 and
0.516 degrees before and after on the former poses) at about ten times the
cost of the rest of the extraction.  From the linear start it took 40 s on
16_15 (``maxiter=200``) and ended worse than the tangent start.

Longer than 800 lines because the module holds the whole of section 4.1.1 and
Appendix A: the translation and rotation fits, their Gauss-Newton polish and
the extraction that chains them read each other's segment arrays, and each
public function carries a runnable example.
"""

from __future__ import annotations

import dataclasses
import warnings
from collections.abc import Mapping
from typing import Any, Literal

import numpy as np
from numpy.typing import NDArray
from scipy.optimize import minimize

from .. import quat
from .._checks import integer, real
from .._warnings import warn
from ..motion import Motion
from ..roles import resolve_roles
from .constraints import ConstraintLayer
from .features import NoContactsWarning, analyze, check_rates
from .noise import FILTER_SIGMA, orientation_filter, sharp_detail
from .representation import StaggeredMotion, casteljau, locate, next_active, pose_u, quat_bezier, translation_joints

__all__ = [
    "W_F",
    "W_C",
    "fit_translation_tangents",
    "fit_rotation_tangents",
    "gauss_newton_tangents",
    "rotation_objective",
    "fit_representation",
    "extract",
]

Array = NDArray[np.float64]

W_F = 1000.0
"""Appendix A fitting weight ``w_f`` (``w_f = 1000 w_c``)."""
W_C = 1.0
"""Appendix A unit-length constraint weight ``w_c``."""

_RIDGE = 1e-6


def fit_translation_tangents(
    seg: NDArray[np.int64], tn: Array, y: Array, p0: Array, p3: Array
) -> tuple[Array, Array]:
    """Least-squares inner control points of cubic Bezier segments.

    Minimises ``sum |B(t'_n) - y_n|^2`` over ``P1, P2`` for every segment at
    once (2 x 2 normal equations per segment, solved in closed form).  A tiny
    ridge term pulls toward the linear spline, which decides segments with
    fewer than two interior samples.

    Parameters
    ----------
    seg : ndarray of int, shape (N,)
        Segment of each sample, in ``[0, S)``.
    tn : ndarray, shape (N,)
        Normalised time of each sample.
    y : ndarray, shape (N, D)
        Sample values.
    p0, p3 : ndarray, shape (S, D)
        End points of the segments.

    Returns
    -------
    a, b : ndarray, shape (S, D)
        ``P1 - p0`` and ``P2 - p3``.

    Examples
    --------
    Samples of the parabola ``(t, t^2)`` give back its Bezier controls
    ``P1 = (1/3, 0)`` and ``P2 = (2/3, 1/3)``:

    >>> import numpy as np
    >>> import mocaplab as ml
    >>> tn = np.linspace(0, 1, 9)[1:-1]
    >>> a, b = ml.staggered.fit_translation_tangents(
    ...     np.zeros(7, dtype=int), tn, np.c_[tn, tn**2], np.array([[0.0, 0.0]]), np.array([[1.0, 1.0]]))
    >>> a.round(4).tolist(), b.round(4).tolist()
    ([[0.3333, 0.0]], [[-0.3333, -0.6667]])
    """
    S, D = p0.shape
    s = 1.0 - tn
    b0, b1, b2, b3 = s**3, 3 * s * s * tn, 3 * s * tn * tn, tn**3
    r = y - (b0 + b1)[:, None] * p0[seg] - (b2 + b3)[:, None] * p3[seg]
    a11 = np.bincount(seg, b1 * b1, minlength=S) + _RIDGE
    a12 = np.bincount(seg, b1 * b2, minlength=S)
    a22 = np.bincount(seg, b2 * b2, minlength=S) + _RIDGE
    lin = (p3 - p0) / 3.0
    r1 = np.stack([np.bincount(seg, b1 * r[:, d], minlength=S) for d in range(D)], axis=1) + _RIDGE * lin
    r2 = np.stack([np.bincount(seg, b2 * r[:, d], minlength=S) for d in range(D)], axis=1) - _RIDGE * lin
    det = a11 * a22 - a12 * a12
    a = (a22[:, None] * r1 - a12[:, None] * r2) / det[:, None]
    b = (a11[:, None] * r2 - a12[:, None] * r1) / det[:, None]
    return a, b


def _casteljau_fast(ctrl: Array, t: Array) -> Array:
    """Recursive slerp of 4 control quaternions ``ctrl`` (4, 4) at ``t`` (n,): (n, 4).

    The same construction as :func:`quat_bezier`, with each level's slerps
    stacked into one array operation (3 + 2 + 1 slerps in 3 passes): this is
    the inner loop of Nelder-Mead, where numpy call overhead dominates.
    """
    # level 1: the control polygon's three edges have scalar angles
    a, b = ctrl[:3], ctrl[1:]
    na = np.sqrt(np.einsum("ij,ij->i", a, a))
    nb = np.sqrt(np.einsum("ij,ij->i", b, b))
    theta = np.arccos(np.clip(np.einsum("ij,ij->i", a, b) / (na * nb), -1.0, 1.0))[:, None]  # (3, 1)
    st = np.sin(theta)
    small = st < 1e-9
    tt = t[None, :]
    w0 = np.where(small, 1.0 - tt, np.sin((1.0 - tt) * theta) / np.where(small, 1.0, st))
    w1 = np.where(small, tt, np.sin(tt * theta) / np.where(small, 1.0, st))
    lev = w0[..., None] * a[:, None, :] + w1[..., None] * b[:, None, :]  # (3, n, 4)
    for _ in range(2):
        a, b = lev[:-1], lev[1:]
        na = np.sqrt(np.einsum("...i,...i->...", a, a))
        nb = np.sqrt(np.einsum("...i,...i->...", b, b))
        theta = np.arccos(np.clip(np.einsum("...i,...i->...", a, b) / (na * nb), -1.0, 1.0))
        st = np.sin(theta)
        small = st < 1e-9
        safe = np.where(small, 1.0, st)
        w0 = np.where(small, 1.0 - tt, np.sin((1.0 - tt) * theta) / safe)
        w1 = np.where(small, tt, np.sin(tt * theta) / safe)
        lev = w0[..., None] * a + w1[..., None] * b
    return lev[0]


def rotation_objective(
    x: Array, q1: Array, q4: Array, t: Array, q: Array, w_f: float = W_F, w_c: float = W_C
) -> float:
    """Appendix A objective ``w_f f_f(q2, q3) + w_c f_c(q2, q3)``.

    Parameters
    ----------
    x : ndarray, shape (8,)
        ``q2`` and ``q3`` (not necessarily unit).
    q1, q4 : ndarray, shape (4,)
        Segment end orientations.
    t : ndarray, shape (n,)
        Normalised times of the interior samples.
    q : ndarray, shape (n, 4)
        Sample orientations (same hemisphere as ``q1``).
    w_f, w_c : float
        Weights (``w_f = 1000 w_c`` in the paper).

    Returns
    -------
    float
        The objective; 0 when the spline passes through every sample with unit controls.

    Notes
    -----
    A choice the paper leaves open: how the spline treats non-unit control
    quaternions while the optimiser moves them.  Here ``q2`` and ``q3`` are
    normalised inside the spline (a rotation is a direction in R^4), so
    ``f_f`` measures rotations only and the final renormalisation leaves the
    fitted curve unchanged; ``f_c`` keeps the parameters near unit length as
    the paper intends.  (Letting the norms shape the curve, as a literal
    slerp of raw 4-vectors would, gives Nelder-Mead degenerate minima with
    ``|q2|^2 + |q3|^2 = 2`` but very unequal norms, which renormalisation then
    spoils.)  ``|q_k . s|`` makes the angle independent of the sign of ``q_k``.

    Examples
    --------
    >>> import numpy as np
    >>> from scipy.spatial.transform import Rotation
    >>> import mocaplab as ml
    >>> tn = np.linspace(0, 1, 9)[1:-1]          # seven interior samples of one segment
    >>> seg = np.zeros(7, dtype=int)
    >>> q = Rotation.from_euler("y", 90 * tn[:, None], degrees=True).as_quat()   # a steady turn
    >>> q1, q4 = Rotation.from_euler("y", [[0], [90]], degrees=True).as_quat()[:, None]
    >>> exact = Rotation.from_euler("y", [[30], [60]], degrees=True).as_quat().ravel()
    >>> float(ml.staggered.rotation_objective(exact, q1[0], q4[0], tn, q))
    0.0
    >>> off = Rotation.from_euler("y", [[20], [80]], degrees=True).as_quat().ravel()
    >>> round(float(ml.staggered.rotation_objective(off, q1[0], q4[0], tn, q)), 3)
    1.488
    """
    q2, q3 = x[:4], x[4:]
    n2, n3 = float(q2 @ q2), float(q3 @ q3)
    f_c = abs(n2 + n3 - 2.0)
    if t.size == 0:
        return w_c * f_c
    if n2 <= 0.0 or n3 <= 0.0:
        return np.inf
    s = _casteljau_fast(np.stack([q1, q2 / np.sqrt(n2), q3 / np.sqrt(n3), q4]), t)
    n = np.sqrt(np.einsum("ij,ij->i", s, s))
    c = np.abs(np.einsum("ij,ij->i", q, s)) / np.maximum(n, 1e-300)
    ang = np.arccos(np.minimum(c, 1.0))
    return w_f * float(ang @ ang) / t.size + w_c * f_c


def _segment_rms(seg: NDArray[np.int64], tn: Array, q: Array, q1: Array, q2: Array, q3: Array, q4: Array) -> Array:
    """RMS rotation angle (radians) between the samples and their segment's spline, per segment."""
    S = q1.shape[0]
    inner = (tn > 0.0) & (tn < 1.0)
    g = seg[inner]
    s = quat_bezier(q1[g], q2[g], q3[g], q4[g], tn[inner])
    s = s / np.linalg.norm(s, axis=-1, keepdims=True)
    ang = 2.0 * np.arccos(np.minimum(np.abs(np.einsum("ij,ij->i", q[inner], s)), 1.0))
    n = np.bincount(g, minlength=S)
    return np.sqrt(np.bincount(g, ang * ang, minlength=S) / np.maximum(n, 1))


def _bernstein_normal(seg: NDArray[np.int64], tn: Array, S: int) -> tuple[Any, ...]:
    """Inner Bernstein weights ``b1, b2`` (n,) and the per-segment normal matrix entries and determinant (S,)."""
    s = 1.0 - tn
    b1, b2 = 3.0 * s * s * tn, 3.0 * s * tn * tn
    a11 = np.bincount(seg, b1 * b1, minlength=S) + _RIDGE
    a12 = np.bincount(seg, b1 * b2, minlength=S)
    a22 = np.bincount(seg, b2 * b2, minlength=S) + _RIDGE
    return b1, b2, a11, a12, a22, a11 * a22 - a12 * a12


def _spherical_residuals(
    seg: NDArray[np.int64], tn: Array, q: Array, q1: Array, q2: Array, q3: Array, q4: Array
) -> tuple[Array, Array]:
    """Residual rotation vectors ``log(s(t)^-1 q)`` (n, 3) of the samples and the squared error per segment (S,)."""
    ctrl = np.stack([q1[seg], q2[seg], q3[seg], q4[seg]], axis=1)  # (n, 4, 4)
    theta = np.arccos(np.clip(np.einsum("...i,...i->...", ctrl[:, :3], ctrl[:, 1:]), -1.0, 1.0))
    r = quat.log(quat.mul(quat.inv(casteljau(ctrl, theta, tn)), q))
    return r, np.bincount(seg, np.einsum("ij,ij->i", r, r), minlength=q1.shape[0]).astype(float)


def _hemisphere(q: Array, ref: Array) -> Array:
    """``q`` with the sign that puts it in the hemisphere of ``ref`` (spline controls never flip)."""
    return np.where(np.sum(q * ref, axis=-1, keepdims=True) < 0, -q, q)


def gauss_newton_tangents(
    seg: NDArray[np.int64],
    tn: Array,
    q: Array,
    q1: Array,
    q2: Array,
    q3: Array,
    q4: Array,
    *,
    iterations: int = 2,
    residuals: tuple[Array, Array] | None = None,
) -> tuple[Array, Array, Array, int]:
    """Polish tangent orientations by Gauss-Newton steps on the spherical residuals (all segments at once).

    Parameters
    ----------
    seg : ndarray of int, shape (n,)
        Segment of each *interior* sample, in ``[0, S)``.
    tn : ndarray, shape (n,)
        Normalised times, strictly inside (0, 1).
    q : ndarray, shape (n, 4)
        Sample orientations.
    q1, q2, q3, q4 : ndarray, shape (S, 4)
        Control orientations (unit, one hemisphere); ``q2, q3`` are the start.
    iterations : int
        Number of steps.
    residuals : (ndarray (n, 3), ndarray (S,)), optional
        The start's residuals and squared errors when already computed.

    Returns
    -------
    q2, q3 : ndarray, shape (S, 4)
        Unit control orientations; every segment's squared error is at most
        its starting one.
    sse : ndarray, shape (S,)
        Sum of squared residual angles of each segment (radians^2).
    improved : int
        Segments that took at least one step.

    Notes
    -----
    One step minimises ``sum_k |b1(t_k) da + b2(t_k) db - r_k|^2`` over the
    corrections ``da, db`` (rotation vectors, ``q2 exp(da)``, ``q3 exp(db)``)
    given the residuals ``r_k = log(s(t_k)^-1 q_k)``: the Euclidean Bezier
    Jacobian, exact to first order when the segment's controls are close.
    A segment whose error would not go down keeps its controls and halves
    its next step.

    Examples
    --------
    Starting from tangents at 20 and 80 degrees, the steps find the exact ones
    of a steady 90 degree turn, at 30 and 60 degrees:

    >>> import numpy as np
    >>> from scipy.spatial.transform import Rotation
    >>> import mocaplab as ml
    >>> tn = np.linspace(0, 1, 9)[1:-1]          # seven interior samples of one segment
    >>> seg = np.zeros(7, dtype=int)
    >>> q = Rotation.from_euler("y", 90 * tn[:, None], degrees=True).as_quat()   # a steady turn
    >>> q1, q4 = Rotation.from_euler("y", [[0], [90]], degrees=True).as_quat()[:, None]
    >>> q2, q3 = Rotation.from_euler("y", [[20], [80]], degrees=True).as_quat()[:, None]
    >>> q2, q3, sse, improved = ml.staggered.gauss_newton_tangents(seg, tn, q, q1, q2, q3, q4, iterations=3)
    >>> np.degrees(Rotation.from_quat(np.r_[q2, q3]).magnitude()).round(6).tolist(), improved
    ([30.0, 60.0], 1)
    """
    S = q1.shape[0]
    b1, b2, a11, a12, a22, det = _bernstein_normal(seg, tn, S)
    r, err = _spherical_residuals(seg, tn, q, q1, q2, q3, q4) if residuals is None else residuals
    scale = np.ones(S)
    took = np.zeros(S, dtype=bool)
    for _ in range(int(iterations)):
        r1 = np.stack([np.bincount(seg, b1 * r[:, d], minlength=S) for d in range(3)], axis=1)
        r2 = np.stack([np.bincount(seg, b2 * r[:, d], minlength=S) for d in range(3)], axis=1)
        da = scale[:, None] * (a22[:, None] * r1 - a12[:, None] * r2) / det[:, None]
        db = scale[:, None] * (a11[:, None] * r2 - a12[:, None] * r1) / det[:, None]
        n2 = _hemisphere(quat.normalize(quat.mul(q2, quat.exp(da))), q1)
        n3 = _hemisphere(quat.normalize(quat.mul(q3, quat.exp(db))), q1)
        r_new, err_new = _spherical_residuals(seg, tn, q, q1, n2, n3, q4)
        ok = err_new < err
        q2 = np.where(ok[:, None], n2, q2)
        q3 = np.where(ok[:, None], n3, q3)
        r = np.where(ok[seg, None], r_new, r)
        err = np.where(ok, err_new, err)
        scale = np.where(ok, 1.0, 0.5 * scale)
        took |= ok
    return q2, q3, err, int(took.sum())


def fit_rotation_tangents(
    seg: NDArray[np.int64],
    tn: Array,
    q: Array,
    q1: Array,
    q4: Array,
    *,
    start: Literal["tangent", "linear", "ease"] = "tangent",
    optimize: bool = True,
    method: Literal["gauss-newton", "nelder-mead"] = "gauss-newton",
    maxiter: int | None = None,
    polish_tol: float = np.deg2rad(2.0),
    max_samples: int = 16,
    w_f: float = W_F,
    w_c: float = W_C,
) -> tuple[Array, Array, dict[str, Any]]:
    """Tangent orientations of recursive-slerp cubic segments (Appendix A).

    Parameters
    ----------
    seg : ndarray of int, shape (N,)
        Segment of each sample in ``[0, S)``.
    tn : ndarray, shape (N,)
        Normalised times.
    q : ndarray, shape (N, 4)
        Sample orientations, sign-continuous with the end orientations.
    q1, q4 : ndarray, shape (S, 4)
        End orientations of the segments.
    start : {"tangent", "linear", "ease"}
        Starting solution: tangent-space least squares (default, see the
        module notes), the linear slerp spline of the paper, or the
        ease-in/out spline (identity tangents: ``q2 = q1``, ``q3 = q4``, zero
        velocity at the knots).  The last two ignore the samples: with
        ``optimize=False`` they are the baselines a fit must beat.
    optimize : bool
        Polish the start (False keeps it).
    method : {"gauss-newton", "nelder-mead"}
        The polish: Gauss-Newton steps on the rotation group for every
        segment at once (default, :func:`gauss_newton_tangents`), or the
        paper's Nelder-Mead per segment on :func:`rotation_objective`.
    maxiter : int, optional
        Gauss-Newton steps (default 2), or the Nelder-Mead iteration bound
        per segment (default 30).
    polish_tol : float
        Nelder-Mead from ``start="tangent"`` runs only on segments whose
        starting RMS rotation error (radians) exceeds this (default 2 degrees).
    max_samples : int
        Interior samples used by the Nelder-Mead objective (evenly subsampled).
    w_f, w_c : float
        Appendix A weights (Nelder-Mead).

    Returns
    -------
    alpha, beta : ndarray, shape (S, 4)
        Unit quaternions with ``q2 = q1 (+) alpha`` and ``q3 = q4 (+) beta``.
    info : dict
        ``"optimized"`` (segments the polish improved, or ran Nelder-Mead
        on), ``"nfev"`` (objective evaluations: per segment for Nelder-Mead,
        one evaluation of every segment per Gauss-Newton step),
        ``"start_error"`` and ``"error"`` (RMS rotation angle per segment
        over all its interior samples, radians).

    Examples
    --------
    A steady 90 degree turn is fitted exactly, with tangents a third of the way (30 degrees):

    >>> import numpy as np
    >>> from scipy.spatial.transform import Rotation
    >>> import mocaplab as ml
    >>> tn = np.linspace(0, 1, 9)[1:-1]          # seven interior samples of one segment
    >>> seg = np.zeros(7, dtype=int)
    >>> q = Rotation.from_euler("y", 90 * tn[:, None], degrees=True).as_quat()   # a steady turn
    >>> q1, q4 = Rotation.from_euler("y", [[0], [90]], degrees=True).as_quat()[:, None]
    >>> alpha, beta, info = ml.staggered.fit_rotation_tangents(seg, tn, q, q1, q4)
    >>> np.degrees(Rotation.from_quat(alpha).magnitude()).round(6).tolist()
    [30.0]
    >>> bool(info["error"][0] < 1e-9)
    True
    """
    if start not in ("tangent", "linear", "ease"):
        raise ValueError(f"Expected `start` in ('tangent', 'linear', 'ease'), got {start!r}")
    if method not in ("gauss-newton", "nelder-mead"):
        raise ValueError(f"Expected `method` in ('gauss-newton', 'nelder-mead'), got {method!r}")
    if maxiter is None:
        maxiter = 2 if method == "gauss-newton" else 30
    if int(maxiter) != maxiter or maxiter < 0:
        raise ValueError(f"Expected `maxiter` to be an integer >= 0, got {maxiter!r}")
    S = q1.shape[0]
    if start == "tangent":
        rel = quat.log(quat.mul(quat.inv(q1[seg]), q))  # (N, 3)
        end = quat.log(quat.mul(quat.inv(q1), q4))  # (S, 3)
        a, b = fit_translation_tangents(seg, tn, rel, np.zeros_like(end), end)
        q2 = quat.mul(q1, quat.exp(a))
        q3 = quat.mul(q1, quat.exp(end + b))
    elif start == "linear":
        q2 = quat.slerp(q1, q4, np.full(S, 1.0 / 3.0))
        q3 = quat.slerp(q1, q4, np.full(S, 2.0 / 3.0))
    else:
        q2, q3 = np.array(q1, copy=True), np.array(q4, copy=True)
    # keep every control orientation in the hemisphere of the first knot
    q2 = _hemisphere(q2, q1)
    q3 = _hemisphere(q3, q1)
    inner = (tn > 0.0) & (tn < 1.0)
    counts = np.bincount(seg[inner], minlength=S)
    if optimize and method == "gauss-newton" and maxiter > 0:
        g = seg[inner]
        r, sse = _spherical_residuals(g, tn[inner], q[inner], q1, q2, q3, q4)
        n = np.maximum(counts, 1)
        err0 = np.sqrt(sse / n)
        # segments that fit exactly already (still joints) are left out of the work
        rows = np.flatnonzero(sse > 1e-24)
        if rows.size == 0:
            return _result(q1, q2, q3, q4, err0, err0, 0, 0)
        local = np.full(S, -1, dtype=np.int64)
        local[rows] = np.arange(rows.size)
        take = local[g] >= 0
        gl = local[g[take]]
        n2, n3, sse_rows, improved = gauss_newton_tangents(
            gl, tn[inner][take], q[inner][take], q1[rows], q2[rows], q3[rows], q4[rows],
            iterations=int(maxiter), residuals=(r[take], sse[rows]),
        )
        q2[rows], q3[rows] = n2, n3
        err = np.array(err0, copy=True)
        err[rows] = np.sqrt(sse_rows / n[rows])
        return _result(q1, q2, q3, q4, err0, err, improved, (int(maxiter) + 1) * rows.size)
    err0 = _segment_rms(seg, tn, q, q1, q2, q3, q4)
    todo = np.flatnonzero(counts > 0) if optimize else np.zeros(0, dtype=np.int64)
    if start == "tangent":
        todo = todo[err0[todo] > polish_tol]
    nfev = 0
    if todo.size:
        order = np.argsort(seg, kind="stable")
        bounds = np.searchsorted(seg[order], np.arange(S + 1))
        for s in todo:
            idx = order[bounds[s] : bounds[s + 1]]
            idx = idx[(tn[idx] > 0.0) & (tn[idx] < 1.0)]
            if idx.size > max_samples:
                idx = idx[np.linspace(0, idx.size - 1, max_samples).round().astype(np.int64)]
            t, qs = tn[idx], q[idx]
            x0 = np.concatenate([q2[s], q3[s]])
            options: dict[str, Any] = {"maxiter": int(maxiter), "xatol": 1e-6, "fatol": 1e-9, "adaptive": True}
            if start == "tangent":
                step = float(np.clip(err0[s], 1e-3, 0.05))
                options["initial_simplex"] = np.vstack([x0, x0 + step * np.eye(8)])
            args = (q1[s], q4[s], t, qs, w_f, w_c)
            res = minimize(rotation_objective, x0, args=args, method="Nelder-Mead", options=options)
            nfev += int(res.nfev)
            c2 = res.x[:4] / np.linalg.norm(res.x[:4])
            c3 = res.x[4:] / np.linalg.norm(res.x[4:])
            # renormalising moves the curve (Appendix A): keep the result only
            # if the renormalised spline fits the segment's samples better
            full = order[bounds[s] : bounds[s + 1]]
            ins = full[(tn[full] > 0.0) & (tn[full] < 1.0)]
            new_err = _segment_rms(
                np.zeros(ins.size, dtype=np.int64), tn[ins], q[ins], q1[s][None], c2[None], c3[None], q4[s][None]
            )[0]
            if new_err < err0[s]:
                q2[s], q3[s] = c2, c3
    err = _segment_rms(seg, tn, q, q1, q2, q3, q4) if todo.size else err0
    return _result(q1, q2, q3, q4, err0, err, int(todo.size), nfev)


def _result(
    q1: Array, q2: Array, q3: Array, q4: Array, err0: Array, err: Array, optimized: int, nfev: int
) -> tuple[Array, Array, dict[str, Any]]:
    alpha = quat.mul(quat.inv(q1), quat.normalize(q2))
    beta = quat.mul(quat.inv(q4), quat.normalize(q3))
    return alpha, beta, {"optimized": optimized, "nfev": nfev, "start_error": err0, "error": err}


def knot_values(
    motion: Motion, knot_times: Array, rotations: Array, positions: Array | None = None
) -> tuple[Array, Array]:
    """Values of the clip at knot times, shape (K, V) seconds.

    Knots on a frame take the frame's values exactly; others are
    interpolated (linear / slerp).  ``rotations`` is the sign-continuous
    (unrolled) rotation array of the clip.  Returns positions and rotations
    (K, J, 4): the root (K, 3) by default, or, with ``positions`` (F, P, 3)
    the samples of the position variables (columns ``0, J + 1, ..., J + P - 1``
    of ``knot_times``), their values (K, P, 3).
    """
    J = motion.n_joints
    u = np.clip(knot_times * motion.fps, 0.0, motion.n_frames - 1)
    f0 = np.clip(np.floor(u + 1e-9).astype(np.int64), 0, motion.n_frames - 1)
    f1 = np.minimum(f0 + 1, motion.n_frames - 1)
    w = np.where(np.abs(u - np.round(u)) < 1e-9, 0.0, u - f0)
    if positions is None:
        root = (1 - w[:, :1]) * motion.root_positions[f0[:, 0]] + w[:, :1] * motion.root_positions[f1[:, 0]]
    else:
        P = positions.shape[1]
        pc = np.concatenate([[0], J + np.arange(1, P)]).astype(np.int64)
        p = np.arange(P)
        wp = w[:, pc, None]
        root = (1 - wp) * positions[f0[:, pc], p] + wp * positions[f1[:, pc], p]
    j = np.arange(J)
    a = rotations[f0[:, 1 : J + 1], j]
    b = rotations[f1[:, 1 : J + 1], j]
    on = w[:, 1 : J + 1] == 0.0
    rot = np.where(on[..., None], a, quat.slerp(a, b, w[:, 1 : J + 1]))
    rot = np.where(np.sum(rot * a, axis=-1, keepdims=True) < 0, -rot, rot)
    return root, rot


def fit_representation(
    motion: Motion,
    times: Array,
    refinements: Array,
    *,
    active: NDArray[np.bool_] | None = None,
    priorities: Array | None = None,
    start: Literal["tangent", "linear", "ease"] = "tangent",
    optimize: bool = True,
    method: Literal["gauss-newton", "nelder-mead"] = "gauss-newton",
    maxiter: int | None = None,
    polish_tol: float = np.deg2rad(2.0),
    filter_sigma: float | None = FILTER_SIGMA,
) -> StaggeredMotion:
    """Build the staggered representation of a clip from pose times and refinements.

    Parameters
    ----------
    motion : Motion
        Its animated translation channels become translation variables
        (:func:`~mocaplab.staggered.representation.translation_joints`),
        fitted like the root translation; constant ones are kept as rest
        translations.
    times : ndarray, shape (K,)
        Pose times in seconds; the first must be 0 and the last the clip's
        duration (so every frame is reproduced).
    refinements : ndarray, shape (K, V)
        Timing refinements in seconds (knots strictly ordered per variable),
        ``V = J + 1 + T``.
    active : ndarray of bool, shape (K, V), optional
        Partial poses (default: every pose controls every variable).
    priorities : ndarray, shape (K,), optional
    start, optimize, method, maxiter, polish_tol
        Rotation fitting options, see :func:`fit_rotation_tangents`.
    filter_sigma : float or None
        Fit the poses, splines and displacement maps to the rotations
        filtered by :func:`~mocaplab.staggered.noise.orientation_filter`
        (Gaussian sigma in seconds, default 0.03 s) and keep the rest as the
        noise layer on the pose timing (section 6, see
        :mod:`mocaplab.staggered.noise`), except its sharp motions
        (:func:`~mocaplab.staggered.noise.sharp_detail`), kept as the sharp
        layer, which moves with each joint's knots.  ``None`` or 0: no filter, no
        noise layer.

    Returns
    -------
    StaggeredMotion
        Evaluating it reproduces ``motion`` on every frame (to rounding),
        translations included.

    Examples
    --------
    Refit a clip with the pose timing :func:`extract` chose:

    >>> import numpy as np
    >>> import mocaplab as ml
    >>> clip = ml.cmu("16_15").resample(30)[:60]
    >>> sm = ml.staggered.extract(clip)
    >>> again = ml.staggered.fit_representation(clip, sm.times, sm.refinements)
    >>> bool(np.allclose(again.evaluate().global_positions(), clip.global_positions()))
    True
    """
    if not isinstance(motion, Motion):
        raise TypeError(f"Expected `motion` to be a Motion, got {type(motion).__name__}")
    times = np.asarray(times, dtype=float).reshape(-1)
    K = times.size
    J = motion.n_joints
    tj = translation_joints(motion)
    T = len(tj)
    V = J + 1 + T
    refinements = np.asarray(refinements, dtype=float)
    if refinements.shape != (K, V):
        raise ValueError(f"Expected `refinements` of shape ({K}, {V}), got {refinements.shape}")
    if K < 2 or abs(times[0]) > 1e-9 or abs(times[-1] - motion.duration) > 1e-9:
        raise ValueError(
            f"Expected pose `times` from 0 to the clip duration {motion.duration:.4f} s, got "
            f"{times[0] if K else None} .. {times[-1] if K else None}"
        )
    act = np.ones((K, V), dtype=bool) if active is None else np.asarray(active, dtype=bool)
    captured = quat.unroll(motion.rotations, axis=0)
    noise = sharp = None
    rotations = captured
    if filter_sigma:
        # section 6: the layers that timing edits move are fitted to filtered rotations
        rotations = orientation_filter(captured, float(filter_sigma), motion.fps)
        # what the filter removed from a sharp motion moves with its joint's knots (the sharp layer, issue 25
        # item 3); the capture noise stays on the pose timing
        sharp = sharp_detail(captured, rotations, motion.skeleton, motion.fps, sigma=float(filter_sigma))
        moved = np.any(sharp != 0.0, axis=-1, keepdims=True)
        carried = np.where(moved, quat.mul(rotations, quat.exp(sharp)), rotations)
        noise = quat.log(quat.mul(quat.inv(carried), captured))
        if not moved.any():
            sharp = None
    positions = np.asarray(motion.root_positions)[:, None]
    if T:
        positions = np.concatenate([positions, np.asarray(motion.translations)[:, list(tj)]], axis=1)
    P = 1 + T
    pc = np.concatenate([[0], J + np.arange(1, P)]).astype(np.int64)
    knots = times[:, None] + refinements
    position_values, rotation_values = knot_values(
        motion, np.where(act, knots, times[:, None]), rotations, positions
    )
    t = motion.times
    k0, k1, tn = locate(times, refinements, act, t)
    nxt = next_active(act)
    nxt_safe = np.where(nxt < 0, np.arange(K)[:, None], nxt)
    # translations (the root and the translation variables): one segment per (start pose, variable)
    p = np.arange(P)
    a, b = fit_translation_tangents(
        (k0[:, pc] * P + p).reshape(-1),
        tn[:, pc].reshape(-1),
        positions.reshape(-1, 3),
        position_values.reshape(K * P, 3),
        position_values[nxt_safe[:, pc], p].reshape(K * P, 3),
    )
    position_tangents = np.stack([a.reshape(K, P, 3), b.reshape(K, P, 3)], axis=2)
    # rotations: one segment per (start pose, joint); joints constant over the
    # clip (CMU hip joints, clavicles...) keep identity tangents, which fit exactly
    rotation_tangents = np.zeros((K, J, 2, 4))
    rotation_tangents[..., 3] = 1.0
    js = np.flatnonzero(~np.all(rotations == rotations[:1], axis=(0, 2)))
    if js.size:
        nj = js.size
        seg = (k0[:, 1 + js] * nj + np.arange(nj)).reshape(-1)
        q1 = rotation_values[:, js].reshape(K * nj, 4)
        q4 = rotation_values[nxt_safe[:, 1 + js], js].reshape(K * nj, 4)
        alpha, beta, _ = fit_rotation_tangents(
            seg, tn[:, 1 + js].reshape(-1), rotations[:, js].reshape(-1, 4), q1, q4,
            start=start, optimize=optimize, method=method, maxiter=maxiter, polish_tol=polish_tol,
        )
        rotation_tangents[:, js] = np.stack([alpha.reshape(K, nj, 4), beta.reshape(K, nj, 4)], axis=2)
    rest = None if motion.translations is None else np.asarray(motion.translations[0])
    sm = StaggeredMotion(
        skeleton=motion.skeleton,
        fps=motion.fps,
        times=times,
        refinements=refinements,
        root_values=position_values[:, 0],
        rotation_values=rotation_values,
        root_tangents=position_tangents[:, 0],
        rotation_tangents=rotation_tangents,
        sample_u=np.asarray(k0 + tn * (k1 - k0), dtype=float),
        root_displacement=np.zeros((t.size, 3)),
        rotation_displacement=np.zeros((t.size, J, 3)),
        active=act,
        priorities=priorities,  # type: ignore[arg-type]  # None means NaN
        name=motion.name,
        translation_joints=tj,
        translation_values=position_values[:, 1:],
        translation_tangents=position_tangents[:, 1:],
        translation_displacement=np.zeros((t.size, T, 3)),
        rest_translations=rest,
    )
    s_pos, s_rot = sm._spline_layers(k0, tn)
    d_pos = positions - s_pos
    d_rot = quat.log(quat.mul(quat.inv(s_rot), rotations))
    return _with(
        sm,
        root_displacement=d_pos[:, 0],
        rotation_displacement=d_rot,
        translation_displacement=d_pos[:, 1:],
        noise_u=None if noise is None else pose_u(times, t),
        rotation_noise=noise,
        rotation_sharp=sharp,
    )


def _with(sm: StaggeredMotion, **changes: Any) -> StaggeredMotion:
    return dataclasses.replace(sm, **changes)


def extract(
    motion: Motion,
    *,
    max_poses: int | None = None,
    fraction: float | None = None,
    interval: tuple[float, float] | None = None,
    contacts: Any = "auto",
    max_refinement: float = 0.25,
    start: Literal["tangent", "linear", "ease"] = "tangent",
    optimize: bool = True,
    method: Literal["gauss-newton", "nelder-mead"] = "gauss-newton",
    maxiter: int | None = None,
    filter_sigma: float | None = FILTER_SIGMA,
    constraints: bool = False,
    constraint_window: float = 0.1,
    analysis: Any = None,
    roles: Mapping[str, Any] | None = None,
    **analysis_options: Any,
) -> StaggeredMotion:
    """Staggered poses of a dense clip (section 4): locate, fit, measure.

    Parameters
    ----------
    motion : Motion
    max_poses, fraction, interval
        Culling of the candidate poses by count (an integer from 2 to the
        clip's frame count), fraction (in [0, 1]) or time interval
        (see :func:`mocaplab.staggered.features.cull_poses`); default keeps
        every candidate.
    contacts : Contacts, "auto" or None
        Global evidence (see :func:`mocaplab.staggered.features.analyze`).
    max_refinement : float
        Bound on timing refinements, seconds (0.25 in the paper).
    start, optimize, method, maxiter
        Rotation fitting options (see :func:`fit_rotation_tangents`): by
        default the tangent-space start polished by two Gauss-Newton steps.
    filter_sigma : float or None
        Filter the rotations before fitting and keep the filtered-out noise
        on the pose timing (section 6; Gaussian sigma in seconds, default
        0.03 s, at most :data:`~mocaplab.staggered.features.MAX_FILTER_SECONDS`,
        ``None`` turns it off): see :mod:`mocaplab.staggered.noise`.
        The clip is reproduced exactly either way.  The clip's frame rate
        must be at most :data:`~mocaplab.staggered.features.MAX_FPS`
        (1000 fps).
    constraints : bool
        Attach the contact constraint layer
        (:class:`~mocaplab.staggered.constraints.ConstraintLayer`: the feet of the
        analysis' contacts held by the shared goal solver
        :func:`mocaplab.goals.solve_goals`, blended over
        ``constraint_window`` seconds).  It is the identity on the unedited
        motion.
    constraint_window : float
        Seconds.
    analysis : PoseAnalysis, optional
        Reuse signals computed by :func:`~mocaplab.staggered.features.analyze`.
    roles : mapping, optional
        Joint-role overrides (:func:`mocaplab.roles.resolve_roles`) for the
        default contact joints and the constraint layer; they are kept on
        the result's skeleton (:meth:`~mocaplab.motion.Skeleton.with_roles`),
        so later edits (the succession's default joint, the pelvis) use them.
    **analysis_options
        Passed to :func:`~mocaplab.staggered.features.analyze`.

    Returns
    -------
    StaggeredMotion
        With ``.times`` (seconds), ``.refinements`` (K, V) and ``.priorities``;
        ``.evaluate()`` reproduces the clip (its translation channels too).

    Examples
    --------
    >>> import mocaplab as ml
    >>> clip = ml.cmu("16_15").resample(30)[:60]
    >>> sm = ml.staggered.extract(clip)
    >>> sm.n_poses, clip.n_frames
    (6, 60)
    """
    if not isinstance(motion, Motion):
        raise TypeError(f"Expected `motion` to be a Motion, got {type(motion).__name__}")
    if motion.n_frames < 2:
        raise ValueError(f"Expected a clip of at least 2 frames, got {motion.n_frames}")
    # the filters' work grows with the rate and the widths: bounded before anything is computed
    check_rates(motion.fps, filter_sigma=filter_sigma, constraint_window=constraint_window)
    max_refinement = real(max_refinement, "max_refinement", low=0.0, unit="seconds")
    if max_poses is not None:
        max_poses = integer(
            max_poses, "max_poses", low=2, high=motion.n_frames, why="the first and last frames, at most one per frame"
        )
    if fraction is not None:
        fraction = real(fraction, "fraction", low=0.0, high=1.0)
    if roles is not None:
        resolved = resolve_roles(motion, roles)
        motion = motion.replace(skeleton=motion.skeleton.with_roles(**dict(resolved)))
    analysis_given = analysis is not None
    if analysis is None:
        analysis = analyze(motion, contacts=contacts, **analysis_options)
    elif analysis.n_frames != motion.n_frames:
        raise ValueError(f"`analysis` covers {analysis.n_frames} frames, `motion` has {motion.n_frames}")
    frames = analysis.select(max_poses=max_poses, fraction=fraction, interval=interval)
    refinements = analysis.refinements(frames, max_refinement=max_refinement)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        sm = fit_representation(
            motion,
            frames / motion.fps,
            refinements,
            priorities=analysis.priorities_of(frames),
            start=start,
            optimize=optimize,
            method=method,
            maxiter=maxiter,
            filter_sigma=filter_sigma,
        )
    if constraints:
        if analysis.contacts is None:
            raise ValueError("`constraints=True` needs contacts: pass `contacts` (or keep 'auto')")
        layer = ConstraintLayer.from_contacts(motion, analysis.contacts, sm.times, window=constraint_window)
        detected_here = isinstance(contacts, str) and not analysis_given  # analyze has warned already
        if not layer.masks.any() and not detected_here:
            warn(
                f"The constraint layer of {motion.name or 'the clip'!r} holds nothing: no contact of "
                f"{list(layer.joints) or list(analysis.contacts.joints)} in the given contacts",
                NoContactsWarning,
            )
        sm = _with(sm, constraints=layer)
    return sm
