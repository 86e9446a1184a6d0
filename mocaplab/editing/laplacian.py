"""Laplacian path editing in space, the equations (Kim et al. 2009, section 4.1).

Unknowns: the ground positions of every frame of every character, stacked
in one vector ``p`` (character after character, frame after frame, ``x``
then ``z``), so one sparse system edits the whole scene at once.  This
module writes that system's matrices and constraint rows;
:mod:`~mocaplab.editing.spatial` factorises and solves it (with the
least-squares layer of :mod:`~mocaplab.editing.lsq`), and
:mod:`~mocaplab.editing.flips` turns the result into headings (section 4.2).

Phase 1, shape preservation (equations 3 to 6)
    minimise ``|A p|^2 + |B p - b|^2_W`` subject to ``H p = h``, where
    ``A p = 0`` keeps each interior frame's Laplacian coordinates (eq. 3,
    :func:`shape_matrix`), ``B`` holds the soft constraints (rows scaled by
    the square root of their weights) and ``H`` the hard ones
    (:func:`spatial_rows`).  The KKT system (eq. 6) is factorised with
    SuperLU (:func:`scipy.sparse.linalg.splu`).
Phase 2, scale compensation (equation 7)
    ``v_i - v_{i-1} = vbar_i - vbar_{i-1}`` with ``vbar_i`` the phase-1 segment
    ``pbar_{i+1} - pbar_i`` rescaled to its undeformed length: the matrix is
    the fixed second-difference operator (:func:`scale_matrix`); only the
    right-hand side depends on phase 1, so both phases are factorised once
    per constraint *structure*.
Stationary sub-paths (section 4.2)
    the equation-3 rows of their interior frames become hard constraints in
    phase 1 (the segment moves as a similarity, :func:`rigid_rows`); in
    phase 2 each of its steps is held by a hard row ``p_{i+1} - p_i =
    vbar_i`` (the phase-1 step rescaled to its undeformed length), so the
    segment moves rigidly and a standing character does not skate.  Only
    right-hand sides depend on phase 1, so the matrices stay fixed.

Relative constraints in metres (our choice; see
:mod:`~mocaplab.editing.constraints`)
    Equations 1 and 2 are linear because they measure the offset in units of
    the other character's tangent ``T = p[j+1] - p[j-1]``: the metric offset
    would grow and shrink with ``|T| / L`` (``L`` the undeformed length).  The
    metric target ``C u`` (``u = T / |T|``, ``C = c_x + c_y R``) is nonlinear
    in ``T``; a soft relative's rows are written linearised about the
    undeformed path (Newton rows ``lhs - C (I - u0 u0^T) T / L = r``, ``u0``
    the undeformed direction), a hard one's keep equations 1 and 2 (``lhs -
    C T / L = r``), so the matrix, and its factorisation, depends only on the
    constraint structure.  Their right-hand sides are then corrected on the
    solution: ``r = C u - M T`` (``M`` the rows' matrix) makes them read
    ``lhs = c_x u + c_y R u``, metres along the edited tangent.  (The
    iteration meets the metric targets either way; the matrix decides where
    along them a hard relative's force acts: the Newton rows about the
    straight path made lesson 05's relay, curled into a spiral, shorten its
    first walker by 11 % instead of 8 %.)  ``r`` depends on the
    solution, so the solve is repeated (a fixed point, Anderson-accelerated,
    :meth:`SpatialSolver.solve <mocaplab.editing.spatial.SpatialSolver.solve>`)
    until ``r`` changes by less than ``relative_tolerance`` (1 mm).  Rows
    linearised about the undeformed path already carry the right first-order
    response (a stretch along the tangent leaves the offset alone, a turn
    turns it), so a drag that moves tied characters together needs one or
    two solves; the rows of equations 1 and 2 respond ``|c| / L`` times too
    strongly to a stretch (about 9 for 0.8 m beside a walk at 30 fps) and
    needed 10 to 20 solves in a formation.  The iteration keeps its best
    iterate and stops when it stops improving or diverges (a soft
    constraint far from anything reachable, or one that fights hard
    constraints:
    :meth:`~mocaplab.editing.spatial.SpatialSolver.soft_conflicts`); a hard
    relative still missed by 10 cm raises, naming the hard constraints on
    its unknowns.  An interactive drag starts from the previous update's
    corrections.  The discrete evaluation writes the rows linearised about
    the current solution instead (``spatial_rows(..., linearize_at=...)``).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence
from typing import Any

import numpy as np
import scipy.sparse as sp
from numpy.typing import NDArray

from .constraints import PinDirection, PinPosition, Relative
from .lsq import Layout, Rows
from .paths import MotionPath, laplacian_coordinates, rot90

__all__ = [
    "shape_matrix",
    "scale_matrix",
    "rigid_rows",
    "TangentRows",
    "spatial_rows",
    "MetricPair",
    "MetricTargets",
    "metric_targets",
    "metric_linearization",
]

Array = NDArray[np.float64]


# --------------------------------------------------------------- matrices
def shape_matrix(paths: Sequence[MotionPath], layout: Layout) -> sp.csr_matrix:
    """Block-diagonal ``A`` of equation 4: two rows (x, z) per interior frame."""
    g = layout.interior()
    coords = np.concatenate([laplacian_coordinates(p.positions)[1:-1] for p in paths])
    x, y = coords[:, 0], coords[:, 1]
    r = np.arange(len(g))
    one = np.ones(len(g))
    # x row: p_i.x - p_{i-1}.x - x (dx) - y (dz),  d = p_{i+1} - p_{i-1}
    # z row: p_i.z - p_{i-1}.z - x (dz) + y (dx)
    rx, rz = 2 * r, 2 * r + 1
    X = lambda f: 2 * f  # noqa: E731
    Z = lambda f: 2 * f + 1  # noqa: E731
    rows = [rx, rx, rx, rx, rx, rx, rz, rz, rz, rz, rz, rz]
    cols = [
        X(g),
        X(g - 1),
        X(g + 1),
        X(g - 1),
        Z(g + 1),
        Z(g - 1),
        Z(g),
        Z(g - 1),
        Z(g + 1),
        Z(g - 1),
        X(g + 1),
        X(g - 1),
    ]
    vals = [one, -one, -x, x, -y, y, one, -one, -x, x, y, -y]
    m = sp.csr_matrix(
        (np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))), shape=(2 * len(g), 2 * layout.total)
    )
    m.sum_duplicates()
    return m


def scale_matrix(layout: Layout) -> sp.csr_matrix:
    """Block-diagonal second-difference matrix of equation 7 (two rows per interior frame)."""
    g = layout.interior()
    r = np.arange(len(g))
    rows, cols, vals = [], [], []
    for c in (0, 1):
        for df, v in ((-1, 1.0), (0, -2.0), (1, 1.0)):
            rows.append(2 * r + c)
            cols.append(2 * (g + df) + c)
            vals.append(np.full(len(g), v))
    return sp.csr_matrix(
        (np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))), shape=(2 * len(g), 2 * layout.total)
    )


def rigid_rows(
    A: sp.csr_matrix, layout: Layout, segments: Sequence[Sequence[tuple[int, int]]]
) -> tuple[sp.csr_matrix, list[tuple[str, NDArray[np.int64]]]]:
    """Rows of ``A`` for the interior frames of stationary segments, as hard rows.

    Returns the row block and, for error messages, one ``(label, row indices)``
    group per segment.
    """
    g_int = layout.interior()
    pos = np.full(layout.total, -1, dtype=np.int64)
    pos[g_int] = np.arange(len(g_int))
    picks: list[NDArray[np.int64]] = []
    groups: list[tuple[str, NDArray[np.int64]]] = []
    n = 0
    for k, segs in enumerate(segments):
        for a, b in segs:
            frames = layout.frame(k, 0) + np.arange(a + 1, b - 1)
            r = pos[frames]
            r = r[r >= 0]
            if len(r) == 0:
                continue
            rr = np.stack([2 * r, 2 * r + 1], axis=1).reshape(-1)
            picks.append(rr)
            groups.append((f"rigid stationary segment of character {k}, frames {a}-{b - 1}", np.arange(n, n + len(rr))))
            n += len(rr)
    if not picks:
        return sp.csr_matrix((0, A.shape[1])), []
    return A[np.concatenate(picks)].tocsr(), groups


@dataclasses.dataclass(frozen=True)
class MetricPair:
    """Two rows (x, z) of a :class:`~mocaplab.editing.constraints.Relative` whose target is metric.

    The rows read ``lhs(p) - M T = r`` with ``T`` the other character's
    tangent (a fixed linear function of ``p``) and ``M`` the metric target
    ``c_x u + c_y R u`` (``u = T / |T|``) differentiated about a reference
    tangent (the undeformed one unless ``linearize_at`` is given).  The
    right-hand side correction is ``(c_x + c_y R) u - M T`` measured on the
    solution.

    Attributes
    ----------
    row : int
        Index of the x row within its :class:`Rows` (the z row follows).
    coef : (float, float)
        ``(c_x, c_y)``: the offset in metres (position rows, eq. 1) or the
        direction times the character's own undeformed tangent length
        (direction rows, eq. 2).
    cols : ndarray of int
        Unknowns (x coordinates; z is ``+ 1``) of the tangent ``T``.
    weights : ndarray
        Their weights in ``T``.
    length : float
        ``L``, the undeformed ``|T|``.
    linear : ndarray, shape (2, 2)
        ``M``: the rows read ``lhs - M T``.
    direction : bool
        True for the direction rows of equation 2.
    """

    row: int
    coef: tuple[float, float]
    cols: NDArray[np.int64]
    weights: Array
    length: float
    linear: Array
    direction: bool = False


# ------------------------------------------------------------ constraints
class TangentRows:
    """Cached rows of each path's tangent operator (:meth:`~mocaplab.editing.paths.MotionPath.tangent_operator`).

    ``row(k, i)`` gives the frames of character ``k`` and their weights in
    its tangent at frame ``i`` (the same for ``x`` and ``z``).  One instance
    per :class:`~mocaplab.editing.spatial.SpatialSolver`, shared by every
    :func:`spatial_rows` call.
    """

    def __init__(self, paths: Sequence[MotionPath]) -> None:
        self.paths = paths
        self._ops: dict[int, sp.csr_matrix] = {}

    def row(self, k: int, i: int) -> tuple[NDArray[np.int64], Array]:
        if k not in self._ops:
            self._ops[k] = self.paths[k].tangent_operator()
        op = self._ops[k]
        s, e = op.indptr[i], op.indptr[i + 1]
        return op.indices[s:e].astype(np.int64), op.data[s:e].astype(float)


def metric_linearization(coef: tuple[float, float], T: Array) -> tuple[Array, Array]:
    """``(M, r)`` with ``lhs - M T' = r`` the metric target ``C u(T')`` linearised about ``T`` (Newton)."""
    L = float(np.linalg.norm(T))
    u = T / L
    C = np.array([[coef[0], coef[1]], [-coef[1], coef[0]]])
    return C @ (np.eye(2) - np.outer(u, u)) / L, C @ u


def _relative_coupling(coef: tuple[float, float], t: Array) -> Array:
    """2 x 2 matrix ``M = (c_x + c_y R) / |t|`` of the relative rows ``lhs - M T`` (equations 1 and 2).

    ``T`` is the other character's tangent (unknown), ``t`` its undeformed value.
    """
    return np.array([[coef[0], coef[1]], [-coef[1], coef[0]]]) / float(np.linalg.norm(t))


def spatial_rows(
    c: Any,
    paths: Sequence[MotionPath],
    layout: Layout,
    tangents: TangentRows,
    step: int,
    *,
    linearize_at: Array | None = None,
) -> Rows:
    """The linear rows (unweighted) of one spatial constraint.

    ``linearize_at`` (stacked positions, shape (2 total,)): relative
    constraints are written as their metric form linearised about these
    positions instead of equations 1 and 2 (``lhs = C u`` with ``u = T / |T|``
    becomes ``lhs - C (I - u u^T) T / |T| = C u`` at the given ``T``: the
    offset keeps its metres when the tangent's length changes, and turns with
    its direction).  The discrete evaluation scores candidates this way
    about the current solution (:mod:`mocaplab.editing.discrete.evaluation`).
    """
    off = layout.offsets
    cols: list[NDArray[np.int64]] = []
    vals: list[Array] = []
    rhs: list[float] = []
    metric: list[MetricPair] = []

    def var(k: int, i: Any, coord: int) -> Any:
        return 2 * (off[k] + np.asarray(i)) + coord

    for sample in c.samples(step):
        if isinstance(c, PinPosition):
            (i,) = sample
            for coord in (0, 1):
                cols.append(np.array([var(c.character, i, coord)]))
                vals.append(np.array([1.0]))
                rhs.append(c.position[coord])
        elif isinstance(c, PinDirection):
            (i,) = sample
            fr, w = tangents.row(c.character, i)
            L = float(np.linalg.norm(paths[c.character].tangents[i]))
            for coord in (0, 1):
                cols.append(var(c.character, fr, coord))
                vals.append(w)
                rhs.append(L * c.direction[coord])
        elif isinstance(c, Relative):
            i, j = sample
            a, b = c.character, c.other
            fb, wb = tangents.row(b, j)
            tb = paths[b].tangents[j]
            Lb = float(np.linalg.norm(tb))
            tx, tz = var(b, fb, 0), var(b, fb, 1)
            # Newton rows about the given positions, else soft ones about the undeformed path (module docstring)
            T_at: NDArray[Any] | None
            if linearize_at is not None:
                T_at = np.array([wb @ linearize_at[tx], wb @ linearize_at[tz]])
            else:
                T_at = None if c.hard else tb
            coefs = [(c.offset, False)]
            if c.direction is not None:
                La = float(np.linalg.norm(paths[a].tangents[i]))
                coefs.append(((c.direction[0] * La, c.direction[1] * La), True))
            for coef, is_dir in coefs:
                r: Any
                if T_at is None or np.linalg.norm(T_at) < 1e-12:
                    M = _relative_coupling(coef, tb)  # eq. 1 (2): M = (cx + cy R) / L, right-hand side 0
                    r = (0.0, 0.0)
                else:
                    M, r = metric_linearization(coef, T_at)
                metric.append(MetricPair(len(cols), coef, np.asarray(tx, dtype=np.int64), wb, Lb, M, is_dir))
                if is_dir:  # T_a - M T_b = r
                    fa, wa = tangents.row(a, i)
                    left = [(var(a, fa, 0), wa), (var(a, fa, 1), wa)]
                else:  # p_a - p_b - M T_b = r
                    left = [
                        (np.array([var(a, i, 0), var(b, j, 0)]), np.array([1.0, -1.0])),
                        (np.array([var(a, i, 1), var(b, j, 1)]), np.array([1.0, -1.0])),
                    ]
                for q in (0, 1):
                    cols.append(np.concatenate([np.atleast_1d(left[q][0]), tx, tz]))
                    vals.append(np.concatenate([np.atleast_1d(left[q][1]), -M[q, 0] * wb, -M[q, 1] * wb]))
                rhs += [float(r[0]), float(r[1])]
        else:  # pragma: no cover - filtered by the scene
            raise TypeError(f"not a spatial constraint: {c!r}")
    return Rows(
        [np.asarray(x, dtype=np.int64).reshape(-1) for x in cols], vals, np.asarray(rhs, dtype=float), tuple(metric)
    )


# ------------------------------------------------- relative constraints in metres
@dataclasses.dataclass(frozen=True)
class MetricTargets:
    """Every metric row pair of a constraint structure, gathered for vectorised corrections.

    Built by :meth:`~mocaplab.editing.spatial.SpatialSolver.factorize`; see the module docstring
    ("Relative constraints in metres").

    Attributes
    ----------
    tangent : sparse (2 R, 2 n)
        Rows ``2 r`` and ``2 r + 1`` give the tangent ``T`` of pair ``r``.
    coef : ndarray, shape (R, 2)
    length : ndarray, shape (R,)
    soft : ndarray of bool, shape (R,)
        Whether the pair's rows are soft (in ``bw``) or hard (in ``h``).
    index : ndarray of int, shape (R,)
        Position of the pair's x row in ``bw`` (soft) or ``h`` (hard).
    scale : ndarray, shape (R,)
        ``sqrt(weight)`` for soft rows (``bw`` is weighted), 1 for hard.
    direction : ndarray of bool, shape (R,)
        Direction pairs (equation 2); the others are offsets (equation 1).
    """

    tangent: sp.csr_matrix
    coef: Array
    length: Array
    linear: Array
    soft: NDArray[np.bool_]
    index: NDArray[np.int64]
    scale: Array
    direction: NDArray[np.bool_]

    @property
    def n(self) -> int:
        return len(self.length)

    def correction(self, p: Array) -> Array:
        """Right-hand sides ``(c_x + c_y R)(u - T / L)`` at positions ``p`` (2 n,), shape (R, 2)."""
        T = (self.tangent @ p).reshape(-1, 2)
        ln = np.linalg.norm(T, axis=1, keepdims=True)
        ok = ln > 1e-12
        u = np.where(ok, T / np.where(ok, ln, 1.0), 0.0)
        want = self.coef[:, :1] * u + self.coef[:, 1:] * rot90(u)
        lin = np.einsum("rij,rj->ri", self.linear, T)
        return np.where(ok, want - lin, 0.0)  # a vanished tangent has no direction: the linear target stands

    def apply(self, bw: Array, h: Array, corr: Array) -> tuple[Array, Array]:
        """Copies of ``bw`` and ``h`` with the metric rows' right-hand sides set to ``corr`` (R, 2)."""
        bw, h = bw.copy(), h.copy()
        vals = corr * self.scale[:, None]
        s, hd = self.soft, ~self.soft
        for target, sel in ((bw, s), (h, hd)):
            if sel.any():
                i = self.index[sel]
                target[i] = vals[sel, 0]
                target[i + 1] = vals[sel, 1]
        return bw, h

    def current(self, bw: Array, h: Array) -> Array:
        """The metric rows' right-hand sides in ``bw`` (weighted) and ``h``, unweighted, shape (R, 2)."""
        out = np.zeros((self.n, 2))
        s, hd = self.soft, ~self.soft
        for source, sel in ((bw, s), (h, hd)):
            if sel.any():
                i = self.index[sel]
                out[sel] = np.stack([source[i], source[i + 1]], axis=1)
        return out / self.scale[:, None]

    def errors(self, p: Array, rows: Array) -> Array:
        """Metric error of each pair at positions ``p``, shape (R,).

        ``rows`` (R, 2) are the pairs' linear row values at ``p`` (unweighted,
        right-hand side not subtracted): ``lhs - (c / L)(T, R T)`` with
        ``lhs = p_a - p_b`` or ``T_a``.  The metric error ``|lhs - (c_x u +
        c_y R u)|`` is ``|rows - correction(p)|``: metres for offsets; for
        directions it is divided by ``|c|`` (the chord between the unit
        directions, about the angle in radians).
        """
        err = np.linalg.norm(rows - self.correction(p), axis=1)
        size = np.maximum(np.linalg.norm(self.coef, axis=1), 1e-300)
        return np.where(self.direction, err / size, err)

    def pair_errors(self, p: Array, soft_values: Array, hard_values: Array) -> Array:
        """:meth:`errors` of every pair at ``p`` from its rows' values ``Bw @ p`` (weighted) and ``H @ p``."""
        rows = np.zeros((self.n, 2))
        for values, sel, scale in ((soft_values, self.soft, self.scale), (hard_values, ~self.soft, None)):
            if sel.any():
                i = self.index[sel]
                vals = np.stack([values[i], values[i + 1]], axis=1)
                rows[sel] = vals / scale[sel, None] if scale is not None else vals
        return self.errors(p, rows)


