"""Laplacian path editing in space (Kim et al. 2009, sections 4.1 and 4.2).

Unknowns: the ground positions of every frame of every character, stacked
in one vector ``p`` (character after character, frame after frame, ``x``
then ``z``), so one sparse system edits the whole scene at once.

Phase 1, shape preservation (equations 3 to 6)
    minimise ``|A p|^2 + |B p - b|^2_W`` subject to ``H p = h``, where
    ``A p = 0`` keeps each interior frame's Laplacian coordinates (eq. 3), ``B``
    holds the soft constraints (rows scaled by the square root of their
    weights) and ``H`` the hard ones.  The KKT system (eq. 6) is factorised
    with SuperLU (:func:`scipy.sparse.linalg.splu`).
Phase 2, scale compensation (equation 7)
    ``v_i - v_{i-1} = vbar_i - vbar_{i-1}`` with ``vbar_i`` the phase-1 segment
    ``pbar_{i+1} - pbar_i`` rescaled to its undeformed length: the matrix is
    the fixed second-difference operator; only the right-hand side depends on
    phase 1, so both phases are factorised once per constraint *structure*.
Stationary sub-paths (section 4.2)
    the equation-3 rows of their interior frames become hard constraints in
    phase 1 (the segment moves as a similarity); in phase 2 each of its steps
    is held by a hard row ``p_{i+1} - p_i = vbar_i`` (the phase-1 step
    rescaled to its undeformed length), so the segment moves rigidly and a
    standing character does not skate.  Only right-hand sides depend on
    phase 1, so the matrices stay fixed.
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
    (:func:`detect_tangent_flips`).  The positions are not changed, so the
    matrix never depends on the flips.

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
    solution, so the solve is repeated (a fixed point, Anderson-accelerated)
    until ``r`` changes by less than ``relative_tolerance`` (1 mm).  Rows
    linearised about the undeformed path already carry the right first-order
    response (a stretch along the tangent leaves the offset alone, a turn
    turns it), so a drag that moves tied characters together needs one or
    two solves; the rows of equations 1 and 2 respond ``|c| / L`` times too
    strongly to a stretch (about 9 for 0.8 m beside a walk at 30 fps) and
    needed 10 to 20 solves in a formation.  The iteration keeps its best
    iterate and stops when it stops improving or diverges (a soft
    constraint far from anything reachable, or one that fights hard
    constraints: :meth:`SpatialSolver.soft_conflicts`); a hard relative
    still missed by 10 cm raises, naming the hard constraints on its
    unknowns.  An interactive drag starts from the previous update's
    corrections.  The discrete evaluation writes the rows linearised about
    the current solution instead (``spatial_rows(..., linearize_at=...)``).

Redundant hard constraints
    A set of hard rows is accepted when it is consistent, not only when it
    has full rank: rows that others imply (the same pin twice, two pins on a
    rigid stationary segment) are left out of the factorisation and checked
    after every solve (:func:`independent_hard_rows`, :class:`HardRows`);
    ``EditResult.notes`` says which.  Inconsistent ones raise
    :class:`~mocaplab.editing.constraints.ConstraintError` naming them.

Free modes (our choice): the Laplacian energies only see a path up to a
similarity (phase 1: translation, rotation, scale) or an index-affine map
(phase 2), so a character that the constraints do not pin down makes the
system singular.  Instead of a Tikhonov term (which at 120 fps biases the
result far more than the weak Laplacian energy allows), we find exactly which
of those modes no constraint touches (an SVD of the constraints restricted to
the modes, per group of linked characters) and fix only them with hard
"gauge" rows: they keep their reference value (the undeformed path in phase
1, the phase-1 result in phase 2).  Nothing that a constraint determines is
biased; a character with no constraint keeps its path.

A drag that moves a target changes only ``b`` and ``h``: phase 1 is then
updated through cached columns of its inverse for the moved entries
(O(frames), :meth:`SpatialSolver._phase1`), phase 2 is one back-substitution
(its right-hand side depends on phase 1 everywhere), plus O(F) vector work.
"""

from __future__ import annotations

import dataclasses
import functools
from collections.abc import Sequence
from functools import cached_property
from typing import Any

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla
from numpy.typing import NDArray
from scipy.sparse.csgraph import connected_components

from .constraints import ConstraintError, PinDirection, PinPosition, Relative
from .paths import MotionPath, central_tangents, ground_angle, laplacian_coordinates, rot90, wrap_angle

__all__ = [
    "gauge_rows",
    "similarity_modes",
    "affine_modes",
    "Layout",
    "Rows",
    "KKT",
    "SpatialSolver",
    "spatial_rows",
    "shape_matrix",
    "scale_matrix",
    "rigid_rows",
    "FLIP_RATE",
    "flip_step",
    "detect_tangent_flips",
    "heading_changes",
    "TURN_RATE",
    "STEADY_SPEED",
]

Array = NDArray[np.float64]


@dataclasses.dataclass(frozen=True)
class Layout:
    """Where each character's frames sit in the stacked unknown vectors.

    ``offsets[k]`` is the global frame index of character ``k``'s frame 0;
    spatial unknown ``2 * (offsets[k] + i) + c`` is coordinate ``c`` (0: x,
    1: z) of frame ``i``; temporal unknown ``offsets[k] + i`` its time.
    """

    n_frames: tuple[int, ...]

    @cached_property
    def offsets(self) -> NDArray[np.int64]:
        off = np.concatenate([[0], np.cumsum(self.n_frames)]).astype(np.int64)
        off.flags.writeable = False
        return off

    @property
    def total(self) -> int:
        return int(sum(self.n_frames))

    def frame(self, k: int, i: int) -> int:
        return int(self.offsets[k]) + int(i)

    def character_of(self) -> NDArray[np.int64]:
        """Character index of every global frame, shape (total,)."""
        return np.repeat(np.arange(len(self.n_frames)), self.n_frames)

    def interior(self) -> NDArray[np.int64]:
        """Global indices of frames with both neighbours in the same character."""
        off = self.offsets
        return np.concatenate([np.arange(off[k] + 1, off[k + 1] - 1) for k in range(len(self.n_frames))]).astype(
            np.int64
        )

    def steps(self) -> NDArray[np.int64]:
        """Global indices ``g`` of within-character steps ``g -> g + 1``."""
        off = self.offsets
        return np.concatenate([np.arange(off[k], off[k + 1] - 1) for k in range(len(self.n_frames))]).astype(np.int64)


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


@dataclasses.dataclass
class Rows:
    """Linear rows ``sum(vals * x[cols]) = rhs`` produced by one constraint.

    ``metric`` lists the row pairs whose right-hand side is corrected to a
    metric target after each solve (relative constraints; :class:`MetricPair`).
    """

    cols: list[NDArray[np.int64]]
    vals: list[Array]
    rhs: Array
    metric: tuple[MetricPair, ...] = ()

    @property
    def n(self) -> int:
        return len(self.cols)


def assemble(rows: Sequence[Rows], n: int, scales: Sequence[float] | None = None) -> tuple[sp.csr_matrix, Array]:
    """Stack rows into a sparse matrix and right-hand side (each block scaled)."""
    cols, vals, ridx, rhs = [], [], [], []
    r = 0
    for b, block in enumerate(rows):
        s = 1.0 if scales is None else scales[b]
        for c, v in zip(block.cols, block.vals, strict=True):
            cols.append(c)
            vals.append(v * s)
            ridx.append(np.full(len(c), r))
            r += 1
        rhs.append(block.rhs * s)
    if r == 0:
        return sp.csr_matrix((0, n)), np.zeros(0)
    m = sp.csr_matrix((np.concatenate(vals), (np.concatenate(ridx), np.concatenate(cols))), shape=(r, n))
    m.sum_duplicates()
    return m, np.concatenate(rhs)


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


