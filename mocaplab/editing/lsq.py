"""Sparse least squares under hard constraints: the solver layer shared by the Laplacian editors.

Kim et al. 2009 solve every edit as a quadratic energy under soft rows
(weighted least squares) and hard rows (Lagrange multipliers), by one KKT
system: equation 6 for the paths in space (section 4.1) and equation 9 for
the time warp (section 4.4).  What both need, and what does not depend on
what the rows mean, lives here:

* where each character's frames sit in the stacked unknowns
  (:class:`Layout`), rows of constraints and their stacking (:class:`Rows`,
  :func:`assemble`), the factorised augmented system (:class:`KKT`);
* redundant hard rows (:func:`full_row_rank_screen`,
  :func:`independent_hard_rows`, :func:`segment_redundancy`,
  :class:`HardRows`, :class:`Redundancy`);
* free modes and the gauge rows that fix them (:func:`similarity_modes`,
  :func:`affine_modes`, :func:`mode_matrix`, :func:`gauge_rows`).

Neighbours: :mod:`~mocaplab.editing.laplacian` writes the spatial rows and
:mod:`~mocaplab.editing.spatial` solves them; :mod:`~mocaplab.editing.timewarp`
writes and solves the temporal ones.  This module imports neither.

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
biased; a character with no constraint keeps its path.  The time warp does
the same with each character's time shift.
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

from .constraints import ConstraintError
from .paths import MotionPath, rot90

__all__ = [
    "Layout",
    "Rows",
    "assemble",
    "KKT",
    "full_row_rank_screen",
    "Redundancy",
    "HardRows",
    "independent_hard_rows",
    "segment_redundancy",
    "mode_matrix",
    "similarity_modes",
    "affine_modes",
    "gauge_rows",
    "label_text",
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


@dataclasses.dataclass
class Rows:
    """Linear rows ``sum(vals * x[cols]) = rhs`` produced by one constraint.

    ``metric`` lists the row pairs whose right-hand side is corrected to a
    metric target after each solve: the spatial relative constraints attach
    :class:`~mocaplab.editing.laplacian.MetricPair` records, which
    :func:`~mocaplab.editing.laplacian.metric_targets` gathers; the rows
    themselves are plain linear rows to everything here.
    """

    cols: list[NDArray[np.int64]]
    vals: list[Array]
    rhs: Array
    metric: tuple[Any, ...] = ()

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


# ------------------------------------------------------------ free modes
def mode_matrix(blocks: list[tuple[int, Array]], n: int, dim: int) -> sp.csc_matrix:
    """Columns from per-character dense blocks ``(first unknown, (len, m) block)``, shape (n, sum of m)."""
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
    return mode_matrix(blocks, 2 * layout.total, 4), np.repeat(np.arange(len(paths)), 4)


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
    return mode_matrix(blocks, 2 * layout.total, 4), np.repeat(np.arange(len(layout.n_frames)), 4)


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


# ------------------------------------------------------ hard rows and KKT
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


def label_text(label: Any) -> str:
    """A hard-row group's label in messages: ``#index constraint`` or the automatic rows' text."""
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
        by = " and ".join(label_text(b) for b in self.implied_by)
        return (
            f"hard {what} constraint {label_text(self.label)} is redundant (implied by {by}): its rows are left out "
            "of the solve and checked instead"
        )


_CONSISTENCY_TOL = 1e-7  # metres or seconds: how far a left-out redundant hard row may miss
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
                    f"Conflicting hard {self.what} constraints: {label_text(r.label)} is determined by "
                    + " and ".join(label_text(b) for b in r.implied_by)
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
        names = ", ".join(label_text(lab) for lab in labels) or "automatic rows"
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
