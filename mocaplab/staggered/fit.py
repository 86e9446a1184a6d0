"""Fitting splines and displacement maps to dense motion (section 4.1.1, Appendix A).

Given pose times and refinements, every variable's knots are its values at
its refined knot times.  Between two knots:

* **Translations:** the two inner Bezier control points minimise the squared
  distance to the samples, a linear least-squares problem solved in closed
  form for all segments at once (:func:`fit_translation_tangents`).
* **Rotations (Appendix A):** the tangent orientations ``q2, q3`` of the
  recursive-slerp cubic minimise ``f = w_f f_f + w_c f_c`` with
  ``f_f = mean_k arccos(q_k . s(t_k))^2`` over the interior samples and the
  unit-length penalty ``f_c = | |q2|^2 + |q3|^2 - 2 |``, ``w_f = 1000 w_c``,
  by Nelder-Mead (``scipy.optimize.minimize``), then renormalised
  (:func:`fit_rotation_tangents`).
* **Displacements:** ``d = v (-) s`` on every sample (:func:`fit_representation`).

Because the displacement maps absorb whatever the splines miss, the fit
quality never affects reconstruction, only how edits look; this is what
makes the speed options below safe.

Speed choices (documented approximations)
-----------------------------------------
Nelder-Mead over every segment of every joint is the cost centre.  By
default (``start="tangent"``):

* the search starts from a *tangent-space least-squares* solution: the
  samples are mapped to rotation vectors relative to the segment's first
  knot, a Euclidean cubic Bezier is fitted there by the same linear least
  squares as translations, and its control points are mapped back with
  ``exp``.  For the small arcs between poses this is already close to the
  optimum (the spherical and Euclidean constructions agree to first order);
* Nelder-Mead then runs only on segments whose starting RMS angular error
  exceeds ``polish_tol`` (default 2 degrees), from a small simplex around
  the start, with at most ``maxiter`` iterations (default 30);
* the objective is vectorised over a segment's samples, subsampled to at most
  ``max_samples`` (default 16) evenly spaced interior samples;
* a Nelder-Mead result is kept only if, renormalised, it fits *all* the
  segment's samples better than the start.

``start="linear"`` follows the paper literally: every segment starts from
the linear (slerp) spline with scipy's default simplex and runs Nelder-Mead
with no skipping (``maxiter`` still bounds it).  Nelder-Mead uses scipy's
``adaptive=True`` coefficients (Gao and Han), which converge in 8 dimensions
where the classic ones stall.

Measured on CMU clips (16_15, 16_05), Nelder-Mead started from the tangent
solution lowers the Appendix A objective by less than 1e-4 relative: the
tangent start is already at the optimum to that precision, and segments with
a large residual are those a cubic cannot follow (their detail goes to the
displacement map).  From the linear start, ``maxiter=200`` costs about 150
times more CPU on 16_15 (40 s against 0.27 s for its 930 segments) and ends
with a larger mean RMS error (0.46 against 0.41 degrees).
"""

from __future__ import annotations

import warnings
from collections.abc import Mapping
from typing import Any, Literal

import numpy as np
from numpy.typing import NDArray
from scipy.optimize import minimize

from .. import quat
from ..motion import Motion
from ..roles import resolve_roles
from .representation import StaggeredMotion, locate, next_active, quat_bezier, translation_joints