# ------------------------------------------------------------ constraints
class _TangentRows:
    """Cached rows of each path's tangent operator."""

    def __init__(self, paths: Sequence[MotionPath]) -> None:
        self.paths = paths
        self._ops: dict[int, sp.csr_matrix] = {}

    def row(self, k: int, i: int) -> tuple[NDArray[np.int64], Array]:
        if k not in self._ops:
            self._ops[k] = self.paths[k].tangent_operator()
        op = self._ops[k]
        s, e = op.indptr[i], op.indptr[i + 1]
        return op.indices[s:e].astype(np.int64), op.data[s:e].astype(float)


def _metric_linearization(coef: tuple[float, float], T: Array) -> tuple[Array, Array]:
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
    tangents: _TangentRows,
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
                    M, r = _metric_linearization(coef, T_at)
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

    Built by :meth:`SpatialSolver.factorize`; see the module docstring
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


# ------------------------------------------------------------ free modes
def _mode_matrix(blocks: list[tuple[int, Array]], n: int, dim: int) -> sp.csc_matrix:
    """Columns from per-character dense blocks ``(first unknown, (len, m) block)``."""
    rows, cols, vals = [], [], []
    c = 0
    for start, blk in blocks:
        r, m = blk.shape
        rows.append(np.repeat(np.arange(start, start + r), m))
        cols.append(np.tile(np.arange(c, c + m), r))
        vals.append(blk.reshape(-1))
        c += m
    return sp.csc_matrix((np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))), shape=(n, c))


def similarity_modes(paths: Sequence[MotionPath], layout: Layout) -> tuple[sp.csc_matrix, NDArray[np.int64]]:
    """Orthonormal basis of the null space of ``A`` (2D similarities of each path).

    Columns per character: x and z translation, scaling about the centroid,
    rotation about the centroid.  A path whose frames all coincide uses the
    index-affine basis instead.  Returns the (2 total, 4 K) matrix and the
    character of each column.
    """
    blocks = []
    for k, p in enumerate(paths):
        F = p.n_frames
        u = p.positions - p.positions.mean(axis=0)
        tx = np.zeros((F, 2))
        tx[:, 0] = 1.0
        tz = np.zeros((F, 2))
        tz[:, 1] = 1.0
        if np.linalg.norm(u) < 1e-9:
            s = (np.arange(F) - (F - 1) / 2.0)[:, None]
            extra = [s * [1.0, 0.0], s * [0.0, 1.0]]
        else:
            extra = [u, rot90(u)]
        cols = [tx, tz] + extra
        cols = [c.reshape(-1) / np.linalg.norm(c) for c in cols]
        blocks.append((2 * int(layout.offsets[k]), np.stack(cols, axis=1)))
    return _mode_matrix(blocks, 2 * layout.total, 4), np.repeat(np.arange(len(paths)), 4)


def affine_modes(layout: Layout) -> tuple[sp.csc_matrix, NDArray[np.int64]]:
    """Orthonormal basis of the null space of the second-difference matrix (index-affine maps)."""
    blocks = []
    for k, F in enumerate(layout.n_frames):
        s = np.arange(F) - (F - 1) / 2.0
        cols = []
        for c in (0, 1):
            one = np.zeros((F, 2))
            one[:, c] = 1.0
            lin = np.zeros((F, 2))
            lin[:, c] = s
            cols += [one, lin]
        cols = [c.reshape(-1) / max(float(np.linalg.norm(c)), 1e-300) for c in cols]
        blocks.append((2 * int(layout.offsets[k]), np.stack(cols, axis=1)))
    return _mode_matrix(blocks, 2 * layout.total, 4), np.repeat(np.arange(len(layout.n_frames)), 4)


def _gauge_coordinates(V: Array, primary: NDArray[np.bool_] | None) -> Array:
    """Rows ``M`` (d, q) with ``M V`` invertible, using primary coordinates first."""
    if primary is None or not primary.any():
        return V.T
    d = V.shape[1]
    VP = V[primary]
    u, sv, vt = np.linalg.svd(VP, full_matrices=True)
    tol = 1e-10 * max(float(np.abs(V).max(initial=0.0)), 1e-300)
    r = int(np.sum(sv > tol))
    rows = []
    if r:
        m1 = np.zeros((r, V.shape[0]))
        m1[:, primary] = u[:, :r].T
        rows.append(m1)
    if r < d:
        VT = (V @ vt[r:].T)[~primary]
        u2, s2, _ = np.linalg.svd(VT, full_matrices=False)
        r2 = int(np.sum(s2 > tol))
        m2 = np.zeros((r2, V.shape[0]))
        m2[:, ~primary] = u2[:, :r2].T
        rows.append(m2)
    return np.vstack(rows)


def gauge_rows(
    Q: sp.csc_matrix,
    owner: NDArray[np.int64],
    C: sp.spmatrix,
    n_chars: int,
    primary: NDArray[np.bool_] | None = None,
) -> sp.csr_matrix:
    """Rows fixing the modes in ``Q``'s span that no row of ``C`` touches.

    ``Q`` (n, q) has orthonormal columns spanning the null space of the
    energy; ``owner[j]`` is the character of column ``j``.  The modes free of
    ``C`` are ``Q V`` with ``V`` an orthonormal basis of the null space of
    ``C Q``, computed separately for each group of characters linked by rows
    of ``C`` (so gauge rows never couple unrelated characters).

    The gauge rows fix mode *coordinates* ``Q^T x``, preferring the
    ``primary`` columns (rotation and scale, or the index-linear modes): free
    directions are first held by their primary coordinates, and only what is
    left (pure translations) by the others.  So pinning one frame of a path
    translates it rigidly instead of also turning it to reduce the overall
    displacement (which the minimum-norm choice would do).
    """
    CQ = sp.csr_matrix(sp.csr_matrix(C) @ Q) if C.shape[0] else sp.csr_matrix((0, Q.shape[1]))
    CQ.eliminate_zeros()
    scale = max(1.0, float(abs(CQ).max())) if CQ.nnz else 1.0
    CQ.data[np.abs(CQ.data) <= 1e-13 * scale] = 0.0
    CQ.eliminate_zeros()
    coo = CQ.tocoo()
    # characters linked by a row
    inc = sp.csr_matrix((np.ones(coo.nnz), (coo.row, owner[coo.col])), shape=(CQ.shape[0], n_chars))
    inc.data[:] = 1.0
    adj = (inc.T @ inc).tocsr()
    ncomp, label = connected_components(adj, directed=False)
    # rows on one character only, and each character's Gram block of them (q_k x q_k, tiny)
    per_row = np.asarray((inc > 0).sum(axis=1)).ravel()
    local = CQ[np.flatnonzero(per_row == 1)]
    Gl = (local.T @ local).tocoo()
    same = owner[Gl.row] == owner[Gl.col]
    out: list[sp.csr_matrix] = []
    for comp in range(ncomp):
        chars = np.flatnonzero(label == comp)
        cols = np.flatnonzero(np.isin(owner, chars))
        sub = CQ[:, cols]
        rows = np.flatnonzero(np.diff(sub.indptr) > 0)
        if len(rows) == 0:
            V = np.eye(len(cols))
        else:
            # fast exact test: the Gram matrix of all rows dominates the block diagonal of the local rows'
            # (lambda_min(G) >= min_k lambda_min(G_k)) and lambda_max(G) <= |CQ|_F^2, so if every character's
            # own rows hold its modes well enough no mode is free
            bound = 1e-12 * float(sub.multiply(sub).sum())
            pos = np.full(len(owner), -1, dtype=np.int64)
            pos[cols] = np.arange(len(cols))
            q = np.bincount(owner[cols], minlength=n_chars)[chars]
            ok = False
            if np.all(q == q[0]):
                qk = int(q[0])
                blocks = np.zeros((len(chars), qk, qk))
                sel = same & (pos[Gl.row] >= 0)
                ci = np.searchsorted(chars, owner[Gl.row[sel]])
                first = np.searchsorted(owner, chars)  # owner is sorted: each character's columns together
                blocks[ci, Gl.row[sel] - first[ci], Gl.col[sel] - first[ci]] = Gl.data[sel]
                ok = bool(np.linalg.eigvalsh(blocks)[:, 0].min() > bound)
            if ok:
                continue
            dense = sub[rows].toarray()
            # null space from the (small, q x q) Gram matrix: eigenvalues are squared singular values
            w, vecs = np.linalg.eigh(dense.T @ dense)
            tol = 1e-12 * max(float(w.max(initial=0.0)), 1e-300)
            V = vecs[:, w <= tol]
        if V.shape[1] == 0:
            continue
        M = _gauge_coordinates(V, None if primary is None else primary[cols])
        out.append(sp.csr_matrix((Q[:, cols] @ M.T).T))
    if not out:
        return sp.csr_matrix((0, Q.shape[0]))
    return sp.vstack(out, format="csr")


