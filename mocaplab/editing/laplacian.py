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
    between successive frames, and repaired (for the heading) by linear
    interpolation of the neighbouring tangent directions.  The positions are
    not changed, so the matrix never depends on the flips.

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

A drag that moves a target changes only ``b`` and ``h``: an update is two
back-substitutions plus O(F) vector work.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence
from typing import Any

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla
from numpy.typing import NDArray
from scipy.ndimage import uniform_filter1d
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
    "detect_tangent_flips",
    "heading_changes",
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

    @property
    def offsets(self) -> NDArray[np.int64]:
        return np.concatenate([[0], np.cumsum(self.n_frames)]).astype(np.int64)

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
    """Linear rows ``sum(vals * x[cols]) = rhs`` produced by one constraint."""

    cols: list[NDArray[np.int64]]
    vals: list[Array]
    rhs: Array

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


def spatial_rows(c: Any, paths: Sequence[MotionPath], layout: Layout, tangents: _TangentRows, step: int) -> Rows:
    """The linear rows (unweighted) of one spatial constraint."""
    off = layout.offsets
    cols: list[NDArray[np.int64]] = []
    vals: list[Array] = []
    rhs: list[float] = []

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
            Lb = float(np.linalg.norm(paths[b].tangents[j]))
            cx, cy = c.offset[0] / Lb, c.offset[1] / Lb
            # x: pa.x - pb.x - cx T.x - cy T.z = 0 ; z: pa.z - pb.z - cx T.z + cy T.x = 0
            cols.append(np.concatenate([[var(a, i, 0), var(b, j, 0)], var(b, fb, 0), var(b, fb, 1)]))
            vals.append(np.concatenate([[1.0, -1.0], -cx * wb, -cy * wb]))
            cols.append(np.concatenate([[var(a, i, 1), var(b, j, 1)], var(b, fb, 1), var(b, fb, 0)]))
            vals.append(np.concatenate([[1.0, -1.0], -cx * wb, cy * wb]))
            rhs += [0.0, 0.0]
            if c.direction is not None:
                fa, wa = tangents.row(a, i)
                La = float(np.linalg.norm(paths[a].tangents[i]))
                dx, dy = c.direction[0] * La / Lb, c.direction[1] * La / Lb
                cols.append(np.concatenate([var(a, fa, 0), var(b, fb, 0), var(b, fb, 1)]))
                vals.append(np.concatenate([wa, -dx * wb, -dy * wb]))
                cols.append(np.concatenate([var(a, fa, 1), var(b, fb, 1), var(b, fb, 0)]))
                vals.append(np.concatenate([wa, -dx * wb, dy * wb]))
                rhs += [0.0, 0.0]
        else:  # pragma: no cover - filtered by the scene
            raise TypeError(f"not a spatial constraint: {c!r}")
    return Rows([np.asarray(x, dtype=np.int64).reshape(-1) for x in cols], vals, np.asarray(rhs, dtype=float))


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
    CQ = (sp.csr_matrix(C) @ Q).toarray() if C.shape[0] else np.zeros((0, Q.shape[1]))
    scale = max(1.0, float(np.abs(CQ).max(initial=0.0)))
    touched = np.abs(CQ) > 1e-13 * scale
    # characters linked by a row
    inc = sp.csr_matrix(
        (np.ones(int(touched.sum())), (np.nonzero(touched)[0], owner[np.nonzero(touched)[1]])),
        shape=(CQ.shape[0], n_chars),
    )
    adj = (inc.T @ inc).tocsr()
    ncomp, label = connected_components(adj, directed=False)
    out: list[sp.csr_matrix] = []
    for comp in range(ncomp):
        chars = np.flatnonzero(label == comp)
        cols = np.flatnonzero(np.isin(owner, chars))
        rows = np.flatnonzero(touched[:, cols].any(axis=1))
        if len(rows) == 0:
            V = np.eye(len(cols))
        else:
            sub = CQ[np.ix_(rows, cols)]
            # null space from the (small, q x q) Gram matrix: eigenvalues are squared singular values
            w, vecs = np.linalg.eigh(sub.T @ sub)
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
    which the caller then checks exactly (:func:`check_hard_rows`).  Cost:
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


def check_hard_rows(H: sp.csr_matrix, groups: Sequence[tuple[Any, NDArray[np.int64]]], what: str) -> None:
    """Raise :class:`ConstraintError` if the hard rows are linearly dependent.

    ``groups`` are ``(label, rows)`` pairs where label is ``(index, constraint)``
    for user constraints or a string for automatic ones.

    A sparse Cholesky screen (:func:`full_row_rank_screen`) clears the usual
    case cheaply; only when it fails are the groups searched, with dense
    rank tests (SVD) on the groups that share unknowns, for a minimal
    dependent set to name in the error.
    """
    if H.shape[0] == 0:
        return
    if full_row_rank_screen(H):
        return
    bad = _dependent_groups(H, groups)
    if bad is None:
        return
    labels = [groups[b][0] for b in bad]
    named = []
    cons, idx = [], []
    for lab in labels:
        if isinstance(lab, tuple):
            idx.append(lab[0])
            cons.append(lab[1])
            named.append(f"#{lab[0]} {lab[1]!r}")
        else:
            cons.append(lab)
            named.append(str(lab))
    raise ConstraintError(
        f"Conflicting or redundant hard {what} constraints (linearly dependent, cannot all hold exactly): "
        + "; ".join(named)
        + ". Make one of them soft (hard=False) or remove it.",
        cons,
        idx,
    )


