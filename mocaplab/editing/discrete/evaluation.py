"""Scoring candidate transformations on subsampled paths (Kim et al. 2009, sections 5.2 and 6).

Algorithm 1 scores every candidate transformation by Laplacian editing of
the scene with that candidate applied, and equation 10,

    ``E = E_shape + E_scale + E_time + c_s sum_k |L_s(P'_k) - L_s(P_k)|
    + c_t sum_k |L_t(P'_k) - L_t(P_k)|``.

Following Algorithm 1 (``DeformationEnergy(P_c, P'_c, C)``), ``P`` is the
*transformed, undeformed* path and ``P'`` its deformed, time-warped version:
the last two terms measure how much continuous editing had to lengthen or
shorten the paths and durations, which a well chosen discrete transformation
avoids.

Subsampled paths (section 6)
----------------------------
Every ``subsample``-th frame (25 by default) is kept, plus the first and last
frames, every frame a constraint row reads (constraint frames and the
neighbours their tangents use), stationary-segment boundaries, and the seam
frames with their neighbours.  On them the three energies of section 4 are
minimised with non-uniform steps (time steps span several frames and are
weighted by ``1/sqrt(m)`` so a uniform warp costs the same as on all frames),
hard constraints and rigid stationary segments are heavily weighted rows
(``PENALTY``), and modes no constraint determines are held by a tiny
regulariser (``EPS``).  The length change is measured on the full path: each
subsampled chord's change scales the arc length of the frames it spans.
Relative constraints are scored in metres: their rows are the metric
constraint linearised about the current full solve (``deformed``).

Parts, blocks and coupling
--------------------------
Each untransformed character path and each candidate's transformed path is
a *part* (:class:`Parts`).  A part's own rows (its Laplacian rows and the
constraint rows on that character alone that fit its band) form one banded
least-squares block per phase (:class:`PhaseBlocks`); all blocks are solved
in one LAPACK call (they are the blocks of one block-diagonal banded
matrix).  The remaining rows (between characters, or too long for a band)
are *coupled* (:class:`Coupling`) and added back by the Woodbury identity:
with ``y = N^-1 b`` and ``Z = N^-1 U^T`` per part, the scene's solution is
``x = y + Z w`` where ``S w = c - U y`` and ``S = I + U Z`` (one row and
column per coupled row).

Cost linear in the characters and in the clip length
----------------------------------------------------
A *variant* is the scene with one candidate applied (variant 0: none).  A
candidate of character ``k`` changes only ``k``'s block, and only the
coupled rows touching ``k`` (``J``, a handful) see it.  So per update:

1. the base scene's coupling is assembled and factorised once
   (``S``, ``X = S^-1``, ``w0``), the blocks of all parts solved once;
2. per candidate, ``S`` changes by ``D = U_c Z_c - U_k Z_k`` on ``J``
   only, and the right-hand side by a vector ``dr`` on ``J`` (plus, in
   phase 2, on the rows of the characters whose phase-1 solution moved):
   the variant's multipliers are ``w0 + X dr - X_J (I + D X_JJ)^-1 D (w0 +
   X dr)_J`` (Woodbury again, a ``|J| x |J|`` solve; ``X dr`` and ``X_J
   beta`` are sparse-times-dense products over the few non-zero entries).
   The coupled rows' residuals are the multipliers themselves (``U x - c =
   -w``), so their energy needs no part's move;
3. the candidate's own part is solved from them, and every other part
   ``k'`` moves by ``dx = Z_k' dw``, kept in that factored form
   (:class:`PhaseSolution`): ``dx`` is expanded, and the part's energies
   re-evaluated, only where it can exceed ``FAR`` (1e-3 m or s: a bound
   ``|Z_k'| |dw|`` picks the pairs, their moves decide); elsewhere the base
   scene's values stand.  The length and duration terms are summed over
   every part of every variant (:func:`_sum_over_parts`), by their
   gradient through ``Z_k'`` (``|J|`` numbers per pair, whatever the clip
   length) wherever a bound on the first-order error is below ``EXACT``
   (1e-12 m or s per part), exactly elsewhere.  A change propagates
   through each link of constraints with a factor of about 0.1 in the
   relay scenes (each character has its own pins), so only the few
   characters around the candidate are expanded.

No array is (variants x characters x unknowns): memory is ``O(parts x
frames x |J|)`` plus ``O(variants x characters x |J|)`` and the ``g x g``
coupling matrix (``g`` coupled rows; 0.8 MB for the 78-character relay);
time is linear in the characters and the frames except the inverse ``X``
(``O(g^3)``, about 9 ms for the relay's 308 rows) and the dense ``O(variants
x g)`` multiplier updates, small at these sizes (``benchmarks/
bench_discrete.py`` prints the curves and their slopes).  A candidate's energy does not depend
on which others are evaluated with it; with ``far=0`` the evaluation is
exact (every part re-solved), which the tests compare with.  Phase 2's
right-hand side (equation 7) is recomputed exactly for every part that
moved.

Longer than 800 lines because the evaluation of every candidate transformation is one vectorised pipeline over shared per-candidate arrays (spliced paths, sparse rows, the linearised solve, the cost terms); its stages read each other's intermediate arrays.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Sequence
from types import MappingProxyType
from typing import Any, cast

import numpy as np
import scipy.linalg as sla
import scipy.sparse as sp
from numpy.typing import NDArray
from scipy.linalg.lapack import dpbsv as _lapack_pbsv

from ..constraints import SPATIAL, TEMPORAL
from ..laplacian import spatial_rows
from ..lsq import Layout
from ..paths import MotionPath
from ..timewarp import temporal_rows
from .transformations import GraphArrays, Track, Transformation, _rot2

__all__ = [
    "SubsampledScene", "Parts", "Coupling", "PhaseBlocks", "LocalRows", "Systems", "PhaseSolution", "PartTerms",
    "PENALTY", "EPS", "FAR", "EXACT",
]  # fmt: skip

Array = NDArray[np.float64]
IntArray = NDArray[np.int64]

PENALTY = 1e4  # weight of hard constraints and rigid rows in the evaluation (times the largest soft weight)
EPS = 1e-8  # regulariser of the free modes
FAR = 1e-3  # metres or seconds: a part that a candidate moves less than this keeps its base energies
EXACT = 1e-12  # metres or seconds: a length or duration term's largest first-order error in one part
_BAND = MappingProxyType({2: 5, 1: 1})  # bandwidth (in unknowns) of the path rows for 2D (space) and 1D (time)
_CHUNK = 2048  # part-variant pairs whose moves are expanded at a time
_DENSE = 20_000  # entries below which a sparse product is written out dense (_sparse_times, _products)
_SEAM = np.array([-2, -1, 0, 1], dtype=np.int64)  # frames kept around each seam
_SEAM.flags.writeable = False


class _Tangents:
    """``row(k, i)`` of each path's tangent operator (what :func:`spatial_rows` needs)."""

    def __init__(self, paths: Sequence[MotionPath]) -> None:
        self.paths = paths
        self.ops: dict[int, sp.csr_matrix] = {}

    def row(self, k: int, i: int) -> tuple[IntArray, Array]:
        if k not in self.ops:
            self.ops[k] = self.paths[k].tangent_operator()
        op = self.ops[k]
        s, e = op.indptr[i], op.indptr[i + 1]
        return op.indices[s:e].astype(np.int64), op.data[s:e].astype(float)


@dataclasses.dataclass(frozen=True)
class _Rows:
    """Constraint rows as fixed-width entry arrays ``(R, W)`` (padding has value 0)."""

    char: IntArray
    frame: IntArray
    coord: IntArray
    val: Array  # weighted by sqrt(weight) (or sqrt(penalty) for hard rows)
    rhs: Array  # (R,), weighted too
    soft: NDArray[np.bool_]  # (R,)
    intra: NDArray[np.bool_]  # (R,) every entry on one character

    @property
    def n(self) -> int:
        return len(self.rhs)


def _compile(
    constraints: Sequence[Any], kinds: tuple[type, ...], make: Any, layout: Layout, dim: int, penalty: float
) -> _Rows:
    off = layout.offsets
    cols_l: list[IntArray] = []
    vals_l: list[Array] = []
    rhs, soft = [], []
    for c_ in constraints:
        if not isinstance(c_, kinds):
            continue
        c: Any = c_
        rows = make(c)
        w = math.sqrt(penalty) if c.hard else math.sqrt(c.weight)
        for cc, vv, bb in zip(rows.cols, rows.vals, rows.rhs, strict=True):
            cols_l.append(np.asarray(cc, dtype=np.int64))
            vals_l.append(np.asarray(vv, dtype=float) * w)
            rhs.append(float(bb) * w)
            soft.append(not c.hard)
    R = len(rhs)
    W = max([len(c) for c in cols_l], default=1)
    cols = np.zeros((R, W), dtype=np.int64)
    vals = np.zeros((R, W))
    for r, (cc, vv) in enumerate(zip(cols_l, vals_l, strict=True)):
        cols[r, : len(cc)] = cc
        cols[r, len(cc) :] = cc[0]
        vals[r, : len(vv)] = vv
    g = cols // dim
    ch = (np.searchsorted(off, g, side="right") - 1).astype(np.int64)
    return _Rows(
        ch,
        (g - off[ch]).astype(np.int64),
        (cols % dim).astype(np.int64),
        vals,
        np.asarray(rhs, dtype=float),
        np.asarray(soft, dtype=bool),
        np.all(ch == ch[:, :1], axis=1) if R else np.zeros(0, bool),
    )