# -------------------------------------------------------------------- KKT
def _dependent_groups(H: sp.csr_matrix, groups: Sequence[tuple[Any, NDArray[np.int64]]]) -> list[int] | None:
    """Indices of a minimal set of row groups of ``H`` that are linearly dependent (None if H has full row rank)."""

    def rank_def(sel: Sequence[int]) -> bool:
        rows = np.concatenate([groups[s][1] for s in sel]) if sel else np.zeros(0, np.int64)
        if len(rows) == 0:
            return False
        sub = H[rows]
        cols = np.unique(sub.indices)
        dense = sub[:, cols].toarray()
        if dense.shape[0] > dense.shape[1]:
            return True
        return bool(np.linalg.matrix_rank(dense) < dense.shape[0])

    # split into components of groups that share unknowns; check each alone
    parent = list(range(len(groups)))

    def find(a: int) -> int:
        while parent[a] != a:
            parent[a] = parent[parent[a]]
            a = parent[a]
        return a

    owner: dict[int, int] = {}
    for gi, (_, rows) in enumerate(groups):
        for col in np.unique(H[rows].indices):
            col = int(col)
            if col in owner:
                ra, rb = find(owner[col]), find(gi)
                if ra != rb:
                    parent[rb] = ra
            else:
                owner[col] = gi
    comps: dict[int, list[int]] = {}
    for gi in range(len(groups)):
        comps.setdefault(find(gi), []).append(gi)
    for order in comps.values():
        if len(order) == 1 and not rank_def(order):
            continue
        found = _minimal_dependent(order, rank_def)
        if found is not None:
            return found
    return None


def _minimal_dependent(order: list[int], rank_def: Any) -> list[int] | None:
    if not rank_def(order):
        return None
    chosen: list[int] = []
    culprit = None
    for g in order:
        if rank_def(chosen + [g]):
            culprit = g
            break
        chosen.append(g)
    if culprit is None:  # pragma: no cover - numerical corner
        return order
    needed = list(chosen)
    for e in reversed(chosen):
        trial = [x for x in needed if x != e]
        if rank_def(trial + [culprit]):
            needed = trial
    return needed + [culprit]


_SCREEN_TOL = 1e-9  # squared sine of the angle between a hard row and the span of the others


def full_row_rank_screen(H: sp.spmatrix) -> bool:
    """Cheap sufficient test that the rows of ``H`` are linearly independent.

    The rows are scaled to unit length and the Gram matrix ``G = H H^T``
    (sparse, ``(m, m)``) is factorised by SuperLU with diagonal pivots in a
    fill-reducing symmetric order: for positive definite ``G`` this is a
    Cholesky factorisation, and its ``i``-th pivot is the squared sine of the
    angle between row ``i`` and the span of the rows eliminated before it.
    All pivots above ``1e-9`` certify full row rank.  A dependent set of rows
    makes one pivot vanish (exactly, up to rounding), so the test returns
    False; it also returns False for rows that are merely close to dependent,
    which the caller then checks exactly (:func:`independent_hard_rows`).  Cost:
    one sparse factorisation of ``G`` (banded for the rigid-segment rows),
    instead of dense SVDs.
    """
    H = sp.csr_matrix(H)
    m, n = H.shape
    if m == 0:
        return True
    if m > n:
        return False
    norms = np.sqrt(np.asarray(H.multiply(H).sum(axis=1)).ravel())
    if not np.all(norms > 0):
        return False
    Hn = sp.diags(1.0 / norms) @ H
    G = (Hn @ Hn.T).tocsc()
    try:
        lu = spla.splu(G, permc_spec="MMD_AT_PLUS_A", diag_pivot_thresh=0.0, options={"SymmetricMode": True})
    except RuntimeError:  # exactly singular
        return False
    piv = lu.U.diagonal()
    return bool(np.all(piv > _SCREEN_TOL))


def _label_text(label: Any) -> str:
    return f"#{label[0]} {label[1]!r}" if isinstance(label, tuple) else str(label)


@dataclasses.dataclass(frozen=True)
class Redundancy:
    """Hard rows left out of a factorisation because other hard rows imply them.

    Attributes
    ----------
    label : (index, constraint) or str
        The constraint (or automatic rows) whose rows were left out.
    rows : ndarray of int
        Their indices in the full hard-row matrix.
    implied_by : tuple
        Labels of the hard rows that determine them.
    """

    label: Any
    rows: NDArray[np.int64]
    implied_by: tuple[Any, ...]

    def note(self, what: str) -> str:
        by = " and ".join(_label_text(b) for b in self.implied_by)
        return (
            f"hard {what} constraint {_label_text(self.label)} is redundant (implied by {by}): its rows are left out "
            "of the solve and checked instead"
        )


_ANDERSON = 5  # iterates mixed by the metric-target iteration
_STALE = 3  # iterations without a smaller change before the metric-target iteration stops
_HARD_MISS = 100.0  # a hard relative missed by this many metric tolerances (10 cm by default) raises
_DIVERGE = 10.0  # a change this many times the best one so far: the metric-target iteration diverges
_INFLUENCE = 8  # at most this many moved right-hand-side entries update phase 1 through cached columns
_INFLUENCE_CACHE = 16  # supports kept per factorisation
_CONSISTENCY_TOL = 1e-7  # metres or seconds: how far a left-out redundant hard row may miss
_UPDATE_RANGE = 1e6  # phase 1 is updated from the previous solution only within this many scene extents
_RANGE_TOL = 1e-6  # fraction of the scene's extent a kept hard row may miss (round-off is ~1e-15 of it)


