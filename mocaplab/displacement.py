"""Hierarchical displacement maps (Lee and Shin 1999).

A *displacement map* is a smooth correction laid over a motion: a root
translation ``d_root(i)`` (metres, world frame) and, per joint, a rotation
vector ``d_j(i)`` (radians).  Applying it gives

.. math::

    p'(i) = p(i) + d_{root}(i), \\qquad q'_j(i) = q_j(i) \\, \\exp(d_j(i))

The rotation displacement is **post-multiplied** (``q * exp(d)``): it is
expressed in the joint's own, already rotated frame, as in Lee and Shin's
``q \\oplus v = q exp(v)``.  :func:`displacement_between` gives the exact
inverse, ``d = log(q^-1 q')``.

The map is fitted to per-frame corrections (for example the per-frame IK
solutions of :mod:`mocaplab.goals`) coarse to fine: level 0 is a uniform
cubic B-spline with knots every ``spacing`` frames, least-squares fitted to
the corrections; each further level has its knot spacing divided by
``ratio`` and is fitted to what the previous levels left.  The sum of the
levels is the map.  Coarse levels carry the large, slow part of the
correction and finer levels add detail only where it is needed, so the
applied correction is smooth (a sum of C2 cubic splines) and does not
introduce the jitter of the raw per-frame solutions.

Per-frame weights make constrained frames count more in every fit (a frame
with weight 0 is ignored); a tiny ridge term pulls coefficients with no
data toward zero displacement.

Examples
--------
>>> import numpy as np
>>> d = np.sin(np.linspace(0, np.pi, 100))[:, None] * [0.0, 0.05, 0.0]
>>> dm = DisplacementMap.fit(root=d, spacing=25, levels=3)
>>> root, rot = dm.evaluate()
>>> bool(np.abs(root - d).max() < 1e-3), rot.shape
(True, (100, 0, 3))
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Sequence

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.interpolate import BSpline
from scipy.linalg import solveh_banded

from . import quat
from .motion import Motion

__all__ = [
    "uniform_knots",
    "fit_bspline",
    "fit_hierarchical",
    "displacement_between",
    "DisplacementMap",
    "blend_ramp",
    "displace",
    "rotation_displacement",
]

Array = NDArray[np.float64]
DEGREE = 3


def blend_ramp(u: ArrayLike) -> NDArray[np.float64]:
    """The one blend ramp of mocaplab: ``6u^5 - 15u^4 + 10u^3`` on [0, 1] (clipped outside).

    Its first and second derivatives vanish at both ends, so a constraint,
    a displacement or a fade blended in with it adds no velocity or
    acceleration jump (the ZMP of physical touch-up depends on
    accelerations).  Every blend in the package (constraint windows, foot
    plants, flight windows, IK fades, pose transitions) uses it.
    """
    x: NDArray[np.float64] = np.clip(np.asarray(u, dtype=float), 0.0, 1.0)
    return x * x * x * (x * (6.0 * x - 15.0) + 10.0)


def uniform_knots(n_frames: int, spacing: float) -> Array:
    """Knot vector of a uniform cubic B-spline covering frames ``0 .. n_frames-1``.

    Knots sit at ``spacing * k`` for ``k = -3 .. K + 3`` with
    ``K = ceil((n_frames - 1) / spacing)`` (at least 1), so the spline is
    defined (and uniform, not clamped) over the whole clip.  It has ``K + 3``
    coefficients.
    """
    if n_frames < 1:
        raise ValueError(f"Expected `n_frames` >= 1, got {n_frames}")
    if not (np.isfinite(spacing) and spacing > 0):
        raise ValueError(f"Expected `spacing` > 0 frames, got {spacing!r}")
    spans = max(1, math.ceil((n_frames - 1) / spacing - 1e-9))
    return spacing * np.arange(-DEGREE, spans + DEGREE + 1, dtype=float)


def fit_bspline(
    values: ArrayLike,
    *,
    spacing: float,
    weights: ArrayLike | None = None,
    smoothing: float = 1e-10,
) -> BSpline:
    """Weighted least-squares uniform cubic B-spline through per-frame values.

    Parameters
    ----------
    values : array_like, shape (F,) or (F, D)
        One value (or vector) per frame, sampled at frames ``0 .. F-1``.
    spacing : float
        Knot spacing in frames.
    weights : array_like, shape (F,), optional
        Non-negative weight of each frame (default 1).
    smoothing : float
        Ridge term, relative to the mean diagonal of the normal matrix; it
        keeps the fit defined where weights vanish (coefficients there go to
        zero) and is small enough not to bias well-sampled spans.

    Returns
    -------
    scipy.interpolate.BSpline
        ``spline(frames)`` evaluates it; vector-valued when ``values`` is 2-D.

    Notes
    -----
    Solves ``(B^T W B + lambda I) c = B^T W y`` with the sparse design matrix
    ``B`` of :meth:`scipy.interpolate.BSpline.design_matrix`; the normal
    matrix is banded (bandwidth 3) and solved by
    :func:`scipy.linalg.solveh_banded`.
    """
    y = np.asarray(values, dtype=float)
    if y.ndim not in (1, 2) or y.shape[0] < 1:
        raise ValueError(f"Expected `values` of shape (F,) or (F, D), got {y.shape}")
    n_frames = y.shape[0]
    w = np.ones(n_frames) if weights is None else np.asarray(weights, dtype=float)
    if w.shape != (n_frames,) or np.any(w < 0) or not np.all(np.isfinite(w)):
        raise ValueError(f"Expected non-negative finite `weights` of shape ({n_frames},), got shape {w.shape}")
    if smoothing < 0:
        raise ValueError(f"Expected `smoothing` >= 0, got {smoothing}")
    t = uniform_knots(n_frames, spacing)
    x = np.arange(n_frames, dtype=float)
    basis = BSpline.design_matrix(x, t, DEGREE).tocsr()
    n_coef = basis.shape[1]
    normal = (basis.T.multiply(w) @ basis).tocsr()
    diag = normal.diagonal()
    lam = smoothing * max(float(diag.mean()), 1e-12)
    ab = np.zeros((DEGREE + 1, n_coef))
    for k in range(DEGREE + 1):
        ab[DEGREE - k, k:] = normal.diagonal(k)
    ab[DEGREE] += lam
    rhs = basis.T @ (w[:, None] * y.reshape(n_frames, -1))
    coef = solveh_banded(ab, rhs, lower=False, check_finite=False)
    coef = coef.reshape((n_coef,) + y.shape[1:])
    return BSpline(t, coef, DEGREE, extrapolate=True)


def fit_hierarchical(
    values: ArrayLike,
    *,
    spacing: float,
    levels: int = 3,
    ratio: float = 2.0,
    weights: ArrayLike | None = None,
    tolerance: float | None = None,
    smoothing: float = 1e-10,
) -> list[BSpline]:
    """Coarse-to-fine B-spline hierarchy (Lee and Shin 1999).

    Level ``l`` has knot spacing ``max(spacing / ratio**l, 1)`` frames and is
    fitted to the residual left by levels ``0 .. l-1``.  Fitting stops early
    when the largest residual on frames of positive weight is at most
    ``tolerance``.

    Parameters
    ----------
    values : array_like, shape (F,) or (F, D)
    spacing : float
        Knot spacing of the coarsest level, in frames.
    levels : int
        Maximum number of levels (>= 1).
    ratio : float
        Spacing ratio between consecutive levels (> 1).
    weights, smoothing
        See :func:`fit_bspline`.
    tolerance : float, optional
        Early-stopping threshold on the residual (units of ``values``).

    Returns
    -------
    list of BSpline
        The levels, coarsest first; their sum approximates ``values``.
    """
    y = np.asarray(values, dtype=float)
    if int(levels) != levels or levels < 1:
        raise ValueError(f"Expected `levels` to be an integer >= 1, got {levels!r}")
    if not ratio > 1:
        raise ValueError(f"Expected `ratio` > 1, got {ratio!r}")
    if y.ndim not in (1, 2) or y.shape[0] < 1:
        raise ValueError(f"Expected `values` of shape (F,) or (F, D), got {y.shape}")
    x = np.arange(y.shape[0], dtype=float)
    w = None if weights is None else np.asarray(weights, dtype=float)
    residual = y
    out: list[BSpline] = []
    for level in range(int(levels)):
        h = max(spacing / ratio**level, 1.0)
        spline = fit_bspline(residual, spacing=h, weights=w, smoothing=smoothing)
        out.append(spline)
        residual = residual - spline(x)
        if tolerance is not None:
            mask = slice(None) if w is None else w > 0
            if residual[mask].size == 0 or np.abs(residual[mask]).max() <= tolerance:
                break
    return out


def displace(q: ArrayLike, d: ArrayLike) -> Array:
    """Apply rotation displacements: ``q * exp(d)``, shapes (..., 4) and (..., 3).

    The one displacement convention of mocaplab, in code: ``d`` is a rotation
    vector in the joint's own (already rotated) frame.  Inverse of
    :func:`rotation_displacement`.
    """
    return quat.normalize(quat.mul(np.asarray(q, dtype=float), quat.exp(np.asarray(d, dtype=float))))


def rotation_displacement(q: ArrayLike, q2: ArrayLike) -> Array:
    """The displacement ``d = log(q^-1 q2)`` taking ``q`` to ``q2`` (``displace(q, d) == q2``), shape (..., 3)."""
    return quat.log(quat.mul(quat.inv(np.asarray(q, dtype=float)), np.asarray(q2, dtype=float)))


def displacement_between(before: Motion, after: Motion) -> tuple[Array, Array]:
    """Exact per-frame displacement taking ``before`` to ``after``.

    Returns
    -------
    root : ndarray, shape (F, 3)
        ``after.root_positions - before.root_positions``: the world
        displacement of the joint that carries the body (joint 0, or the
        pelvis below a static reference root, :attr:`Motion.carrier_joint`).
    rotations : ndarray, shape (F, J, 3)
        ``log(q_before^-1 q_after)`` per joint (the post-multiplied
        convention of :class:`DisplacementMap`).
    """
    for name, m in (("before", before), ("after", after)):
        if not isinstance(m, Motion):
            raise TypeError(f"Expected `{name}` to be a Motion, got {type(m).__name__}")
    if before.rotations.shape != after.rotations.shape:
        raise ValueError(
            f"Expected motions of equal shape, got before {before.rotations.shape} and after {after.rotations.shape}"
        )
    return _carried(after) - _carried(before), rotation_displacement(before.rotations, after.rotations)


def _carried(m: Motion) -> Array:
    """World positions of the joint that carries the body (:attr:`Motion.carrier_joint`), shape (F, 3)."""
    j = m.carrier_joint
    return np.asarray(m.root_positions) if j == 0 else np.asarray(m.global_positions()[:, j])


@dataclasses.dataclass(frozen=True, eq=False)
class DisplacementMap:
    """A smooth root-translation and joint-rotation correction over a clip.

    Build it with :meth:`fit` (from per-frame corrections) or
    :meth:`between` (from two motions); do not fill the fields by hand.

    Attributes
    ----------
    n_frames : int
    n_joints : int
    joints : tuple of int
        Joints that carry a rotation displacement (others stay zero).
    levels : tuple of BSpline
        Coarse-to-fine levels; each maps a frame to a vector of
        ``3 + 3 * len(joints)`` values (root translation, then the rotation
        vectors of ``joints`` in order).
    """

    n_frames: int
    n_joints: int
    joints: tuple[int, ...]
    levels: tuple[BSpline, ...]

    @classmethod
    def fit(
        cls,
        root: ArrayLike | None = None,
        rotations: ArrayLike | None = None,
        *,
        weights: ArrayLike | None = None,
        spacing: float = 16.0,
        levels: int = 3,
        ratio: float = 2.0,
        tolerance: float | None = None,
        joints: Sequence[int] | None = None,
        smoothing: float = 1e-10,
    ) -> DisplacementMap:
        """Fit a hierarchical map to per-frame corrections.

        Parameters
        ----------
        root : array_like, shape (F, 3), optional
            Root translation corrections, metres (default zero).
        rotations : array_like, shape (F, J, 3), optional
            Joint rotation corrections as rotation vectors, radians, in the
            ``q * exp(d)`` convention (default zero).
        weights : array_like, shape (F,), optional
            Per-frame weights; give constrained frames a large weight so they
            are hit closely.
        spacing : float
            Knot spacing of the coarsest level, frames.
        levels, ratio, tolerance, smoothing
            See :func:`fit_hierarchical`.
        joints : sequence of int, optional
            Only these joints get a rotation displacement (default: every
            joint whose correction is not identically zero).

        Returns
        -------
        DisplacementMap
        """
        if root is None and rotations is None:
            raise ValueError("Expected `root` and/or `rotations` corrections, got neither")
        rot = None if rotations is None else np.asarray(rotations, dtype=float)
        if rot is not None and (rot.ndim != 3 or rot.shape[2] != 3):
            raise ValueError(f"Expected `rotations` of shape (F, J, 3), got {rot.shape}")
        n_frames = rot.shape[0] if rot is not None else np.asarray(root).shape[0]
        n_joints = 0 if rot is None else rot.shape[1]
        r = np.zeros((n_frames, 3)) if root is None else np.asarray(root, dtype=float)
        if r.shape != (n_frames, 3):
            raise ValueError(f"Expected `root` of shape ({n_frames}, 3), got {r.shape}")
        if joints is None:
            sel = () if rot is None else tuple(int(j) for j in np.flatnonzero(np.any(rot != 0.0, axis=(0, 2))))
        else:
            sel = tuple(int(j) for j in joints)
            if any(not 0 <= j < n_joints for j in sel):
                raise ValueError(f"Expected `joints` in [0, {n_joints}), got {list(sel)}")
        cols = [r] if rot is None else [r, rot[:, list(sel)].reshape(n_frames, -1)]
        values = np.concatenate(cols, axis=1)
        fitted = fit_hierarchical(
            values, spacing=spacing, levels=levels, ratio=ratio, weights=weights,
            tolerance=tolerance, smoothing=smoothing,
        )
        return cls(n_frames=int(n_frames), n_joints=int(n_joints), joints=sel, levels=tuple(fitted))

    @classmethod
    def between(cls, before: Motion, after: Motion, **options: object) -> DisplacementMap:
        """Fit the map taking ``before`` toward ``after`` (options as in :meth:`fit`)."""
        root, rot = displacement_between(before, after)
        return cls.fit(root, rot, **options)  # type: ignore[arg-type]

    @property
    def spacings(self) -> tuple[float, ...]:
        """Knot spacing of each level, frames."""
        return tuple(float(s.t[1] - s.t[0]) for s in self.levels)

    def evaluate(self, frames: ArrayLike | None = None, *, upto: int | None = None) -> tuple[Array, Array]:
        """The correction at ``frames`` (default every frame), summed over levels.

        Parameters
        ----------
        frames : array_like, shape (n,), optional
            Frame numbers (fractional allowed).
        upto : int, optional
            Sum only the first ``upto`` levels (to show the hierarchy).

        Returns
        -------
        root : ndarray, shape (n, 3)
        rotations : ndarray, shape (n, J, 3)
            Zero for joints outside :attr:`joints`.
        """
        x = np.arange(self.n_frames, dtype=float) if frames is None else np.asarray(frames, dtype=float).reshape(-1)
        use = self.levels if upto is None else self.levels[: max(0, int(upto))]
        total = np.zeros((x.size, 3 + 3 * len(self.joints)))
        for spline in use:
            total += spline(x)
        rot = np.zeros((x.size, self.n_joints, 3))
        if self.joints:
            rot[:, list(self.joints)] = total[:, 3:].reshape(x.size, len(self.joints), 3)
        return total[:, :3], rot

    def apply(self, motion: Motion, *, scale: float = 1.0) -> Motion:
        """A new Motion with the correction applied (``q * exp(scale * d)``, ``p + scale * d``)."""
        if not isinstance(motion, Motion):
            raise TypeError(f"Expected `motion` to be a Motion, got {type(motion).__name__}")
        if motion.n_frames != self.n_frames or (self.joints and motion.n_joints != self.n_joints):
            raise ValueError(
                f"Expected a motion of {self.n_frames} frames and {self.n_joints} joints, "
                f"got {motion.n_frames} frames and {motion.n_joints} joints"
            )
        root, rot = self.evaluate()
        new_rot = np.array(motion.rotations, copy=True)
        if self.joints:
            js = list(self.joints)
            new_rot[:, js] = displace(motion.rotations[:, js], scale * rot[:, js])
        # the translation moves the whole body in the world (at the pelvis below a static root)
        return motion.replace(rotations=new_rot).transformed(translation=scale * root)