@dataclasses.dataclass(frozen=True)
class RowTable:
    """Constraint rows of one domain with an all-zero padding row appended (index ``R``).

    ``intra_of[k]`` lists the rows on character ``k`` alone (padded with
    ``R``); ``cross`` the rows linking characters.
    """

    char: IntArray  # (R + 1, W)
    frame: IntArray
    coord: IntArray
    val: Array
    rhs: Array  # (R + 1,)
    soft: NDArray[np.bool_]
    intra: NDArray[np.bool_]
    intra_of: IntArray  # (K, R_k)
    cross: IntArray
    dim: int

    @property
    def band(self) -> int:
        return _BAND[self.dim]

    @classmethod
    def of(cls, rows: _Rows, K: int, dim: int) -> RowTable:
        R = rows.n

        def ext(a: NDArray[Any], v: Any) -> NDArray[Any]:
            return np.concatenate([a, np.full((1,) + a.shape[1:], v, dtype=a.dtype)])

        touch = np.any(rows.val != 0, axis=1)
        owner = rows.char[:, 0] if R else np.zeros(0, np.int64)
        lists = [np.flatnonzero(rows.intra & touch & (owner == k)) for k in range(K)]
        intra_of = np.full((K, max([len(x) for x in lists], default=0)), R, dtype=np.int64)
        for k, x in enumerate(lists):
            intra_of[k, : len(x)] = x
        return cls(
            ext(rows.char, 0),
            ext(rows.frame, 0),
            ext(rows.coord, 0),
            ext(rows.val, 0.0),
            ext(rows.rhs, 0.0),
            ext(rows.soft, False),
            ext(rows.intra, True),
            intra_of,
            np.flatnonzero(~rows.intra & touch).astype(np.int64),
            dim,
        )


def _fmap(f: IntArray, a: IntArray, b: IntArray, L: IntArray) -> IntArray:
    """Current frames ``f`` (P, ...) -> frames after replacing ``[a, b)`` by ``L`` frames (per part, (P,)).

    Removed frames go to the nearest side of the seam.
    """
    sh = (len(a),) + (1,) * (f.ndim - 1)
    a, b, L = a.reshape(sh), b.reshape(sh), L.reshape(sh)
    inner = np.where(f - a < b - f, a, a + L - 1)
    return np.where(f < a, f, np.where(f >= b, f + L - (b - a), inner))


@dataclasses.dataclass(frozen=True)
class Parts:
    """Subsampled paths for the evaluation, padded to a common number ``n`` of kept frames.

    Part ``q`` is character ``char[q]``'s path with its current frames
    ``[a, b)`` replaced by ``L`` new frames (the untransformed path has
    ``a = b = F`` and ``L = 0``).
    """

    char: IntArray  # (P,)
    a: IntArray
    b: IntArray
    L: IntArray
    frames: IntArray  # (P, n) kept frames (sorted), padded with a frame beyond every path
    nv: IntArray  # (P,) number of kept frames
    X: Array  # (P, n, 2) their ground positions (padding repeats the last)
    arc: Array  # (P, n - 1) arc length of the full path between successive kept frames
    rpt: NDArray[np.bool_]  # (P, n) kept frame strictly inside a stationary segment
    rst: NDArray[np.bool_]  # (P, n - 1) both ends of the step in one segment
    nfr: IntArray  # (P,) full frame count
    dt: Array  # (P,)
    start: Array  # (P,)


def _bsearch(frames: IntArray, nvalid: IntArray, queries: IntArray) -> IntArray:
    """Per-row ``searchsorted(frames[i], queries[i])`` clipped to the valid entries; shapes (c, n), (c,), (c, ...)."""
    c, n = frames.shape
    big = int(frames.max(initial=0)) + 2
    shape = (c,) + (1,) * (queries.ndim - 1)
    off = np.arange(c, dtype=np.int64) * big
    idx = np.searchsorted((frames + off[:, None]).ravel(), queries + off.reshape(shape))
    idx = idx - (np.arange(c, dtype=np.int64) * n).reshape(shape)
    return np.clip(idx, 0, (nvalid - 1).reshape(shape))


def _gather(x: Array, cols: IntArray) -> Array:
    """``x[i, cols[i]]`` for a batch: x (c, n), cols (c or 1, ...)."""
    c = x.shape[0]
    if c == 0:
        return np.zeros((0,) + cols.shape[1:])
    if cols.shape[0] == 1:  # the same columns for every path
        return x[:, cols[0]]
    flat = cols.reshape(c, -1)
    return np.take_along_axis(x, flat, axis=1).reshape(cols.shape)


def _band(c: int, n: int, u: int, cols: IntArray, vals: Array) -> Array:
    """Batched normal matrices ``sum_rows r r^T`` in LAPACK upper band storage (c, u + 1, n).

    Rows are given as entry arrays: columns ``cols`` (c or 1, R, W) and
    values ``vals`` (c, R, W).  Every row's columns must lie within ``u`` of
    each other.  Columns shared by every path (``cols.shape[0] == 1``, the
    path rows) are turned into storage positions once.
    """
    W = cols.shape[2]
    if cols.shape[1] == 0 or W == 0:
        return np.zeros((c, u + 1, n))
    v = vals[:, :, :, None] * vals[:, :, None, :]
    c1 = cols[:, :, :, None]
    c2 = cols[:, :, None, :]
    pos = (u + c1 - c2) * n + c2
    keep = c1 <= c2
    if cols.shape[0] == 1:
        idx = (np.arange(c, dtype=np.int64)[:, None] * ((u + 1) * n) + pos[0][keep[0]][None, :]).ravel()
        val = v[:, keep[0]].ravel()
    else:
        keep = np.broadcast_to(keep, v.shape)
        idx = (np.arange(c, dtype=np.int64)[:, None, None, None] * ((u + 1) * n) + pos)[keep]
        val = v[keep]
    return np.bincount(idx, val, minlength=c * (u + 1) * n).astype(float).reshape(c, u + 1, n)


def _pbsv(ab: Array, b: Array) -> Array:
    """Solve one banded SPD system (LAPACK ``pbsv``: an unblocked banded Cholesky, fast for small bands)."""
    _, x, info = _lapack_pbsv(ab, b)
    if info != 0:  # pragma: no cover - the regulariser keeps the matrices definite
        raise np.linalg.LinAlgError(f"banded Cholesky failed (info={info})")
    return x


def _spd_solve(ab: Array, b: Array) -> Array:
    """Batched banded SPD solves: ab (c, u + 1, n) upper band storage, b (c, n, k) -> (c, n, k).

    The ``c`` matrices are laid side by side as the blocks of one
    block-diagonal matrix, which is banded with the same bandwidth (each
    block's band entries reaching before its first column are zero), so
    one LAPACK ``pbsv`` call solves them all: per-call overhead, not
    arithmetic, is the cost at these sizes.  Each block is factorised
    exactly as it would be alone (the zero couplings contribute exact
    zeros), so a path's solution does not depend on the others in the batch.
    """
    c, u1, n = ab.shape
    k = b.shape[2]
    if k == 0 or c == 0:
        return np.zeros((c, n, k))
    big = np.asfortranarray(np.transpose(ab, (1, 0, 2)).reshape(u1, c * n))
    return _pbsv(big, b.reshape(c * n, k)).reshape(c, n, k)


def _fits(cols: IntArray, vals: Array, u: int) -> NDArray[np.bool_]:
    """Rows (..., W) whose non-zero columns fit in a band of width ``u``."""
    if cols.shape[-1] == 0:
        return np.ones(cols.shape[:-1], bool)
    big = np.where(vals != 0, cols, cols[..., :1])
    return big.max(axis=-1) - big.min(axis=-1) <= u


def _rhs(n: int, cols: IntArray, vals: Array, rhs: Array) -> Array:
    """Batched ``M^T rhs``: cols/vals (c, R, W), rhs (c, R) -> (c, n)."""
    w = vals * rhs[:, :, None]
    c = max(w.shape[0], cols.shape[0]) if min(w.shape[0], cols.shape[0]) else w.shape[0]
    if c == 0:
        return np.zeros((0, n))
    w = np.broadcast_to(w, (c,) + w.shape[1:])
    idx = np.broadcast_to(np.arange(c, dtype=np.int64)[:, None, None] * n + cols, w.shape)
    return np.bincount(idx.ravel(), w.ravel(), minlength=c * n).astype(float).reshape(c, n)