@dataclasses.dataclass(frozen=True)
class HardRows:
    """The hard rows of one linear system: all of them, and a linearly independent subset to factorise.

    Built by :func:`independent_hard_rows`.  A set of hard constraints is
    accepted when it is *consistent*, not only when it has full rank: rows
    that other hard rows imply (the same pin twice, two pins on a rigid
    stationary segment, a direction pin on one) are left out of the KKT
    system (which needs independent rows) and checked after every solve
    (:meth:`check`): if their targets disagree with what the kept rows
    determine, the edit raises :class:`ConstraintError` naming them.

    Attributes
    ----------
    H : sparse (m, n)
        Every hard row.
    keep : ndarray of bool, shape (m,)
        The rows in the factorisation.
    redundant : tuple of Redundancy
    what : str
        "spatial" or "temporal" (for messages).
    """

    H: sp.csr_matrix
    keep: NDArray[np.bool_]
    redundant: tuple[Redundancy, ...]
    what: str
    groups: tuple[tuple[Any, NDArray[np.int64]], ...] = ()

    @functools.cached_property
    def kept_rows(self) -> NDArray[np.int64]:
        return np.flatnonzero(self.keep)

    @functools.cached_property
    def kept(self) -> sp.csr_matrix:
        return self.H if self.keep.all() else self.H[self.kept_rows]

    def notes(self) -> tuple[str, ...]:
        return tuple(r.note(self.what) for r in self.redundant)

    def check(self, x: Array, h: Array, *, scale: float = 1.0) -> None:
        """Raise :class:`ConstraintError` if a hard row is not met by ``x`` (``h``: all right-hand sides).

        The kept rows hold by construction up to round-off: a miss beyond
        ``_RANGE_TOL * scale`` (``scale``: the scene's extent, metres or
        seconds) means the targets are too far from the scene for double
        precision (a pin 1e15 m away is met only to about 0.1 m) and raises
        instead of handing back a silently violated "hard" constraint.  The
        left-out redundant rows must agree with the kept ones.
        """
        self.check_range(x, h, scale)
        for r in self.redundant:
            miss = float(np.max(np.abs(self.H[r.rows] @ x - h[r.rows])))
            if miss > _CONSISTENCY_TOL * max(1.0, float(np.max(np.abs(h), initial=0.0))):
                labels = [*r.implied_by, r.label]
                unit = "m" if self.what == "spatial" else "s"
                raise ConstraintError(
                    f"Conflicting hard {self.what} constraints: {_label_text(r.label)} is determined by "
                    + " and ".join(_label_text(b) for b in r.implied_by)
                    + f", and its target is {miss:.3g} {unit} away from what they give (they cannot all hold "
                    "exactly). Make one of them soft (hard=False), move it back, or remove it"
                    + (
                        "; or let the segment deform (stationary=None, or segments that leave these frames out)."
                        if any(isinstance(b, str) and "rigid stationary segment" in b for b in r.implied_by)
                        else "."
                    ),
                    [lab[1] if isinstance(lab, tuple) else lab for lab in labels],
                    [lab[0] for lab in labels if isinstance(lab, tuple)],
                )

    def check_range(self, x: Array, h: Array, scale: float) -> None:
        """Raise :class:`ConstraintError` ("out of numeric range") if a kept row misses by more than round-off."""
        kept = self.kept_rows
        if not kept.size:
            return
        miss = np.abs(self.kept @ x - h[kept])
        tol = _RANGE_TOL * max(float(scale), 1.0)
        bad = ~(miss <= tol)  # NaN counts as missed
        if not bad.any():
            return
        rows = kept[bad]
        labels = [lab for lab, g in self.groups if np.isin(g, rows).any()]
        worst = float(np.nanmax(np.where(np.isfinite(miss), miss, np.inf)))
        unit = "m" if self.what == "spatial" else "s"
        top = float(np.max(np.abs(h[kept]), initial=0.0))
        names = ", ".join(_label_text(lab) for lab in labels) or "automatic rows"
        raise ConstraintError(
            f"Hard {self.what} constraints are missed by {worst:.3g} {unit} after the solve ({names}): the targets "
            f"are out of numeric range for this scene (largest target {top:.3g} {unit}, scene {scale:.3g} {unit} "
            f"across; a hard constraint must hold to {tol:.3g} {unit}). Bring the targets near the characters.",
            [lab[1] if isinstance(lab, tuple) else lab for lab in labels],
            [lab[0] for lab in labels if isinstance(lab, tuple)],
        )


def independent_hard_rows(
    H: sp.spmatrix,
    groups: Sequence[tuple[Any, NDArray[np.int64]]],
    what: str,
    *,
    known: Sequence[Redundancy] = (),
) -> HardRows:
    """Split hard rows into an independent set to factorise and redundant rows to check (:class:`HardRows`).

    ``groups`` are ``(label, rows)`` pairs in order of preference: when rows
    depend on each other, the rows of the *later* group are the ones left
    out (put automatic rows such as rigid segments first, then the user's
    constraints in index order).  ``known``: redundancies found beforehand
    by structure (pins inside a rigid segment, :func:`segment_redundancy`);
    their rows are left out from the start.  A sparse Cholesky screen
    (:func:`full_row_rank_screen`) then clears the usual case with one sparse
    factorisation; otherwise a minimal dependent set of groups is found
    (dense rank tests on the groups that share unknowns), the redundant
    rows of its last group are left out, and the screen runs again.
    """
    H = sp.csr_matrix(H)
    m = H.shape[0]
    keep = np.ones(m, bool)
    redundant: list[Redundancy] = list(known)
    for r in known:
        keep[r.rows] = False
    labelled = tuple((lab, np.asarray(rows, np.int64)) for lab, rows in groups)
    if m == 0 or full_row_rank_screen(H[np.flatnonzero(keep)] if known else H):
        return HardRows(H, keep, tuple(redundant), what, labelled)
    for _ in range(m):
        live = [(lab, rows[keep[rows]]) for lab, rows in groups]
        index = [i for i, (_, rows) in enumerate(live) if len(rows)]
        sub = [live[i] for i in index]
        bad = _dependent_groups(H, sub)
        if bad is None:  # only close to dependent: the KKT factorisation copes
            break
        culprit = sub[bad[-1]]
        basis_rows = np.concatenate([sub[b][1] for b in bad[:-1]]) if len(bad) > 1 else np.zeros(0, np.int64)
        cols = np.unique(H[np.concatenate([basis_rows, culprit[1]])].indices)
        basis = H[basis_rows][:, cols].toarray()
        rank = int(np.linalg.matrix_rank(basis)) if len(basis_rows) else 0
        dropped = []
        for r in culprit[1]:
            trial = np.vstack([basis, H[[r]][:, cols].toarray()])
            new_rank = int(np.linalg.matrix_rank(trial))
            if new_rank == rank:
                dropped.append(int(r))
            else:
                basis, rank = trial, new_rank
        if not dropped:  # pragma: no cover - numerical corner: accept as the screen's near-dependence
            break
        keep[dropped] = False
        redundant.append(Redundancy(culprit[0], np.asarray(dropped, np.int64), tuple(sub[b][0] for b in bad[:-1])))
        if full_row_rank_screen(H[np.flatnonzero(keep)]):
            break
    return HardRows(H, keep, tuple(redundant), what, labelled)