def metric_targets(
    soft: Sequence[Rows], weights: Sequence[float], hard: Sequence[Rows], n: int
) -> MetricTargets | None:
    """Gather the :class:`MetricPair` rows of the soft and hard blocks (None if there are none)."""
    rows, cols, vals, coef, length, is_soft, index, scale, direction, linear = [], [], [], [], [], [], [], [], [], []
    r = 0
    for blocks, ws, flag in ((soft, weights, True), (hard, [1.0] * len(hard), False)):
        start = 0
        for block, w in zip(blocks, ws, strict=True):
            for m in block.metric:
                for c in (0, 1):
                    rows.append(np.full(len(m.cols), 2 * r + c))
                    cols.append(m.cols + c)
                    vals.append(m.weights)
                coef.append(m.coef)
                length.append(m.length)
                linear.append(m.linear)
                is_soft.append(flag)
                index.append(start + m.row)
                scale.append(float(np.sqrt(w)) if flag else 1.0)
                direction.append(m.direction)
                r += 1
            start += block.n
    if r == 0:
        return None
    T = sp.csr_matrix((np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))), shape=(2 * r, n))
    return MetricTargets(
        T,
        np.asarray(coef, dtype=float),
        np.asarray(length, dtype=float),
        np.asarray(linear, dtype=float).reshape(-1, 2, 2),
        np.asarray(is_soft, dtype=bool),
        np.asarray(index, dtype=np.int64),
        np.asarray(scale, dtype=float),
        np.asarray(direction, dtype=bool),
    )