class KKT:
    """A factorised augmented system ``[[N, H^T], [H, 0]]`` (equations 6 and 9).

    Parameters
    ----------
    N : sparse (n, n)
        Symmetric positive definite normal matrix.
    H : sparse (m, n)
        Hard constraint rows (full row rank: check with :func:`check_hard_rows`).
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
@dataclasses.dataclass
class SpatialFactors:
    """Both phases' factorisations for one constraint structure."""

    shape: KKT
    scale: KKT | None
    Bw: sp.csr_matrix
    BwT: sp.csr_matrix
    H: sp.csr_matrix  # user hard rows followed by rigid rows
    G1: sp.csr_matrix  # phase-1 gauge rows (fixed to the undeformed path)
    g1: Array
    G2: sp.csr_matrix  # phase-2 gauge rows (fixed to the phase-1 result)


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
    ) -> None:
        self.paths = list(paths)
        self.layout = Layout(tuple(p.n_frames for p in paths))
        self.p0 = np.concatenate([p.positions for p in paths]).reshape(-1)
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

    def factorize(
        self, soft: Sequence[Rows], weights: Sequence[float], hard: Sequence[Rows], labels: Sequence[Any]
    ) -> tuple[SpatialFactors, Array, Array]:
        """Factorise both phases for a constraint structure.

        Returns the factors and the (weighted) soft and hard right-hand sides.
        """
        n = 2 * self.layout.total
        K = len(self.paths)
        Bw, bw = assemble(soft, n, [float(np.sqrt(w)) for w in weights])
        Hu, h = assemble(hard, n)
        H = sp.vstack([Hu, self.R], format="csr")
        groups: list[tuple[Any, NDArray[np.int64]]] = []
        r = 0
        for lab, block in zip(labels, hard, strict=True):
            groups.append((lab, np.arange(r, r + block.n)))
            r += block.n
        for lab, rows in self.rigid_groups:
            groups.append((lab, rows + r))
        check_hard_rows(H, groups, "spatial")
        BwT = Bw.T.tocsr()
        BtB = (BwT @ Bw).tocsr()
        C = sp.vstack([Bw, H], format="csr")
        G1 = gauge_rows(self.Q1, self.owner1, C, K, self._primary)
        shape = KKT(self.AtA + BtB, sp.vstack([H, G1], format="csr"))
        G2 = sp.csr_matrix((0, n))
        scale = None
        if self.scale_compensation:
            H2 = sp.vstack([Hu, self.R2], format="csr")
            if self.R2.shape[0]:
                check_hard_rows(
                    H2,
                    groups[: len(hard)] + [("rigid stationary segments", np.arange(Hu.shape[0], H2.shape[0]))],
                    "spatial",
                )
            G2 = gauge_rows(self.Q2, self.owner2, sp.vstack([Bw, H2], format="csr"), K, self._primary2)
            scale = KKT(self.AhtAh + BtB, sp.vstack([H2, G2], format="csr"))
        return SpatialFactors(shape, scale, Bw, BwT, H, G1, G1 @ self.p0, G2), bw, h

    def solve(self, f: SpatialFactors, bw: Array, h: Array) -> tuple[Array, Array]:
        """Phase 1 and phase 2 solutions, each shape (2 * total,)."""
        zr = np.zeros(self.R.shape[0])
        Btb = f.BwT @ bw if len(bw) else np.zeros(2 * self.layout.total)
        pbar = f.shape.solve(Btb, np.concatenate([h, zr, f.g1]))
        if f.scale is None:
            return pbar, pbar
        a, v = self._scale_terms(pbar)
        rhs = self.AhatT @ a
        r2 = v[self._rigid_step_rows].reshape(-1)
        phat = f.scale.solve(rhs + Btb, np.concatenate([h, r2, f.G2 @ pbar]))
        return pbar, phat

    def scale_rhs(self, pbar: Array) -> Array:
        """Right-hand side ``vbar_i - vbar_{i-1}`` of equation 7, shape (2 * n_interior,)."""
        return self._scale_terms(pbar)[0]

    def _scale_terms(self, pbar: Array) -> tuple[Array, Array]:
        P = pbar.reshape(-1, 2)
        seg = P[1:] - P[:-1]
        ln = np.sqrt(np.einsum("ij,ij->i", seg, seg))
        scale = np.divide(self._L0full, ln, out=np.ones_like(ln), where=ln > 1e-15)
        v = seg * scale[:, None]
        dv = v[1:] - v[:-1]  # row g - 1 belongs to frame g
        return dv[self._interior - 1].reshape(-1), v

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
def detect_tangent_flips(
    tangents: Array,
    new_tangents: Array,
    *,
    threshold: float = np.pi / 2,
    valid: NDArray[np.bool_] | None = None,
    window: int = 31,
) -> NDArray[np.bool_]:
    """Frames whose deformed tangent flipped (section 4.2), shape (F,) bool.

    ``phi_i`` is the signed angle from the undeformed tangent ``t_i`` to the
    deformed one.  As in the paper, a flip is reported where
    ``|phi_{i+1} - phi_i| > threshold`` between successive valid frames.  To
    know which frames around such a jump are the flipped ones (a short
    reversed stretch, Figure 4), each frame's ``phi`` is compared with the
    circular mean of ``phi`` over ``window`` frames: the two frames of each
    jump, and the runs of frames more than ``threshold`` away from a coherent
    mean (resultant length above 0.5) that touch a jump, are flipped.  Deformed tangents of (almost) zero
    length count as flipped.  ``valid`` marks the frames to examine (default
    all); others are never flipped.
    """
    F = len(tangents)
    valid = np.ones(F, bool) if valid is None else np.asarray(valid, bool)
    out = np.zeros(F, bool)
    ln = np.linalg.norm(new_tangents, axis=1)
    tiny = ln < 1e-9 * max(1.0, float(np.max(np.linalg.norm(tangents, axis=1), initial=0.0)))
    out[valid & tiny] = True
    idx = np.flatnonzero(valid & ~tiny)
    if len(idx) < 3:
        return out
    phi = wrap_angle(ground_angle(new_tangents[idx]) - ground_angle(tangents[idx]))
    jump = np.abs(wrap_angle(np.diff(phi))) > threshold
    if not jump.any():
        return out
    w = max(3, min(int(window) | 1, len(idx) | 1))
    c = uniform_filter1d(np.cos(phi), w, mode="nearest")
    s = uniform_filter1d(np.sin(phi), w, mode="nearest")
    coherent = np.hypot(c, s) > 0.5
    far = coherent & (np.abs(wrap_angle(phi - np.arctan2(s, c))) > threshold)
    near_jump = np.zeros(len(idx), bool)
    near_jump[:-1] |= jump
    near_jump[1:] |= jump
    # keep runs of "far" frames that touch a jump
    run_id = np.cumsum(np.concatenate([[1], np.diff(far.astype(np.int8)) != 0]))
    keep = np.unique(run_id[far & near_jump])
    flipped = (far & np.isin(run_id, keep)) | near_jump
    out[idx[flipped]] = True
    return out