def segment_redundancy(
    H: sp.csr_matrix,
    user: Sequence[tuple[Any, NDArray[np.int64]]],
    segments: Sequence[tuple[Any, NDArray[np.int64], Array]],
) -> list[Redundancy]:
    """Pins that a rigid segment and earlier pins already determine, found from the segment's few free modes.

    A rigid stationary segment leaves its frames only a few degrees of
    freedom: a similarity in phase 1 (4), a translation in phase 2 (2).  On
    the segment, the positions are ``p = B c`` (plus a fixed particular
    solution) with ``B`` the basis of those modes, so a hard row fixing one
    unknown of the segment (a position pin) is a row of ``B``, and whether
    it is implied by the rigid rows and the earlier pins is a rank test on a
    matrix of at most a handful of columns, instead of dense rank tests on
    the thousands of rows of a long segment (:func:`_dependent_groups`).

    Parameters
    ----------
    H : sparse (m, n)
        Every hard row.
    user : sequence of (label, rows)
        The user's hard constraints in order of preference (later ones are
        left out first).
    segments : sequence of (label, unknowns, basis)
        Per rigid segment: its label, the unknowns of its frames (shape
        (u,)) and the basis of its free modes on them (shape (u, d)).

    Returns
    -------
    list of Redundancy
        Per constraint and segment, the rows left out and what implies them
        (the segment and the pins kept before them).
    """
    if not segments or not user:
        return []
    H = sp.csr_matrix(H)
    nnz = np.diff(H.indptr)
    out: list[Redundancy] = []
    for seg_label, unknowns, basis in segments:
        where = np.full(H.shape[1], -1, dtype=np.int64)
        where[unknowns] = np.arange(len(unknowns))
        scale = max(float(np.abs(basis).max(initial=0.0)), 1e-300)
        kept_rows: list[Array] = []
        kept_labels: list[Any] = []
        for label, rows in user:
            dropped = []
            for r in np.asarray(rows, np.int64):
                if nnz[r] != 1:
                    continue
                col = int(H.indices[H.indptr[r]])
                if where[col] < 0:
                    continue
                row = basis[where[col]] * float(H.data[H.indptr[r]])
                trial = np.vstack([*kept_rows, row])
                tol = 1e-9 * scale * max(1.0, float(np.abs(H.data[H.indptr[r]])))
                if len(kept_rows) >= basis.shape[1] or np.linalg.matrix_rank(trial, tol=tol) <= len(kept_rows):
                    dropped.append(int(r))
                else:
                    kept_rows.append(row)
                    if not any(lab is label for lab in kept_labels):
                        kept_labels.append(label)
            if dropped:
                by = (seg_label, *[lab for lab in kept_labels if lab is not label])
                out.append(Redundancy(label, np.asarray(dropped, np.int64), by))
    return out


class KKT:
    """A factorised augmented system ``[[N, H^T], [H, 0]]`` (equations 6 and 9).

    Parameters
    ----------
    N : sparse (n, n)
        Symmetric positive definite normal matrix.
    H : sparse (m, n)
        Hard constraint rows (full row rank: the kept rows of :func:`independent_hard_rows`).
    """

    def __init__(self, N: sp.spmatrix, H: sp.spmatrix) -> None:
        self.n = N.shape[0]
        self.m = H.shape[0]
        if self.m:
            K = sp.bmat([[N, H.T], [H, None]], format="csc")
        else:
            K = sp.csc_matrix(N)
        try:
            self.lu = spla.splu(K, permc_spec="MMD_AT_PLUS_A", options={"SymmetricMode": True})
        except RuntimeError as exc:  # exactly singular
            raise ConstraintError(f"The editing system is singular ({exc}); check the hard constraints") from None

    def solve(self, r: Array, h: Array) -> Array:
        rhs = np.concatenate([r, h]) if self.m else r
        x = self.lu.solve(rhs)
        return x[: self.n]


# ----------------------------------------------------------------- solver
@dataclasses.dataclass(frozen=True)
class SpatialFactors:
    """Both phases' factorisations for one constraint structure.

    Attributes
    ----------
    shape, scale : KKT
        Phase 1 (equation 6) and phase 2 (equation 7; None without scale
        compensation).
    Bw, BwT : sparse
        Soft rows scaled by the square roots of their weights, and transposed.
    H : sparse
        User hard rows followed by the rigid-segment rows of phase 1.
    hard1, hard2 : HardRows
        The hard rows of each phase with the independent subset factorised.
    G1, g1 : sparse, ndarray
        Phase-1 gauge rows and their values (the undeformed path).
    G2 : sparse
        Phase-2 gauge rows (held at the phase-1 result).
    metric : MetricTargets or None
        The relative constraints' rows whose targets are corrected to metres.
    influence : dict
        Cache of phase-1 inverse columns for small right-hand-side changes
        (see :meth:`SpatialSolver._phase1`), bounded.
    """

    shape: KKT
    scale: KKT | None
    Bw: sp.csr_matrix
    BwT: sp.csr_matrix
    H: sp.csr_matrix
    hard1: HardRows
    hard2: HardRows | None
    G1: sp.csr_matrix
    g1: Array
    G2: sp.csr_matrix
    metric: MetricTargets | None
    influence: dict[tuple[tuple[int, ...], tuple[int, ...]], Array] = dataclasses.field(default_factory=dict)

    def notes(self) -> tuple[str, ...]:
        out = list(self.hard1.notes())
        if self.hard2 is not None:
            out += [n + " (phase 2)" for n in self.hard2.notes() if n not in out]
        return tuple(out)


@dataclasses.dataclass(frozen=True)
class SpatialSolution:
    """Both phases' solutions for one set of targets.

    Attributes
    ----------
    pbar, phat : ndarray, shape (2 total,)
        Phase-1 and phase-2 positions (``phat is pbar`` without scale compensation).
    bw, h : ndarray
        The right-hand sides solved for: the given ones with the relative
        rows' metric corrections.
    iterations : int
        Solves made (1 when there is no relative constraint).
    change : float
        Largest change of a metric correction at the kept iterate, metres
        (its metric error, about).
    corrections : ndarray, shape (R, 2)
        The relative rows' right-hand-side corrections solved for.
    diverged : bool
        The metric-target iteration was stopped because its corrections
        grew (the kept iterate is the best one before).
    """

    pbar: Array
    phat: Array
    bw: Array
    h: Array
    iterations: int
    change: float
    corrections: Array
    diverged: bool = False