def _res(cols: IntArray, vals: Array, rhs: Array, x: Array) -> Array:
    """Batched residuals ``M x - rhs``: (c, R)."""
    return np.sum(vals * _gather(x, cols), axis=-1) - rhs


# ---------------------------------------------------------------- structures
@dataclasses.dataclass(frozen=True)
class LocalRows:
    """Each part's own constraint rows of one domain that fit its band (padded entry arrays).

    Attributes
    ----------
    cols : ndarray of int, shape (P, R, W)
        Unknowns (within the part) of each row's entries.
    vals : ndarray, shape (P, R, W)
        Weighted values (rows that do not fit are emptied: all zero).
    rhs : ndarray, shape (P, R)
    soft : ndarray of bool, shape (P, R)
        Soft rows (their residuals are energy; hard ones are penalties).
    """

    cols: IntArray
    vals: Array
    rhs: Array
    soft: NDArray[np.bool_]


@dataclasses.dataclass(frozen=True)
class Coupling:
    """The rows of one domain added back by the Woodbury identity (see the module docstring).

    Attributes
    ----------
    rows : ndarray of int, shape (g,)
        Their ids in the domain's :class:`RowTable`: rows between characters
        and rows too long for some part's band.
    rhs : ndarray, shape (g,)
    soft : ndarray of bool, shape (g,)
    of_char : ndarray of int, shape (K, gk)
        For each character, the coupled rows (indices ``0 .. g-1``) touching
        it, padded with ``g`` (a dummy row).
    U : ndarray, shape (P, gk, m)
        Each part's entries in the coupled rows of its character (zero for a
        row the part holds in its own block, or does not touch).
    held : ndarray of bool, shape (P, gk)
        Which of those rows the part takes part in.
    """

    rows: IntArray
    rhs: Array
    soft: NDArray[np.bool_]
    of_char: IntArray
    U: Array
    held: NDArray[np.bool_]

    @property
    def g(self) -> int:
        return len(self.rows)


@dataclasses.dataclass(frozen=True)
class PhaseBlocks:
    """One banded least-squares block per part for one phase (shape, scale or time).

    Attributes
    ----------
    normal : ndarray, shape (P, u + 1, m)
        The blocks' normal matrices in LAPACK upper band storage.
    Z : ndarray, shape (P, m, gk)
        ``normal^-1 U^T`` for the part's coupled rows.
    y : ndarray, shape (P, m), or None
        ``normal^-1 b`` (None for phase 2, whose right-hand side comes from phase 1).
    """

    normal: Array
    Z: Array
    y: Array | None


@dataclasses.dataclass(frozen=True)
class Systems:
    """Everything about the parts that does not depend on the other characters.

    Attributes
    ----------
    n : int
        Kept frames per part (padded); space has ``m = 2 n`` unknowns.
    valid, vstep : ndarray of bool, shapes (P, n), (P, n - 1)
        Real (not padding) frames and steps.
    span, arc : ndarray, shape (P, n - 1)
        Frames spanned by each kept step, and the full path's arc length there.
    last, nfr, dt : ndarray, shape (P,)
        Index of the last kept frame, full frame count, frame time.
    space, time : Coupling
    s_loc, t_loc : LocalRows
    lap_cols, lap_vals, lap_energy
        Equation-3 rows: shared columns (1, R, 6), per-part weighted values
        (P, R, 6) and which rows are energy (not rigid penalties) (P, R).
    sec_cols, sec_vals, sec_w
        Equation-7 rows on per-frame velocities (1, R, 3), (P, R, 3) and
        their weights (P, n - 2).
    rig_cols, rig_vals, rig_w
        Phase-2 rigid-step penalty rows (1, R, 2), (P, R, 2), (P, R).
    bs : ndarray, shape (P, m)
        The local constraint rows' part of the spatial right-hand sides.
    L0 : ndarray, shape (P, n - 1)
        Undeformed chord lengths between kept frames.
    tim_cols, tim_vals, tim_rhs
        Time-step rows (1, n - 1, 2), (P, n - 1, 2), (P, n - 1).
    shape, scale, time : PhaseBlocks
    """

    n: int
    valid: NDArray[np.bool_]
    vstep: NDArray[np.bool_]
    span: Array
    arc: Array
    last: IntArray
    nfr: Array
    dt: Array
    space: Coupling
    time: Coupling
    s_loc: LocalRows
    t_loc: LocalRows
    lap_cols: IntArray
    lap_vals: Array
    lap_energy: NDArray[np.bool_]
    sec_cols: IntArray
    sec_vals: Array
    sec_w: Array
    rig_cols: IntArray
    rig_vals: Array
    rig_w: Array
    bs: Array
    L0: Array
    tim_cols: IntArray
    tim_vals: Array
    tim_rhs: Array
    shape: PhaseBlocks
    scale: PhaseBlocks
    time_blocks: PhaseBlocks


@dataclasses.dataclass(frozen=True)
class PhaseSolution:
    """One phase's solutions for the base scene and every variant.

    The other parts' moves are kept in factored form, ``dx = Zr dw`` per part
    and variant, and expanded (:meth:`moves`) only for the pairs that need
    them: a (K, C, m) array of every move is never built.

    Attributes
    ----------
    base : ndarray, shape (K, m)
        The untransformed scene's part solutions.
    cand : ndarray, shape (C, m)
        Each candidate's own part, in its variant.
    moved_v, moved_k : ndarray of int, shape (M,)
        Variant (1 .. C) and character of every other part the candidate
        moved (beyond ``far``).
    moved : ndarray, shape (M, m)
        Their solutions.
    residual : ndarray, shape (1 + C, g)
        Coupled rows' residuals ``U x - c`` per variant.
    dw : ndarray, shape (K, C, gk)
        How each variant changes the multipliers of each base part's coupled
        rows (0 for the candidate's own character).
    Zr : ndarray, shape (K, m, gk)
        The base parts' ``Z``, less the translation for parts whose own
        energies ignore it (the length and duration terms ignore it too).
    bound : ndarray, shape (K, C)
        An upper bound of ``max |dx|`` per unknown (the smaller of the
        largest row norm of ``Zr`` times ``|dw|`` and the sum of each
        column's largest entry times ``|dw_j|``; plus the shift, if any;
        0 for the candidate's own character).
    shift_v, shift_k, shift : ndarray
        Moves not of the form ``Zr dw`` (phase 2: the parts whose phase-1
        solution moved, ``y`` changed): variant (1 .. C), character and the
        move (S, m), added by :meth:`moves`.
    """

    base: Array
    cand: Array
    moved_v: IntArray
    moved_k: IntArray
    moved: Array
    residual: Array
    dw: Array
    Zr: Array
    bound: Array
    shift_v: IntArray
    shift_k: IntArray
    shift: Array

    def moves(self, k: IntArray, c: IntArray) -> Array:
        """``dx`` of base parts ``k`` in variants ``c + 1`` (0-based candidates), shape (N, m): how far each moves."""
        dx = _products(self.Zr, k, self.dw[k, c])
        if len(self.shift_v) and len(k):
            K = self.Zr.shape[0]
            keys = (self.shift_v - 1) * K + self.shift_k
            by = np.argsort(keys)
            want = c * K + k
            j = np.clip(np.searchsorted(keys[by], want), 0, len(keys) - 1)
            hit = keys[by][j] == want
            dx[hit] += self.shift[by[j[hit]]]
        return dx


def _sparse_times(rows: IntArray, cols: IntArray, vals: Array, n: int, X: Array) -> Array:
    """``M @ X`` for the sparse ``M`` (n, len(X)) with entries ``vals`` at ``(rows, cols)`` (duplicates add up).

    ``M`` is written out when it is small (below :data:`_DENSE` entries, where a sparse matrix's
    set-up costs more than the product), kept sparse otherwise (its rows hold a few entries each).
    """
    g = X.shape[0]
    if n * g <= _DENSE:
        return np.bincount(rows * g + cols, vals, minlength=n * g).reshape(n, g) @ X
    order = np.argsort(rows, kind="stable")  # the rows come in a few sorted runs
    indptr = np.zeros(n + 1, dtype=np.int64)
    np.cumsum(np.bincount(rows, minlength=n), out=indptr[1:])
    return np.asarray(sp.csr_matrix((vals[order], cols[order], indptr), shape=(n, X.shape[0])) @ X)