def _procrustes_angle(orig: Array, new: Array) -> float:
    """Yaw angle of the best rotation taking centred ``orig`` onto centred ``new``."""
    x = orig - orig.mean(axis=0)
    y = new - new.mean(axis=0)
    return float(np.arctan2(np.sum(y * rot90(x)), np.sum(y * x)))


def heading_changes(
    path: MotionPath,
    new_positions: Array,
    *,
    segments: Sequence[tuple[int, int]] = (),
    flip_threshold: float = np.pi / 2,
) -> tuple[Array, NDArray[np.bool_], Array]:
    """Turn of the tangent direction per frame after a deformation.

    Returns
    -------
    dtheta : ndarray, shape (F,)
        Yaw change (radians) of the path direction at each frame, continuous
        (unwrapped).  Degenerate (stationary) and flipped frames take the
        value interpolated from their neighbours; rigid stationary segments
        take their best-fit rotation.
    flipped : ndarray of bool, shape (F,)
        Frames whose tangent flipped and was repaired.
    tangents : ndarray, shape (F, 2)
        Repaired unit tangent directions of the deformed path.
    """
    new_positions = np.asarray(new_positions, dtype=float)
    t0 = path.tangents
    t1 = central_tangents(new_positions)
    valid = ~path.degenerate
    flipped = detect_tangent_flips(t0, t1, threshold=flip_threshold, valid=valid)
    good = valid & ~flipped
    F = path.n_frames
    if good.any():
        idx = np.flatnonzero(good)
        d = np.unwrap(wrap_angle(ground_angle(t1[idx]) - ground_angle(t0[idx])))
        dtheta = np.interp(np.arange(F), idx, d)
    else:
        dtheta = np.full(F, _procrustes_angle(path.positions, new_positions))
    for a, b in segments:
        if b - a >= 2:
            ang = _procrustes_angle(path.positions[a:b], new_positions[a:b])
            ref = dtheta[a:b].mean()
            dtheta[a:b] = ang + 2 * np.pi * np.round((ref - ang) / (2 * np.pi))
    c, s = np.cos(dtheta), np.sin(dtheta)
    u = t0 / np.linalg.norm(t0, axis=1, keepdims=True)
    tang = c[:, None] * u + s[:, None] * rot90(u)
    return dtheta, flipped, tang