class SpatialSolver:
    """Constant parts of the spatial problem for one set of characters.

    Parameters
    ----------
    paths : sequence of MotionPath
    segments : sequence of list of (start, stop)
        Stationary segments per character (made rigid).
    scale_compensation : bool
    """

    def __init__(
        self,
        paths: Sequence[MotionPath],
        segments: Sequence[Sequence[tuple[int, int]]],
        *,
        scale_compensation: bool = True,
        metric_tolerance: float = 1e-3,
        metric_iterations: int = 20,
    ) -> None:
        self.metric_tolerance = float(metric_tolerance)
        self.metric_iterations = int(metric_iterations)
        self.paths = list(paths)
        self.layout = Layout(tuple(p.n_frames for p in paths))
        self.p0 = np.concatenate([p.positions for p in paths]).reshape(-1)
        P = self.p0.reshape(-1, 2)
        #: the scene's extent in metres (hard residuals are checked against it)
        self.extent = float(np.max(np.ptp(P, axis=0), initial=0.0)) if len(P) else 0.0
        self.A = shape_matrix(paths, self.layout)
        self.AtA = (self.A.T @ self.A).tocsr()
        self.Ahat = scale_matrix(self.layout)
        self.AhatT = self.Ahat.T.tocsr()
        self.AhtAh = (self.AhatT @ self.Ahat).tocsr()
        self.R, self.rigid_groups = rigid_rows(self.A, self.layout, segments)
        # phase 2: rigid segments keep their phase-1 segment vectors rescaled to
        # the undeformed lengths (a rotation of the undeformed segment)
        rigid_steps = [
            self.layout.frame(k, 0) + np.arange(a, b - 1)
            for k, segs in enumerate(segments)
            for a, b in segs
            if b - a >= 2
        ]
        rs = np.concatenate(rigid_steps).astype(np.int64) if rigid_steps else np.zeros(0, np.int64)
        self.rigid_groups2: list[tuple[str, NDArray[np.int64]]] = []
        r0 = 0
        for k, segs in enumerate(segments):
            for a, b in segs:
                if b - a >= 2:
                    lab = f"rigid stationary segment of character {k}, frames {a}-{b - 1}"
                    self.rigid_groups2.append((lab, np.arange(2 * r0, 2 * (r0 + b - 1 - a))))
                    r0 += b - 1 - a
        n2 = len(rs)
        rr = np.arange(2 * n2)
        cc = np.stack([2 * rs, 2 * rs + 1], axis=1).reshape(-1)
        self.R2 = sp.csr_matrix(
            (
                np.concatenate([np.ones(2 * n2), -np.ones(2 * n2)]),
                (np.concatenate([rr, rr]), np.concatenate([cc + 2, cc])),
            ),
            shape=(2 * n2, 2 * self.layout.total),
        )
        self._rigid_step_rows = rs  # global step g: segment p[g] -> p[g + 1]
        self.segments = [list(s) for s in segments]
        self.scale_compensation = bool(scale_compensation)
        self.tangent_rows = _TangentRows(self.paths)
        self.Q1, self.owner1 = similarity_modes(self.paths, self.layout)
        self.Q2, self.owner2 = affine_modes(self.layout)
        self._primary = np.tile([False, False, True, True], K0 := len(self.paths))
        self._primary2 = np.tile([False, True, False, True], K0)
        # phase-2 helpers: undeformed segment lengths of within-character steps
        steps = self.layout.steps()
        P0 = self.p0.reshape(-1, 2)
        self._steps = steps
        self._L0 = np.linalg.norm(P0[steps + 1] - P0[steps], axis=1)
        # lengths of all n - 1 consecutive segments, 0 across characters
        self._L0full = np.zeros(max(self.layout.total - 1, 0))
        self._L0full[steps] = self._L0
        self._interior = self.layout.interior()
        self._segment_modes = self._rigid_segment_modes()

    def _rigid_segment_modes(self) -> tuple[list[tuple[str, NDArray[np.int64], Array]], ...]:
        """Per phase, each rigid segment's label, unknowns and the basis of the motions its rigid rows leave free.

        Phase 1: the similarities of the segment's undeformed positions (its
        Laplacian coordinates are similarity invariant), kept only where the
        rigid rows verifiably vanish on them (a segment of coincident frames
        has other free modes: left to the generic test).  Phase 2: the two
        translations (the steps are held).
        """
        phase1: list[tuple[str, NDArray[np.int64], Array]] = []
        phase2: list[tuple[str, NDArray[np.int64], Array]] = []
        P = self.p0.reshape(-1, 2)
        n = 2 * self.layout.total
        groups1 = dict(self.rigid_groups)
        for k, segs in enumerate(self.segments):
            for a, b in segs:
                label = f"rigid stationary segment of character {k}, frames {a}-{b - 1}"
                frames = self.layout.frame(k, 0) + np.arange(a, b)
                unknowns = np.stack([2 * frames, 2 * frames + 1], axis=1).reshape(-1)
                F = len(frames)
                tx = np.tile([1.0, 0.0], F)
                tz = np.tile([0.0, 1.0], F)
                if b - a >= 2:
                    phase2.append((label, unknowns, np.stack([tx, tz], axis=1)))
                rows = groups1.get(label)
                u = P[frames] - P[frames].mean(axis=0)
                size = float(np.linalg.norm(u))
                if rows is None or size < 1e-6:
                    continue
                basis = np.stack([tx, tz, u.reshape(-1) / size, rot90(u).reshape(-1) / size], axis=1)
                full = np.zeros((n, 4))
                full[unknowns] = basis
                Rs = self.R[rows]
                residual = float(np.abs(Rs @ full).max(initial=0.0))
                if residual <= 1e-9 * max(1.0, float(abs(Rs).max())):
                    phase1.append((label, unknowns, basis))
        return phase1, phase2

    def factorize(
        self, soft: Sequence[Rows], weights: Sequence[float], hard: Sequence[Rows], labels: Sequence[Any]
    ) -> tuple[SpatialFactors, Array, Array]:
        """Factorise both phases for a constraint structure.

        Returns the factors and the (weighted) soft and hard right-hand sides.
        Redundant hard rows are left out of the factorisations and checked at
        every solve (:class:`HardRows`); inconsistent ones raise there.
        """
        n = 2 * self.layout.total
        K = len(self.paths)
        Bw, bw = assemble(soft, n, [float(np.sqrt(w)) for w in weights])
        Hu, h = assemble(hard, n)
        H = sp.vstack([Hu, self.R], format="csr")
        user: list[tuple[Any, NDArray[np.int64]]] = []
        r = 0
        for lab, block in zip(labels, hard, strict=True):
            user.append((lab, np.arange(r, r + block.n)))
            r += block.n
        rigid = [(lab, rows + r) for lab, rows in self.rigid_groups]
        # pins inside a rigid segment: which are implied is decided on the segment's few free modes
        known1 = segment_redundancy(H, user, self._segment_modes[0])
        hard1 = independent_hard_rows(H, rigid + user, "spatial", known=known1)  # rigid rows kept first
        BwT = Bw.T.tocsr()
        BtB = (BwT @ Bw).tocsr()
        C = sp.vstack([Bw, H], format="csr")
        G1 = gauge_rows(self.Q1, self.owner1, C, K, self._primary)
        shape = KKT(self.AtA + BtB, sp.vstack([hard1.kept, G1], format="csr"))
        G2 = sp.csr_matrix((0, n))
        scale = None
        hard2 = None
        if self.scale_compensation:
            H2 = sp.vstack([Hu, self.R2], format="csr")
            rigid2 = [(lab, rows + Hu.shape[0]) for lab, rows in self.rigid_groups2]
            known2 = segment_redundancy(H2, user, self._segment_modes[1])
            hard2 = independent_hard_rows(H2, rigid2 + user, "spatial", known=known2)
            G2 = gauge_rows(self.Q2, self.owner2, sp.vstack([Bw, H2], format="csr"), K, self._primary2)
            scale = KKT(self.AhtAh + BtB, sp.vstack([hard2.kept, G2], format="csr"))
        metric = metric_targets(soft, weights, hard, n)
        return SpatialFactors(shape, scale, Bw, BwT, H, hard1, hard2, G1, G1 @ self.p0, G2, metric), bw, h

    def solve(
        self, f: SpatialFactors, bw: Array, h: Array, *, previous: SpatialSolution | None = None
    ) -> SpatialSolution:
        """Both phases for the right-hand sides ``bw`` (weighted soft) and ``h`` (hard).

        With relative constraints, the solve is repeated with their rows'
        right-hand sides corrected to the metric targets measured on the
        last solution (Anderson-accelerated fixed point) until no correction
        changes by more than ``metric_tolerance`` metres, at most
        ``metric_iterations`` solves; the iterate with the smallest change is
        kept if they stop improving (see the module docstring).

        ``previous``: the solution of the previous update with the same
        factors.  Its corrections start the iteration (a drag moves them
        little), and if only a few right-hand-side entries changed, phase 1
        is updated through cached columns of its inverse (:meth:`_phase1`)
        instead of solved again.  Without it the iteration starts from the
        linear rows of equations 1 and 2, so the result depends only on the
        constraints; with it, on them to within ``metric_tolerance``.
        """
        M = f.metric
        if M is None:
            pbar, phat = self._solve_once(f, bw, h, previous)
            return SpatialSolution(pbar, phat, bw, h, 1, 0.0, np.zeros((0, 2)))
        start = None if previous is None else previous.corrections
        if start is None or start.shape != (M.n, 2):
            x, bw1, h1 = M.current(bw, h).reshape(-1), bw, h
        else:
            x = start.reshape(-1).copy()
            bw1, h1 = M.apply(bw, h, start)
        # redundant hard rows are checked on the kept iterate: a relative's rows are met only once corrected
        pbar, phat = self._solve_once(f, bw1, h1, previous, redundant=False)
        xs: list[Array] = []
        gs: list[Array] = []
        best = (np.inf, pbar, phat, bw1, h1, x)
        stale = 0
        it = 1
        diverged = False
        while True:
            g = M.correction(phat).reshape(-1)
            change = float(np.max(np.abs(g - x)))
            if not np.isfinite(change) or change > _DIVERGE * best[0]:
                diverged = True  # corrections that grow: the targets cannot be met (a conflict), keep the best
                break
            if change < best[0]:
                best, stale = (change, pbar, phat, bw1, h1, x), 0
            else:
                stale += 1
            if change <= self.metric_tolerance or it >= self.metric_iterations or stale >= _STALE:
                break
            xs, gs = (xs + [x])[-_ANDERSON:], (gs + [g])[-_ANDERSON:]
            if len(xs) == 1:
                x = g
            else:
                G_ = np.array(gs)
                R_ = G_ - np.array(xs)
                dR, dG = (R_[1:] - R_[:-1]).T, (G_[1:] - G_[:-1]).T
                gamma = np.linalg.lstsq(dR, R_[-1], rcond=None)[0]
                x = g - dG @ gamma
            bw1, h1 = M.apply(bw, h, x.reshape(-1, 2))
            it += 1
            try:
                pbar, phat = self._solve_once(f, bw1, h1, redundant=False)
            except ConstraintError:  # targets run out of numeric range: the iteration diverged
                diverged = True
                break
        change, pbar, phat, bw1, h1, x = best
        self._check_hard(f, pbar, phat, h1)
        if change > self.metric_tolerance and (diverged or stale >= _STALE):  # not merely out of iterations
            self._check_hard_relatives(f, phat, h1)
        return SpatialSolution(pbar, phat, bw1, h1, it, change, x.reshape(-1, 2), diverged)

    def _phase1(
        self, f: SpatialFactors, Btb: Array, hk: Array, previous: SpatialSolution | None, bw: Array, h: Array
    ) -> Array:
        """Phase 1: a solve, or, when few right-hand-side entries moved since ``previous``, an update.

        Phase 1 is linear in its right-hand side: ``pbar = K^-1 r``.  A drag
        moves a handful of entries ``r_S``, so ``pbar = pbar_prev + K^-1 E_S
        dr_S``; the columns ``K^-1 E_S`` are solved once per structure and
        support ``S`` and kept in ``f.influence`` (an O(frames) update instead
        of a back-substitution through the whole factorisation).
        """
        if (
            previous is not None
            and len(previous.bw) == len(bw)
            and len(previous.h) == len(h)
            # an update adds to the previous solution: from far away it would lose every digit of the new one
            and float(np.max(np.abs(previous.pbar), initial=0.0)) <= _UPDATE_RANGE * max(self.extent, 1.0)
        ):
            dsoft = np.flatnonzero(bw != previous.bw)
            dhard = np.flatnonzero(h != previous.h)
            keep_rows = np.flatnonzero(f.hard1.keep[: len(h)])
            if 0 < len(dsoft) + len(dhard) <= _INFLUENCE and np.all(np.isin(dhard, keep_rows)):
                key = (tuple(dsoft.tolist()), tuple(dhard.tolist()))
                cols = f.influence.get(key)
                n = 2 * self.layout.total
                if cols is None:
                    pos = np.searchsorted(keep_rows, dhard)  # kept hard rows come first in the constraint block
                    E = np.zeros((n + len(hk), len(dsoft) + len(dhard)))
                    if len(dsoft):
                        E[:n, : len(dsoft)] = f.BwT[:, dsoft].toarray()
                    E[n + pos, len(dsoft) + np.arange(len(dhard))] = 1.0
                    cols = np.ascontiguousarray(f.shape.lu.solve(E)[:n].T)  # one row per moved entry
                    if len(f.influence) >= _INFLUENCE_CACHE:
                        f.influence.pop(next(iter(f.influence)))
                    f.influence[key] = cols
                delta = np.concatenate([bw[dsoft] - previous.bw[dsoft], h[dhard] - previous.h[dhard]])
                pbar = previous.pbar.copy()
                for c, d in zip(cols, delta, strict=True):  # axpys: no threaded BLAS call for a (n x k) product
                    pbar += d * c
                return pbar
        return f.shape.solve(Btb, hk)

    def _solve_once(
        self,
        f: SpatialFactors,
        bw: Array,
        h: Array,
        previous: SpatialSolution | None = None,
        *,
        redundant: bool = True,
    ) -> tuple[Array, Array]:
        """Phase 1 and phase 2 solutions, each shape (2 * total,).

        ``redundant=False``: only the kept hard rows are checked (numeric
        range); the caller checks the left-out ones (:meth:`_check_hard`).
        """
        zr = np.zeros(self.R.shape[0])
        Btb = f.BwT @ bw if len(bw) else np.zeros(2 * self.layout.total)
        full1 = np.concatenate([h, zr])
        pbar = self._phase1(f, Btb, np.concatenate([full1[f.hard1.keep], f.g1]), previous, bw, h)

        def check(rows: HardRows, x: Array, full: Array) -> None:
            if redundant:
                rows.check(x, full, scale=self.extent)
            else:
                rows.check_range(x, full, self.extent)

        check(f.hard1, pbar, full1)
        if f.scale is None or f.hard2 is None:
            return pbar, pbar
        a, v = self._scale_terms(pbar)
        rhs = self.AhatT @ a
        r2 = v[self._rigid_step_rows].reshape(-1)
        full2 = np.concatenate([h, r2])
        phat = f.scale.solve(rhs + Btb, np.concatenate([full2[f.hard2.keep], f.G2 @ pbar]))
        check(f.hard2, phat, full2)
        return pbar, phat

    def _fought_by(self, f: SpatialFactors, B: sp.csr_matrix, skip: Sequence[int] = ()) -> list[Any]:
        """Labels of the hard rows touching ``B``'s unknowns if a combination of ``B``'s rows is one of theirs.

        ``B`` (2, n): a relative's two rows; ``skip``: its own rows in ``f.H``.
        Empty when the hard rows leave every combination of ``B`` free.
        """
        H = f.H.tocsr()
        cols = np.unique(B.indices)
        touching = np.setdiff1d(np.unique(f.H.tocsc()[:, cols].tocoo().row), np.asarray(skip, dtype=np.int64))
        if not len(touching):
            return []
        allcols = np.unique(np.concatenate([cols, H[touching].indices]))
        Hs = H[touching][:, allcols].toarray()
        Bs = B[:, allcols].toarray()
        if int(np.linalg.matrix_rank(np.vstack([Hs, Bs]))) >= int(np.linalg.matrix_rank(Hs)) + 2:
            return []
        label_of: dict[int, Any] = {}
        for lab, g in f.hard1.groups:
            for r in np.asarray(g).tolist():
                label_of[r] = lab
        labels: list[Any] = []
        for r in touching.tolist():
            lab = label_of.get(r)
            if lab is not None and not any(lab is x for x in labels):
                labels.append(lab)
        return labels

    def soft_conflicts(
        self, f: SpatialFactors, sol: SpatialSolution, *, tolerance: float | None = None, limit: int = 20
    ) -> list[tuple[int, float, tuple[Any, ...]]]:
        """Soft relative pairs missed by more than ``tolerance`` because hard rows fix what they ask for.

        A pair is in conflict when a combination of its two rows is a
        combination of the hard rows touching its unknowns (the pins on the
        positions and tangent it relates): no solution can reduce that part
        of its error, so the result is the least-squares compromise.

        Returns
        -------
        list of (index, error, labels)
            ``index``: the pair's x row in ``bw``; ``error``: its metric
            error in metres; ``labels``: the hard constraints it fights.  At
            most ``limit`` pairs, largest error first.
        """
        M = f.metric
        tol = self.metric_tolerance if tolerance is None else float(tolerance)
        if M is None or not M.soft.any():
            return []
        soft = np.flatnonzero(M.soft)
        idx = M.index[soft]
        vals = f.Bw @ sol.phat
        rows = np.stack([vals[idx], vals[idx + 1]], axis=1) / M.scale[soft, None]
        sub = dataclasses.replace(
            M,
            tangent=M.tangent[np.stack([2 * soft, 2 * soft + 1], 1).ravel()],
            coef=M.coef[soft],
            length=M.length[soft],
            linear=M.linear[soft],
            soft=M.soft[soft],
            index=idx,
            scale=M.scale[soft],
            direction=M.direction[soft],
        )
        err = sub.errors(sol.phat, rows)
        order = np.argsort(-err)
        out: list[tuple[int, float, tuple[Any, ...]]] = []
        for q in order[: 4 * limit]:
            if not err[q] > tol or len(out) >= limit:
                break
            labels = self._fought_by(f, f.Bw[[int(idx[q]), int(idx[q]) + 1]])
            if labels:
                out.append((int(idx[q]), float(err[q]), tuple(labels)))
        return out

    def _check_hard_relatives(self, f: SpatialFactors, phat: Array, h: Array) -> None:
        """Raise :class:`ConstraintError` if a hard relative is missed by more than ``_HARD_MISS`` tolerances.

        A hard relative the iteration cannot meet fights other hard
        constraints (pins on the positions and tangent it relates fix what
        it asks for): the error names it and the hard constraints sharing
        its unknowns.
        """
        M = f.metric
        assert M is not None
        hard = np.flatnonzero(~M.soft)
        if not len(hard):
            return
        idx = M.index[hard]
        vals = f.H @ phat
        rows = np.stack([vals[idx], vals[idx + 1]], axis=1)
        sub = dataclasses.replace(
            M,
            tangent=M.tangent[np.stack([2 * hard, 2 * hard + 1], 1).ravel()],
            coef=M.coef[hard],
            length=M.length[hard],
            linear=M.linear[hard],
            soft=M.soft[hard],
            index=idx,
            scale=M.scale[hard],
            direction=M.direction[hard],
        )
        err = sub.errors(phat, rows)
        q = int(np.argmax(err))
        if not err[q] > _HARD_MISS * self.metric_tolerance:
            return
        row = int(idx[q])
        # the pair's rows linearised about the undeformed path: what hard rows can fix of them to first order
        T = M.tangent[[2 * int(hard[q]), 2 * int(hard[q]) + 1]]
        t0 = T @ self.p0
        M_rest = (
            _metric_linearization(tuple(M.coef[hard[q]]), t0)[0] if np.linalg.norm(t0) > 1e-12 else M.linear[hard[q]]
        )
        B = (f.H[[row, row + 1]] + sp.csr_matrix(M.linear[hard[q]] - M_rest) @ T).tocsr()
        fought = self._fought_by(f, B, skip=(row, row + 1))
        if not fought:
            return  # no hard constraint fixes what it asks for: a slow iteration, noted by the result
        label_of = {r: lab for lab, g in f.hard1.groups for r in np.asarray(g).tolist()}
        own = label_of.get(row)
        others = [lab for lab in fought if lab is not own]
        labels = [own, *others]
        raise ConstraintError(
            f"The hard relative constraint {_label_text(own)} is missed by {err[q]:.3g} m: "
            + (
                "it fights " + " and ".join(_label_text(o) for o in others) + ", which fix what it asks for"
                if others
                else "its metric target cannot be reached"
            )
            + ". Make one of them soft (hard=False), move it, or remove it.",
            [lab[1] if isinstance(lab, tuple) else lab for lab in labels],
            [lab[0] for lab in labels if isinstance(lab, tuple)],
        )

    def _check_hard(self, f: SpatialFactors, pbar: Array, phat: Array, h: Array) -> None:
        """Check every hard row (the left-out redundant ones too) on a kept iterate (:meth:`HardRows.check`)."""
        f.hard1.check(pbar, np.concatenate([h, np.zeros(self.R.shape[0])]), scale=self.extent)
        if f.scale is not None and f.hard2 is not None:
            r2 = self._scale_terms(pbar)[1][self._rigid_step_rows].reshape(-1)
            f.hard2.check(phat, np.concatenate([h, r2]), scale=self.extent)

    def scale_rhs(self, pbar: Array) -> Array:
        """Right-hand side ``vbar_i - vbar_{i-1}`` of equation 7, shape (2 * n_interior,)."""
        return self._scale_terms(pbar)[0]

    def _scale_terms(self, pbar: Array) -> tuple[Array, Array]:
        P = pbar.reshape(-1, 2)
        v = P[1:] - P[:-1]
        ln = np.hypot(v[:, 0], v[:, 1])
        scale = np.divide(self._L0full, ln, out=np.ones_like(ln), where=ln > 1e-15)
        v *= scale[:, None]
        i = self._interior
        dv = v[i] - v[i - 1]  # the rows of frame g: vbar_g - vbar_{g-1}
        return dv.reshape(-1), v

    # ---------------------------------------------------------- energies
    def shape_energy(self, f: SpatialFactors, bw: Array, pbar: Array) -> float:
        """Phase-1 objective ``|A p|^2 + |B p - b|^2_W`` at ``pbar``."""
        r = self.A @ pbar
        s = f.Bw @ pbar - bw if len(bw) else np.zeros(0)
        return float(r @ r + s @ s)

    def scale_energy(self, f: SpatialFactors, bw: Array, pbar: Array, phat: Array) -> float:
        """Phase-2 objective ``|Ahat p - ahat|^2 + |B p - b|^2_W`` at ``phat``."""
        r = self.Ahat @ phat - self.scale_rhs(pbar)
        s = f.Bw @ phat - bw if len(bw) else np.zeros(0)
        return float(r @ r + s @ s)


# ------------------------------------------------------ tangent flipping
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