__all__ = [
    "W_F",
    "W_C",
    "fit_translation_tangents",
    "fit_rotation_tangents",
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


def fit_rotation_tangents(
    seg: NDArray[np.int64],
    tn: Array,
    q: Array,
    q1: Array,
    q4: Array,
    *,
    start: Literal["tangent", "linear"] = "tangent",
    optimize: bool = True,
    maxiter: int = 30,
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
    start : {"tangent", "linear"}
        Starting solution: tangent-space least squares (default, see the
        module notes) or the linear slerp spline of the paper.
    optimize : bool
        Run Nelder-Mead (False keeps the starting solution).
    maxiter : int
        Nelder-Mead iteration bound per segment.
    polish_tol : float
        With ``start="tangent"``, only segments whose starting RMS rotation
        error (radians) exceeds this are optimised (default 2 degrees).
    max_samples : int
        Interior samples used by the objective (evenly subsampled).
    w_f, w_c : float
        Appendix A weights.

    Returns
    -------
    alpha, beta : ndarray, shape (S, 4)
        Unit quaternions with ``q2 = q1 (+) alpha`` and ``q3 = q4 (+) beta``.
    info : dict
        ``"optimized"`` (segments run through Nelder-Mead), ``"nfev"`` (total
        objective evaluations), ``"start_error"`` and ``"error"`` (RMS
        rotation angle per segment over all its interior samples, radians).
    """
    if start not in ("tangent", "linear"):
        raise ValueError(f"Expected `start` in ('tangent', 'linear'), got {start!r}")
    S = q1.shape[0]
    if start == "tangent":
        rel = quat.log(quat.mul(quat.inv(q1[seg]), q))  # (N, 3)
        end = quat.log(quat.mul(quat.inv(q1), q4))  # (S, 3)
        a, b = fit_translation_tangents(seg, tn, rel, np.zeros_like(end), end)
        q2 = quat.mul(q1, quat.exp(a))
        q3 = quat.mul(q1, quat.exp(end + b))
    else:
        q2 = quat.slerp(q1, q4, np.full(S, 1.0 / 3.0))
        q3 = quat.slerp(q1, q4, np.full(S, 2.0 / 3.0))
    # keep every control orientation in the hemisphere of the first knot
    q2 = np.where(np.sum(q2 * q1, axis=-1, keepdims=True) < 0, -q2, q2)
    q3 = np.where(np.sum(q3 * q1, axis=-1, keepdims=True) < 0, -q3, q3)
    err0 = _segment_rms(seg, tn, q, q1, q2, q3, q4)
    inner = (tn > 0.0) & (tn < 1.0)
    counts = np.bincount(seg[inner], minlength=S)
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
    alpha = quat.mul(quat.inv(q1), quat.normalize(q2))
    beta = quat.mul(quat.inv(q4), quat.normalize(q3))
    return alpha, beta, {"optimized": int(todo.size), "nfev": nfev, "start_error": err0, "error": err}


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
    start: Literal["tangent", "linear"] = "tangent",
    optimize: bool = True,
    maxiter: int = 30,
    polish_tol: float = np.deg2rad(2.0),
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
    start, optimize, maxiter, polish_tol
        Rotation fitting options, see :func:`fit_rotation_tangents`.

    Returns
    -------
    StaggeredMotion
        Evaluating it reproduces ``motion`` on every frame (to rounding),
        translations included.
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
    rotations = quat.unroll(motion.rotations, axis=0)
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
    # rotations: one segment per (start pose, joint)
    j = np.arange(J)
    seg = (k0[:, 1 : J + 1] * J + j).reshape(-1)
    q1 = rotation_values.reshape(K * J, 4)
    q4 = rotation_values[nxt_safe[:, 1 : J + 1], j].reshape(K * J, 4)
    alpha, beta, _ = fit_rotation_tangents(
        seg, tn[:, 1 : J + 1].reshape(-1), rotations.reshape(-1, 4), q1, q4,
        start=start, optimize=optimize, maxiter=maxiter, polish_tol=polish_tol,
    )
    rotation_tangents = np.stack([alpha.reshape(K, J, 4), beta.reshape(K, J, 4)], axis=2)
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
        sm, root_displacement=d_pos[:, 0], rotation_displacement=d_rot, translation_displacement=d_pos[:, 1:]
    )


def _with(sm: StaggeredMotion, **changes: Any) -> StaggeredMotion:
    import dataclasses

    return dataclasses.replace(sm, **changes)


def extract(
    motion: Motion,
    *,
    max_poses: int | None = None,
    fraction: float | None = None,
    interval: tuple[float, float] | None = None,
    contacts: Any = "auto",
    max_refinement: float = 0.25,
    start: Literal["tangent", "linear"] = "tangent",
    optimize: bool = True,
    maxiter: int = 30,
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
        Culling of the candidate poses by count, fraction or time interval
        (see :func:`mocaplab.staggered.features.cull_poses`); default keeps
        every candidate.
    contacts : Contacts, "auto" or None
        Global evidence (see :func:`mocaplab.staggered.features.analyze`).
    max_refinement : float
        Bound on timing refinements, seconds (0.25 in the paper).
    start, optimize, maxiter
        Rotation fitting options (see :func:`fit_rotation_tangents`).
    constraints : bool
        Attach the contact constraint layer
        (:class:`~mocaplab.staggered.edit.ConstraintLayer`: the feet of the
        analysis' contacts held by the shared goal solver
        :func:`mocaplab.refinement.solve_goals`, blended over
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
    >>> from mocaplab import cmu                              # doctest: +SKIP
    >>> sm = extract(cmu("16_15"))                            # doctest: +SKIP
    >>> sm.n_poses < cmu("16_15").n_frames                    # doctest: +SKIP
    True
    """
    from .features import analyze

    if not isinstance(motion, Motion):
        raise TypeError(f"Expected `motion` to be a Motion, got {type(motion).__name__}")
    if motion.n_frames < 2:
        raise ValueError(f"Expected a clip of at least 2 frames, got {motion.n_frames}")
    if not 0.0 <= max_refinement:
        raise ValueError(f"Expected `max_refinement` >= 0 seconds, got {max_refinement!r}")
    if roles is not None:
        resolved = resolve_roles(motion, roles)
        motion = motion.replace(skeleton=motion.skeleton.with_roles(**dict(resolved)))
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
            maxiter=maxiter,
        )
    if constraints:
        from .edit import ConstraintLayer

        if analysis.contacts is None:
            raise ValueError("`constraints=True` needs contacts: pass `contacts` (or keep 'auto')")
        layer = ConstraintLayer.from_contacts(motion, analysis.contacts, sm.times, window=constraint_window)
        sm = _with(sm, constraints=layer)
    return sm