def _products(A: Array, k: IntArray, w: Array) -> Array:
    """``A[k[i]] @ w[i]`` for every ``i``: A (K, m, r), w (N, r) -> (N, m).

    One matrix product per distinct ``k``: ``A[k]`` would copy an (m, r)
    matrix per row, the memory of a dense (N, m, r) array (that copy is
    taken only when it is small, below :data:`_DENSE` entries).
    """
    if len(k) * A.shape[1] * A.shape[2] <= _DENSE:
        return _mv(A[k], w)
    out = np.zeros((len(k), A.shape[1]))
    order = np.argsort(k, kind="stable")
    edges = np.searchsorted(k[order], np.arange(A.shape[0] + 1))
    for q in np.flatnonzero(np.diff(edges)):
        i = order[edges[q] : edges[q + 1]]
        out[i] = w[i] @ A[q].T
    return out


def _translation_invariant(loc: LocalRows, K: int, dim: int) -> NDArray[np.bool_]:
    """Base parts (K,) whose own constraint rows all ignore a translation (each coordinate's coefficients sum to 0)."""
    vals, cols = loc.vals[:K], loc.cols[:K]
    if vals.shape[1] == 0:
        return np.ones(K, bool)
    ok = np.ones(K, bool)
    for c in range(dim):
        sums = np.sum(np.where(cols % dim == c, vals, 0.0), axis=2)
        ok &= np.all(np.abs(sums) <= 1e-12 * np.maximum(np.abs(vals).sum(axis=2), 1e-300), axis=1)
    return ok


def _mv(A: Array, x: Array) -> Array:
    """Batched matrix-vector products ``A[i] @ x[i]``: (N, r, c), (N, c) -> (N, r)."""
    return (A @ x[..., None])[..., 0]


def _add_at(a: Array, index: tuple[Any, ...] | IntArray, values: Any) -> None:
    """``_add_at(a, index, values)`` through one ``bincount`` (``np.add.at`` is slow per element)."""
    idx = np.ravel_multi_index(tuple(np.broadcast_arrays(*index)) if isinstance(index, tuple) else (index,), a.shape)
    vals = np.broadcast_to(values, idx.shape)
    a += np.bincount(idx.ravel(), vals.ravel().astype(float), minlength=a.size).reshape(a.shape)


def _couple(
    cp: Coupling,
    y: Array,
    Z: Array,
    K: int,
    kc: IntArray,
    *,
    far: float,
    extra: tuple[IntArray, IntArray, Array] | None = None,
    dim: int = 1,
    valid: NDArray[np.bool_] | None = None,
    invariant: NDArray[np.bool_] | None = None,
) -> PhaseSolution:
    """Solve one phase for the base scene and every variant (module docstring, steps 1-3).

    ``y`` (P, m) and ``Z`` (P, m, gk) are the parts' block solutions (base
    parts first, then one per candidate of character ``kc``).  ``extra =
    (v, k, y_new)`` gives base parts whose ``y`` differs in variant ``v``
    (phase 2: their phase-1 solution moved).  ``dim`` unknowns per frame,
    ``valid`` (K, m / dim) the base parts' real frames, ``invariant`` (K,)
    the base parts whose own energies ignore a translation.
    """
    P, m = y.shape
    C = P - K
    g = cp.g
    ci = np.arange(C)
    ev, ek, ey = extra if extra is not None else (np.zeros(0, np.int64), np.zeros(0, np.int64), np.zeros((0, m)))
    shift = ey - y[ek]
    if g == 0:
        bound = np.zeros((K, C))
        if len(ev):
            bound[ek, ev - 1] = np.abs(shift).max(axis=1, initial=0.0)
        return PhaseSolution(
            y[:K].copy(), y[K:].copy(), ev, ek, ey.copy(), np.zeros((1 + C, 0)),
            np.zeros((K, C, 0)), np.zeros((K, m, 0)), bound, ev, ek, shift,
        )  # fmt: skip
    G = cp.of_char  # (K, gk), padded with g
    U, held = cp.U, cp.held
    gk = G.shape[1]
    UZ = U @ Z  # (P, gk, gk)
    Uy = _mv(U, y)
    # 1. the base scene: S = I + sum U Z, w0 = S^-1 (c - U y)
    S = np.eye(g + 1)
    _add_at(S, (G[:, :, None], G[:, None, :]), UZ[:K])
    S[g, :] = 0.0
    S[:, g] = 0.0
    S[g, g] = 1.0
    cnt = np.zeros(g + 1)
    _add_at(cnt, G, held[:K])
    cnt[g] = 0.0
    crhs = np.append(cp.rhs, 0.0)
    c0 = np.where(cnt > 0, crhs, 0.0)
    r0 = c0.copy()
    _add_at(r0, G, -Uy[:K])
    r0[g] = 0.0
    X = sla.cho_solve(sla.cho_factor(S), np.eye(g + 1))
    w0 = X @ r0
    xb = y[:K] + _mv(Z[:K], w0[G])
    # the coupled rows' residuals are the multipliers: S w = c - U y gives U x - c = (S - I) w - (c - U y) = -w
    if C == 0:
        return PhaseSolution(
            xb, np.zeros((0, m)), ev, ek, np.zeros((0, m)), -w0[None, :g],
            np.zeros((K, 0, gk)), Z[:K], np.zeros((K, 0)), ev, ek, shift,
        )  # fmt: skip
    # 2. per candidate: S + D on J = G[kc], right-hand side changes dR (|J| entries, and the
    # rows of the parts whose y changed): u = X dR is a sparse-times-dense product
    J = G[kc]  # (C, gk)
    D = UZ[K:] - UZ[kc]
    heldv = held[K:] | ((cnt[J] - held[kc]) > 0)
    dc = np.where(heldv, crhs[J], 0.0) - c0[J]
    rows = np.concatenate([np.repeat(ci, gk), np.repeat(ev - 1, gk)])
    cols = np.concatenate([J.ravel(), G[ek].ravel()])
    vals = np.concatenate([(dc - (Uy[K:] - Uy[kc])).ravel(), -_products(U[:K], ek, shift).ravel()])
    u = _sparse_times(rows, cols, vals, C, X)  # X is symmetric: u = dR X
    u[:, g] = 0.0
    XJJ = X[J[:, :, None], J[:, None, :]]  # (C, gk, gk)
    A = np.eye(gk)[None] + D @ XJJ
    beta = np.linalg.solve(A, (D @ (w0[J] + u[ci[:, None], J])[..., None]))[..., 0]
    # dw = u - X[:, J] beta: the |J| columns of X, weighted (sparse times dense again)
    dw = u - _sparse_times(np.repeat(ci, gk), J.ravel(), beta.ravel(), C, X)
    dw[:, g] = 0.0
    wv = w0[None] + dw
    xc = y[K:] + _mv(Z[K:], wv[ci[:, None], J])
    residual = -np.concatenate([w0[None], wv])[:, :g]
    # 3. the other parts.  A part's own energies and the length/duration terms ignore a translation
    # when its own rows do (no absolute pin or time; `invariant`), so its move is measured with the
    # translation taken out of Z (Zr: each column less its mean over the part's frames, per coordinate)
    dwG = np.swapaxes(dw[:, G], 0, 1)  # (K, C, gk)
    dwG[kc, ci] = 0.0  # the candidate's character: its part is replaced, not moved
    Zr = Z[:K]
    if invariant is not None and valid is not None and invariant.any():
        Zr = Zr.copy()
        ii = np.flatnonzero(invariant)
        z = Zr[ii].reshape(len(ii), -1, dim, gk)
        w = valid[ii][:, :, None, None]
        mean = np.sum(z * w, axis=1, keepdims=True) / np.maximum(np.sum(w, axis=1, keepdims=True), 1.0)
        Zr[ii] = np.where(w, z - mean, 0.0).reshape(len(ii), -1, gk)
    # |Zr dw| per unknown, bounded twice: by the largest row norm times |dw| (Cauchy-Schwarz), and by
    # each column's largest entry times |dw_j| (tighter when the columns' scales differ: hard rows)
    zrow = np.sqrt(np.max(np.sum(Zr * Zr, axis=2), axis=1, initial=0.0))  # (K,)
    zcol = np.max(np.abs(Zr), axis=1, initial=0.0)  # (K, gk)
    bound = np.minimum(zrow[:, None] * np.linalg.norm(dwG, axis=2), np.einsum("kcg,kg->kc", np.abs(dwG), zcol))
    bound *= 1.0 + 1e-9
    if len(ev):
        bound[ek, ev - 1] += np.abs(shift).max(axis=1, initial=0.0)
    # the parts' own energies are re-evaluated only where a part moves by more than `far`: the bound
    # picks the pairs that can, their moves decide (padding frames do not move: their Z rows are 0)
    near = bound.T > far  # (C, K)
    if len(ev):
        near[ev - 1, ek] = True
    vi, ki = np.nonzero(near)
    sol = PhaseSolution(xb, xc, ev, ek, ey, residual, dwG, Zr, bound, ev, ek, shift)
    sig = np.abs(sol.moves(ki, vi)).max(axis=1, initial=0.0) > far
    if len(ev):
        forced = np.zeros((C, K), bool)
        forced[ev - 1, ek] = True
        sig |= forced[vi, ki]
    vi, ki = vi[sig], ki[sig]
    xch = xb[ki] + _products(Z[:K], ki, dw[vi[:, None], G[ki]])
    if len(ev):
        pos = np.full((C, K), -1, dtype=np.int64)
        pos[vi, ki] = np.arange(len(vi))
        xch[pos[ev - 1, ek]] += shift
    return dataclasses.replace(sol, moved_v=(vi + 1).astype(np.int64), moved_k=ki.astype(np.int64), moved=xch)


class PartTerms:
    """Each part's own terms of equation 10 on its subsampled path, for parts ``q`` of a :class:`Systems`.

    Every method takes part indices ``q`` (N,) and those parts' solutions
    (N, m) (or (N, n) in time) and returns one number per part, or per-part
    arrays.  ``shape``, ``scale`` and ``time`` are the energies of the three
    phases (their own Laplacian, equation-7 or time-step rows and their soft
    constraint rows); ``length_change`` and ``duration_change`` are signed:
    the terms ``c_s |...|`` and ``c_t |...|`` take their absolute values.
    """

    def __init__(self, S: Systems) -> None:
        self.S = S
        self.n = S.n
        self.m = 2 * S.n

    @staticmethod
    def _soft(loc: LocalRows, q: IntArray, x: Array) -> Array:
        if not loc.cols.shape[1]:
            return np.zeros(len(q))
        r = _res(loc.cols[q], loc.vals[q], loc.rhs[q], x)
        return np.sum(np.where(loc.soft[q], r, 0.0) ** 2, axis=1)

    def shape(self, q: IntArray, x: Array) -> Array:
        """Phase 1: equation-3 residuals (rigid rows excluded) and soft constraint rows, squared."""
        S = self.S
        lr = np.sum(S.lap_vals[q] * _gather(x, S.lap_cols), axis=-1)
        return np.sum(np.where(S.lap_energy[q], lr, 0.0) ** 2, axis=1) + self._soft(S.s_loc, q, x)

    def scale_targets(self, q: IntArray, x1: Array) -> tuple[Array, Array]:
        """Phase 2's right-hand sides (N, m) from phase-1 solutions, and the equation-7 targets (N, 2 (n - 2))."""
        S, n, m = self.S, self.n, self.m
        N = len(q)
        P2 = x1.reshape(N, n, 2)
        seg = P2[:, 1:] - P2[:, :-1]
        ln = np.linalg.norm(seg, axis=-1)
        L0 = S.L0[q]
        vb = seg * np.divide(L0, ln, out=np.ones_like(ln), where=ln > 1e-12)[..., None]
        ub = vb / S.span[q][..., None]
        rhs = S.bs[q] + EPS * x1
        r_sec = np.zeros((N, 0))
        if n >= 3:
            r_sec = ((ub[:, 1:] - ub[:, :-1]) * S.sec_w[q][..., None]).reshape(N, 2 * (n - 2))
            rhs += _rhs(m, S.sec_cols, S.sec_vals[q], r_sec)
        rhs += _rhs(m, S.rig_cols, S.rig_vals[q], vb.reshape(N, 2 * (n - 1)) * S.rig_w[q])
        rhs = np.where(np.repeat(~S.valid[q], 2, axis=1), 0.0, rhs)
        return rhs, r_sec

    def solve_scale(self, q: IntArray, rhs: Array) -> Array:
        """Phase 2's block solutions ``N2^-1 rhs`` (without the coupled rows)."""
        return _spd_solve(self.S.scale.normal[q], rhs[..., None])[..., 0] if len(q) else np.zeros((0, self.m))

    def scale(self, q: IntArray, x2: Array, r_sec: Array) -> Array:
        """Phase 2: equation-7 residuals against the targets ``r_sec`` and soft constraint rows, squared."""
        S = self.S
        e = self._soft(S.s_loc, q, x2)
        if self.n >= 3:
            e = e + np.sum(_res(S.sec_cols, S.sec_vals[q], r_sec, x2) ** 2, axis=1)
        return e

    def time(self, q: IntArray, xt: Array) -> Array:
        """Time: time-step residuals and soft constraint rows, squared."""
        S = self.S
        return np.sum(_res(S.tim_cols, S.tim_vals[q], S.tim_rhs[q], xt) ** 2, axis=1) + self._soft(S.t_loc, q, xt)

    def _ratio(self, q: IntArray) -> Array:
        """Full-path arc length per undeformed kept chord (0 on padding steps)."""
        S = self.S
        L0 = S.L0[q]
        return np.where(S.vstep[q], np.divide(S.arc[q], L0, out=np.ones_like(L0), where=L0 > 1e-6), 0.0)

    def length_change(self, q: IntArray, x2: Array) -> Array:
        """Signed change of the full path's length: each kept chord's change scales the arc it spans."""
        c1 = np.linalg.norm(np.diff(x2.reshape(len(q), self.n, 2), axis=1), axis=-1)
        return np.sum(self._ratio(q) * (c1 - self.S.L0[q]), axis=1)

    def length_linear(self, q: IntArray, x2: Array) -> tuple[Array, Array, Array]:
        """Gradient of :meth:`length_change` at ``x2`` and its error bound (see :func:`_sum_over_parts`).

        A move of at most ``e`` per unknown changes a chord ``c`` by ``|d| <= 2 sqrt(2) e``; while
        ``|d| <= |c| / 2`` the chord's length is its first-order value within ``|d|^2 / |c|``.
        """
        N, n = len(q), self.n
        d = np.diff(x2.reshape(N, n, 2), axis=1)
        c = np.hypot(d[..., 0], d[..., 1])
        r = self._ratio(q)
        on = r != 0
        unit = d / np.where(c > 0, c, 1.0)[..., None]
        grad = np.zeros((N, n, 2))
        grad[:, 1:] += r[..., None] * unit
        grad[:, :-1] -= r[..., None] * unit
        flat = np.any(on & (c == 0), axis=1)  # a zero chord: no first-order bound, evaluated exactly
        curv = np.where(flat, 0.0, 8.0 * np.sum(np.abs(r) / np.where(on & (c > 0), c, np.inf), axis=1))
        reach = np.where(flat, 0.0, np.min(np.where(on, c, np.inf), axis=1, initial=np.inf) / (4 * math.sqrt(2)))
        return grad.reshape(N, self.m), curv, reach

    def duration_change(self, q: IntArray, xt: Array) -> Array:
        """Signed change of the duration (first to last kept frame)."""
        S = self.S
        return xt[np.arange(len(q)), S.last[q]] - xt[:, 0] - (S.nfr[q] - 1) * S.dt[q]

    def duration_linear(self, q: IntArray, xt: Array) -> tuple[Array, Array, Array]:
        """Gradient of :meth:`duration_change` (it is linear: no error)."""
        grad = np.zeros((len(q), self.n))
        grad[:, 0] = -1.0
        grad[np.arange(len(q)), self.S.last[q]] += 1.0
        return grad, np.zeros(len(q)), np.full(len(q), np.inf)


def _sum_over_parts(
    sol: PhaseSolution,
    kc: IntArray,
    signed: Any,
    linear: Any,
    base_term: Array,
    cand_term: Array,
) -> Array:
    """A term ``|s(x)|`` summed over every part of every variant, shape (1 + C,) (no part left out).

    ``linear(q, x)`` gives, for the base parts' solutions ``x`` (K, m), the
    gradient of ``s`` (K, m) and two numbers per part that bound the
    first-order error: a move of at most ``e`` (per unknown) changes ``s``
    by its gradient times the move within ``e**2 * curv``, if ``e <= reach``
    (``curv = 0`` and ``reach = inf`` for a linear ``s``).  Parts whose
    bound on the error exceeds :data:`EXACT` (and the moves that are not
    ``Zr dw``) are evaluated exactly with ``signed(k, x)``; the others, most
    of a large scene, by the gradient through ``Zr``: ``(K, C, gk)``
    products, never a (K, C, m) array.
    """
    K, C = sol.dw.shape[:2]
    tot = np.full(1 + C, float(base_term.sum()))
    if C == 0:
        return tot
    ci = np.arange(C)
    allK = np.arange(K, dtype=np.int64)
    grad, curv, reach = linear(allK, sol.base)
    s0 = signed(allK, sol.base)
    h = np.einsum("km,kmg->kg", grad, sol.Zr)
    each = np.abs(s0[:, None] + np.einsum("kcg,kg->kc", sol.dw, h))
    e = sol.bound
    exact = (e > reach[:, None]) | (e * e * curv[:, None] > EXACT)
    exact[sol.shift_k, sol.shift_v - 1] = True
    exact[kc, ci] = False
    ke, ce = np.nonzero(exact)
    for i in range(0, len(ke), _CHUNK):  # in chunks: memory O(_CHUNK m)
        k, c = ke[i : i + _CHUNK], ce[i : i + _CHUNK]
        each[k, c] = np.abs(signed(k, sol.base[k] + sol.moves(k, c)))
    each[kc, ci] = cand_term
    tot[1:] = each.sum(axis=0)
    return tot


class SubsampledScene:
    """The current scene prepared for subsampled evaluation of candidates (module docstring).

    Parameters
    ----------
    tracks : sequence of Track
        The characters' current structure.
    paths : sequence of MotionPath
        Their undeformed paths (of the tracks' motions).
    constraints : sequence
        Constraints on the tracks' current frames.
    segments : sequence of list of (start, stop)
        Rigid stationary segments per character (half-open).
    starts : sequence of float
        Reference time of each character's frame 0.
    subsample, cs, ct : int, float, float
        Subsampling ratio and the weights of equation 10.
    step : int
        Sampling step of variational constraints.
    tangents : optional
        The editor's tangent-row cache (a ``row(k, i)`` object).
    deformed : sequence of ndarray (F_k, 2), optional
        The current full solve's paths: relative constraints are scored as
        their metric form linearised about them (see
        :func:`~mocaplab.editing.laplacian.spatial_rows`), so a candidate that
        changes a tangent's length keeps the offsets in metres.  Default: the
        linear rows of equations 1 and 2.
    far : float
        See :data:`FAR`; 0 re-solves every part of every variant (exact).
    """

    def __init__(
        self,
        tracks: Sequence[Track],
        paths: Sequence[MotionPath],
        constraints: Sequence[Any],
        segments: Sequence[Sequence[tuple[int, int]]],
        starts: Sequence[float],
        *,
        subsample: int = 25,
        cs: float = 1.0,
        ct: float = 1.0,
        step: int = 10,
        tangents: Any = None,
        deformed: Sequence[Array] | None = None,
        far: float = FAR,
    ) -> None:
        self.tracks = list(tracks)
        self.subsample = int(subsample)
        self.cs, self.ct = float(cs), float(ct)
        self.far = float(far)
        K = len(tracks)
        self.K = K
        layout = Layout(tuple(t.n_frames for t in tracks))
        dts = [t.motion.dt for t in tracks]
        self.dts = np.array(dts, dtype=float)
        self.starts = np.array([float(s) for s in starts], dtype=float)
        wmax = max([1.0] + [float(c.weight) for c in constraints if hasattr(c, "weight") and not c.hard])
        self.pen = PENALTY * wmax
        tang = tangents if tangents is not None else _Tangents(paths)
        at = None if deformed is None else np.concatenate([np.asarray(q, dtype=float) for q in deformed]).reshape(-1)
        self.space = _compile(
            constraints,
            SPATIAL,
            lambda c: spatial_rows(c, paths, layout, cast(Any, tang), step, linearize_at=at),
            layout,
            2,
            self.pen,
        )
        self.time = _compile(constraints, TEMPORAL, lambda c: temporal_rows(c, layout, dts, step), layout, 1, self.pen)
        self._ts = RowTable.of(self.space, K, 2)
        self._tt = RowTable.of(self.time, K, 1)
        self.segments = [list(s) for s in segments]
        # per-character arrays, concatenated (character k's frame f is row poff[k] + f)
        self.F = np.array([t.n_frames for t in tracks], dtype=np.int64)
        self.poff = np.concatenate([[0], np.cumsum(self.F)]).astype(np.int64)
        pos = [np.asarray(p.positions, dtype=float) for p in paths]
        self.P = np.concatenate(pos)
        self.H = np.concatenate([t.headings for t in tracks])
        self.C = np.concatenate(
            [np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(p, axis=0), axis=1))]) for p in pos]
        )
        # motion graphs, concatenated (node i of character k's graph is goff[k] + i)
        gds: list[GraphArrays] = []
        where: dict[int, int] = {}
        goff = []
        total = 0
        for t in tracks:
            gd = t.arrays
            if id(gd) not in where:
                where[id(gd)] = total
                gds.append(gd)
                total += t.graph.n_frames
            goff.append(where[id(gd)])
        self.goff = np.array(goff, dtype=np.int64)
        self.gpos = np.concatenate([g.pos for g in gds])
        self.gyaw = np.concatenate([g.yaw for g in gds])
        self.garc = np.concatenate([g.arc for g in gds])
        self.gfirst = np.concatenate([g.first for g in gds])
        self.nodes = np.concatenate([self.goff[k] + t.nodes for k, t in enumerate(tracks)])
        # kept frames of the untransformed paths
        ratio = self.subsample
        base: list[IntArray] = []
        for k, t in enumerate(tracks):
            F = t.n_frames
            keep = [np.arange(0, F, ratio), [0, F - 1]]
            for rows in (self.space, self.time):
                keep.append(rows.frame[(rows.char == k) & (rows.val != 0)])
            for a, b in self.segments[k]:
                keep.append([a, b - 1])
            base.append(np.unique(np.clip(np.concatenate([np.asarray(x, dtype=np.int64) for x in keep]), 0, F - 1)))
        self.base_frames = base
        self._bn = np.array([len(f) for f in base], dtype=np.int64)
        self._bf = np.full((K, int(self._bn.max())), -1, dtype=np.int64)
        for k, f in enumerate(base):
            self._bf[k, : len(f)] = f
        S = max([len(s) for s in self.segments], default=0)
        self._seg = np.zeros((K, S, 2), dtype=np.int64)
        for k, segs in enumerate(self.segments):
            if segs:
                self._seg[k, : len(segs)] = segs
        self._baseline: float | None = None

    @property
    def baseline(self) -> float:
        """Equation-10 energy of the untransformed scene (subsampled)."""
        if self._baseline is None:
            self.energies([])
        return cast(float, self._baseline)

    def energy(self, t: Transformation) -> float:
        """Equation-10 energy of the scene with ``t`` applied (subsampled)."""
        return float(self.energies([t])[0])

    def energies(self, ts: Sequence[Transformation]) -> Array:
        """Equation-10 energies of the scene with each of ``ts`` applied, shape (len(ts),): one batch."""
        total = self.terms(ts)["total"]
        if self._baseline is None:
            self._baseline = float(total[0])
        return total[1:]

    def terms(self, ts: Sequence[Transformation] = ()) -> dict[str, Array]:
        """The terms of equation 10 (``shape, scale, time, length, duration, total``), each (1 + len(ts),).

        Entry 0 is the untransformed scene, entry ``i + 1`` the scene with ``ts[i]`` applied.
        """
        parts = self.parts(ts)
        return self._evaluate(self.systems(parts), parts, len(ts))

    def parts(self, ts: Sequence[Transformation]) -> Parts:
        """The untransformed paths (parts ``0 .. K-1``) and one transformed path per candidate."""
        K, C = self.K, len(ts)
        kc = np.array([t.character for t in ts], dtype=np.int64)
        ac = np.array([t.removed[0] for t in ts], dtype=np.int64)
        bc = np.array([t.removed[1] for t in ts], dtype=np.int64)
        sc = np.array([t.inserted[0] for t in ts], dtype=np.int64)
        ec = np.array([t.inserted[1] for t in ts], dtype=np.int64)
        Lc = ec - sc
        char = np.concatenate([np.arange(K, dtype=np.int64), kc])
        F = self.F[char]
        a = np.concatenate([self.F, ac])
        b = np.concatenate([self.F, bc])
        L = np.concatenate([np.zeros(K, np.int64), Lc])
        nfr = F - (b - a) + L
        BIG = np.iinfo(np.int64).max // 4
        # ---- kept frames
        base = np.where(self._bf >= 0, self._bf, BIG)
        blocks = [base]
        if C:
            bf = self._bf[kc]
            ok = (bf >= 0) & ((bf < ac[:, None]) | (bf >= bc[:, None]))
            r = self.subsample
            nins = -(-int(Lc.max()) // r)
            steps = r * np.arange(nins, dtype=np.int64)
            allf = np.concatenate(
                [_fmap(bf, ac, bc, Lc), ac[:, None] + _SEAM, (ac + Lc)[:, None] + _SEAM, ac[:, None] + steps], axis=1
            )
            okall = np.concatenate([ok, np.ones((C, 2 * len(_SEAM)), bool), steps[None, :] < Lc[:, None]], axis=1)
            allf = np.where(okall, np.clip(allf, 0, (nfr[K:] - 1)[:, None]), BIG)
            allf.sort(axis=1)
            dup = np.zeros(allf.shape, bool)
            dup[:, 1:] = allf[:, 1:] == allf[:, :-1]
            allf[dup] = BIG
            allf.sort(axis=1)
            blocks.append(allf)
        n = max(int(np.sum(blk < BIG, axis=1).max()) for blk in blocks)
        frames = np.full((K + C, n), BIG, dtype=np.int64)
        frames[:K, : min(n, base.shape[1])] = base[:, :n]
        if C:
            frames[K:, : min(n, blocks[1].shape[1])] = blocks[1][:, :n]
        nv = np.sum(frames < BIG, axis=1)
        frames[frames == BIG] = int(nfr.max()) + 1
        idx = np.arange(n)
        valid = idx[None, :] < nv[:, None]
        # ---- ground positions and arc lengths
        P_ = K + C
        th = np.zeros(P_)
        t1 = np.zeros((P_, 2))
        sg = np.zeros(P_, np.int64)
        ins_arc0 = np.zeros(P_)
        dth = np.zeros(P_)
        ref_o = np.zeros((P_, 2))
        last_pos = np.zeros((P_, 2))
        post_arc0 = np.zeros(P_)
        NG = len(self.gpos)
        if C:
            po = self.poff[kc]
            ka, kb = po + ac - 1, po + bc
            pa, Ha, Ca = self.P[ka], self.H[ka], self.C[ka]
            go = self.goff[kc]
            s_ = np.clip(go + sc, 0, NG - 1)
            ref = np.where(self.gfirst[s_], s_, s_ - 1)
            th_ = Ha - self.gyaw[ref]
            t1_ = pa - _rot2(th_, self.gpos[ref])
            d0 = np.linalg.norm(_rot2(th_, self.gpos[s_]) + t1_ - pa, axis=1)
            eg = np.clip(go + ec - 1, 0, NG - 1)
            hasL = Lc > 0
            lp = np.where(hasL[:, None], _rot2(th_, self.gpos[eg]) + t1_, pa)
            lh = np.where(hasL, self.gyaw[eg] + th_, Ha)
            la = np.where(hasL, Ca + d0 + self.garc[eg] - self.garc[s_], Ca)
            nb = self.nodes[kb]
            refb = np.where(self.gfirst[nb], nb, nb - 1)
            th_old = self.H[kb] - self.gyaw[nb]
            ro = _rot2(th_old, self.gpos[refb] - self.gpos[nb]) + self.P[kb]
            dth_ = lh - (self.gyaw[refb] + th_old)
            first_suf = _rot2(dth_, self.P[kb] - ro) + lp
            th[K:], t1[K:], sg[K:], dth[K:], ref_o[K:], last_pos[K:] = th_, t1_, s_, dth_, ro, lp
            ins_arc0[K:] = Ca + d0 - self.garc[s_]
            post_arc0[K:] = la + np.linalg.norm(first_suf - lp, axis=1) - self.C[kb]
        f = np.where(valid, frames, 0)
        po2 = self.poff[char][:, None]
        Fm1 = (F - 1)[:, None]
        pre = f < a[:, None]
        ins = ~pre & (f < (a + L)[:, None])
        fp = po2 + np.minimum(f, Fm1)
        gi = np.clip(sg[:, None] + f - a[:, None], 0, NG - 1)
        old = po2 + np.clip(f - (a + L - b)[:, None], 0, Fm1)
        X = np.where(
            pre[..., None],
            self.P[fp],
            np.where(
                ins[..., None],
                _rot2(th[:, None], self.gpos[gi]) + t1[:, None],
                _rot2(dth[:, None], self.P[old] - ref_o[:, None]) + last_pos[:, None],
            ),
        )
        A = np.where(
            pre, self.C[fp], np.where(ins, ins_arc0[:, None] + self.garc[gi], post_arc0[:, None] + self.C[old])
        )
        X = np.take_along_axis(X, np.minimum(idx[None, :], nv[:, None] - 1)[..., None], axis=1)
        arc = np.where(valid[:, 1:], np.diff(A, axis=1), 0.0)
        # ---- rigid (stationary) segments, cut by the transformation
        seg = self._seg[char]
        sa, sb = seg[..., 0], seg[..., 1]
        lo = np.concatenate([sa, np.maximum(sa, b[:, None])], axis=1)
        hi = np.concatenate([np.minimum(sb, a[:, None]), sb], axis=1)
        ok = hi - lo >= np.where(np.arange(P_) < K, 1, 3)[:, None]
        nlo = _fmap(lo, a, b, L)[..., None]
        nhi = _fmap(hi - 1, a, b, L)[..., None] + 1
        fr3 = frames[:, None, :]
        inside = ok[..., None] & (fr3 >= nlo) & (fr3 < nhi)
        rpt = np.any(ok[..., None] & (fr3 > nlo) & (fr3 < nhi - 1), axis=1)
        rst = np.any(inside[..., :-1] & inside[..., 1:], axis=1)
        return Parts(char, a, b, L, frames, nv, X, arc, rpt, rst, nfr, self.dts[char], self.starts[char])

    # ------------------------------------------------------------ systems
    def _cols(self, tab: RowTable, ids: IntArray, p: Parts) -> IntArray:
        """Unknown indices (within each part) of the entries of rows ``ids`` (P, R) -> (P, R, W)."""
        kk = _bsearch(p.frames, p.nv, _fmap(tab.frame[ids], p.a, p.b, p.L))
        return tab.dim * kk + tab.coord[ids] if tab.dim == 2 else kk

    def _local(self, tab: RowTable, p: Parts) -> tuple[LocalRows, IntArray]:
        """Each part's own constraint rows that fit its band; also the ids of those that do not."""
        ids = tab.intra_of[p.char]
        cols = self._cols(tab, ids, p)
        val = tab.val[ids]
        ok = _fits(cols, val, tab.band)
        # rows that do not fit are emptied here (zero values, one column) and coupled instead
        cols = np.where(ok[..., None], cols, cols[..., :1])
        rows = LocalRows(cols, np.where(ok[..., None], val, 0.0), np.where(ok, tab.rhs[ids], 0.0), ok & tab.soft[ids])
        return rows, np.unique(ids[~ok])

    def _coupling(self, tab: RowTable, p: Parts, far: IntArray, m: int) -> Coupling:
        """The coupled rows of a domain, compact per character (:class:`Coupling`)."""
        K, P_ = self.K, len(p.char)
        R = len(tab.rhs) - 1  # the all-zero padding row
        G = np.union1d(tab.cross, far).astype(np.int64)
        g = len(G)
        touch = np.zeros((K, g + 1), bool)
        rr, ww = np.nonzero(tab.val[G] != 0)
        touch[tab.char[G][rr, ww], rr] = True
        gk = max(1, int(touch.sum(axis=1).max(initial=0)))
        of_char = np.full((K, gk), g, dtype=np.int64)
        for k in range(K):
            idx = np.flatnonzero(touch[k, :g])
            of_char[k, : len(idx)] = idx
        rid = np.append(G, R)[of_char[p.char]]  # (P, gk) table rows
        cols = self._cols(tab, rid, p)
        val = tab.val[rid]
        use = ~tab.intra[rid] | ~_fits(cols, val, tab.band)
        mask = (tab.char[rid] == p.char[:, None, None]) & (val != 0) & use[..., None]
        q = (np.arange(P_, dtype=np.int64)[:, None, None] * gk + np.arange(gk, dtype=np.int64)[None, :, None]) * m
        U = np.bincount((q + cols)[mask], val[mask], minlength=P_ * gk * m).astype(float).reshape(P_, gk, m)
        return Coupling(G, tab.rhs[G], tab.soft[G], of_char, U, mask.any(axis=-1))

    def systems(self, p: Parts) -> Systems:
        """Build and solve the parts' blocks (everything that does not depend on the other characters)."""
        P_, n = p.frames.shape
        m = 2 * n
        sq = math.sqrt(self.pen)
        idx = np.arange(n)
        valid = idx[None, :] < p.nv[:, None]
        vstep = valid[:, 1:]
        X = p.X
        span = np.where(vstep, np.diff(p.frames, axis=1), 1).astype(float)
        s_loc, far_s = self._local(self._ts, p)
        t_loc, far_t = self._local(self._tt, p)
        space = self._coupling(self._ts, p, far_s, m)
        time = self._coupling(self._tt, p, far_t, n)
        # ---- phase 1: equation-3 rows weighted mbar^-3/2 (rigid ones: penalty)
        if n >= 3:
            t = X[:, 2:] - X[:, :-2]
            d = X[:, 1:-1] - X[:, :-2]
            nn = np.sum(t * t, axis=-1)
            ok = nn > 1e-18
            safe = np.where(ok, nn, 1.0)
            lx = np.where(ok, np.sum(d * t, axis=-1) / safe, 0.5)
            ly = np.where(ok, (d[..., 0] * t[..., 1] - d[..., 1] * t[..., 0]) / safe, 0.0)
            mbar = 0.5 * (span[:, :-1] + span[:, 1:])
            vint = valid[:, 2:]
            rig = p.rpt[:, 1:-1]
            wr = np.where(vint, np.where(rig, sq, mbar**-1.5), 0.0)
            g = idx[1:-1]
            X0, X1, X2 = 2 * (g - 1), 2 * g, 2 * (g + 1)
            one = np.ones_like(lx)
            rx_c = np.stack([X1, X0, X2, X0, X2 + 1, X0 + 1], axis=-1)
            rz_c = np.stack([X1 + 1, X0 + 1, X2 + 1, X0 + 1, X2, X0], axis=-1)
            rx_v = np.stack([one, -one, -lx, lx, -ly, ly], axis=-1)
            rz_v = np.stack([one, -one, -lx, lx, ly, -ly], axis=-1)
            lap_c = np.stack([rx_c, rz_c], axis=1).reshape(1, -1, 6)
            lap_v = (np.stack([rx_v, rz_v], axis=2) * wr[:, :, None, None]).reshape(P_, -1, 6)
            lap_energy = np.repeat(vint & ~rig, 2, axis=1)
        else:
            lap_c, lap_v = np.zeros((1, 0, 6), np.int64), np.zeros((P_, 0, 6))
            lap_energy = np.zeros((P_, 0), bool)
        pad = np.repeat(~valid, 2, axis=1)
        u2 = _BAND[2]
        Nc = _band(P_, m, u2, s_loc.cols, s_loc.vals)  # constraint rows: in both phases
        N1 = _band(P_, m, u2, lap_c, lap_v) + Nc
        N1[:, u2] += EPS + pad
        x0 = np.where(pad, 0.0, X.reshape(P_, -1))
        bs = _rhs(m, s_loc.cols, s_loc.vals, s_loc.rhs)
        UsT = np.swapaxes(space.U, 1, 2)
        sol = _spd_solve(N1, np.concatenate([(bs + EPS * x0)[..., None], UsT], axis=2))
        shape = PhaseBlocks(N1, sol[..., 1:], sol[..., 0])
        # ---- phase 2: equation 7 on per-frame velocities, rows weighted 1/sqrt(mean span)
        if n >= 3:
            ia, ib = 1.0 / span[:, :-1], 1.0 / span[:, 1:]
            wv = np.where(valid[:, 2:], (0.5 * (span[:, :-1] + span[:, 1:])) ** -0.5, 0.0)
            g = idx[1:-1]
            cols_ = [np.stack([2 * (g - 1) + q, 2 * g + q, 2 * (g + 1) + q], axis=-1) for q in (0, 1)]
            vals_ = [np.stack([ia, -ia - ib, ib], axis=-1) * wv[..., None]] * 2
            sec_c = np.stack(cols_, axis=1).reshape(1, -1, 3)
            sec_v = np.stack(vals_, axis=2).reshape(P_, -1, 3)
        else:
            sec_c, sec_v = np.zeros((1, 0, 3), np.int64), np.zeros((P_, 0, 3))
            wv = np.zeros((P_, 0))
        st = idx[:-1]
        rc = np.stack([np.stack([2 * (st + 1) + q, 2 * st + q], axis=-1) for q in (0, 1)], axis=1).reshape(1, -1, 2)
        wrs = np.repeat(np.where(p.rst, sq, 0.0), 2, axis=1)
        rig_v = wrs[:, :, None] * np.array([1.0, -1.0])
        N2 = _band(P_, m, u2, sec_c, sec_v) + _band(P_, m, u2, rc, rig_v) + Nc
        N2[:, u2] += EPS + pad
        Z2 = _spd_solve(N2, UsT) if UsT.shape[2] else np.zeros((P_, m, 0))
        scale = PhaseBlocks(N2, Z2, None)
        L0 = np.linalg.norm(np.diff(X, axis=1), axis=-1)
        # ---- time: t[i+1] - t[i] = m_i h, rows weighted 1/sqrt(m_i)
        wt = np.where(vstep, 1.0 / np.sqrt(np.maximum(span, 1.0)), 0.0)
        tc = np.stack([idx[1:], idx[:-1]], axis=-1)[None]
        tv = np.stack([wt, -wt], axis=-1)
        trhs = span * p.dt[:, None] * wt
        u1 = _BAND[1]
        Nt = _band(P_, n, u1, tc, tv) + _band(P_, n, u1, t_loc.cols, t_loc.vals)
        Nt[:, u1] += EPS + ~valid
        t0 = np.where(valid, p.start[:, None] + p.frames * p.dt[:, None], 0.0)
        bt = _rhs(n, tc, tv, trhs) + _rhs(n, t_loc.cols, t_loc.vals, t_loc.rhs) + EPS * t0
        sol = _spd_solve(Nt, np.concatenate([bt[:, :, None], np.swapaxes(time.U, 1, 2)], axis=2))
        tblocks = PhaseBlocks(Nt, sol[..., 1:], sol[..., 0])
        return Systems(
            n, valid, vstep, span, p.arc, (p.nv - 1).astype(np.int64), p.nfr.astype(float), p.dt,
            space, time, s_loc, t_loc, lap_c, lap_v, lap_energy, sec_c, sec_v, wv, rc, rig_v, wrs,
            bs, L0, tc, tv, trhs, shape, scale, tblocks,
        )  # fmt: skip

    # ------------------------------------------------------------- energies
    def _evaluate(self, S: Systems, p: Parts, C: int) -> dict[str, Array]:
        """Equation 10 for every variant: the scene (0) and the scene with candidate ``i`` (``i + 1``)."""
        K = self.K
        T = PartTerms(S)
        kc = p.char[K:]
        allK = np.arange(K, dtype=np.int64)
        allC = K + np.arange(C, dtype=np.int64)

        def per_variant(base: Array, cand: Array, mv: IntArray, mk: IntArray, moved: Array) -> Array:
            tot = np.full(1 + C, float(base.sum()))
            tot[1:] += cand - base[kc]
            _add_at(tot, mv, moved - base[mk])
            return tot

        def coupled(sol: PhaseSolution, cp: Coupling) -> Array:
            return np.sum(np.where(cp.soft[None, :], sol.residual, 0.0) ** 2, axis=1)

        def every_part(sol: PhaseSolution, signed: Any, linear: Any) -> Array:
            base, cand = np.abs(signed(allK, sol.base)), np.abs(signed(allC, sol.cand))
            return _sum_over_parts(sol, kc, signed, linear, base, cand)

        far = self.far
        # phase 1 (shape)
        vK = S.valid[:K]
        inv_s, inv_t = _translation_invariant(S.s_loc, K, 2), _translation_invariant(S.t_loc, K, 1)
        s1 = _couple(S.space, cast(Array, S.shape.y), S.shape.Z, K, kc, far=far, dim=2, valid=vK, invariant=inv_s)
        e_shape = T.shape
        E_shape = per_variant(
            e_shape(allK, s1.base), e_shape(allC, s1.cand), s1.moved_v, s1.moved_k, e_shape(s1.moved_k, s1.moved)
        ) + coupled(s1, S.space)
        # phase 2 (scale): right-hand sides from phase 1, exact for every part that moved
        rb, secb = T.scale_targets(allK, s1.base)
        rc_, secc = T.scale_targets(allC, s1.cand)
        rm, secm = T.scale_targets(s1.moved_k, s1.moved)
        y2 = np.concatenate([T.solve_scale(allK, rb), T.solve_scale(allC, rc_)])
        y2m = T.solve_scale(s1.moved_k, rm)
        extra = (s1.moved_v, s1.moved_k, y2m)
        s2 = _couple(S.space, y2, S.scale.Z, K, kc, far=far, extra=extra, dim=2, valid=vK, invariant=inv_s)
        sec2 = secb[s2.moved_k].copy()
        if len(s1.moved_v):  # the parts whose phase-1 solution moved have their own equation-7 targets
            pos = np.full((C + 1, K), -1, dtype=np.int64)
            pos[s1.moved_v, s1.moved_k] = np.arange(len(s1.moved_v))
            i = pos[s2.moved_v, s2.moved_k]
            sec2[i >= 0] = secm[i[i >= 0]]
        E_scale = per_variant(
            T.scale(allK, s2.base, secb),
            T.scale(allC, s2.cand, secc),
            s2.moved_v,
            s2.moved_k,
            T.scale(s2.moved_k, s2.moved, sec2),
        ) + coupled(s2, S.space)
        dL = every_part(s2, T.length_change, T.length_linear)
        # time
        st_ = _couple(
            S.time, cast(Array, S.time_blocks.y), S.time_blocks.Z, K, kc, far=far, dim=1, valid=vK, invariant=inv_t
        )
        e_time = T.time
        E_time = per_variant(
            e_time(allK, st_.base), e_time(allC, st_.cand), st_.moved_v, st_.moved_k, e_time(st_.moved_k, st_.moved)
        ) + coupled(st_, S.time)
        dT = every_part(st_, T.duration_change, T.duration_linear)
        total = E_shape + E_scale + E_time + self.cs * dL + self.ct * dT
        return {"shape": E_shape, "scale": E_scale, "time": E_time, "length": dL, "duration": dT, "total": total}
