"""The spatial solver of Laplacian path editing (Kim et al. 2009, section 4.1).

:class:`SpatialSolver` holds the constant parts of the spatial problem of one
set of characters (the matrices of :mod:`~mocaplab.editing.laplacian`: shape
rows, scale rows, rigid stationary segments; the free modes of
:mod:`~mocaplab.editing.lsq`);
:meth:`SpatialSolver.factorize` factorises both phases for one constraint
structure (:class:`SpatialFactors`, with the hard rows, gauges and KKT systems
of :mod:`~mocaplab.editing.lsq`) and :meth:`SpatialSolver.solve` solves them for
one set of targets (:class:`SpatialSolution`).  The scene
(:mod:`~mocaplab.editing.scene`) keeps the factors between drags.

Relative constraints in metres
    their rows' right-hand sides are corrected on each solution and the solve
    repeated until the corrections settle (a fixed point, Anderson-accelerated
    while its changes shrink, best iterate kept, divergence and stalls
    detected; a hard relative still missed by 10 cm raises naming the hard
    constraints it fights).  What the rows are and why:
    :mod:`~mocaplab.editing.laplacian`, "Relative constraints in metres".
    ``iterations`` bounds the solves of one call: an interactive drag may
    stop early and settle on release
    (:meth:`~mocaplab.editing.SceneEditor.settle`).

A drag that moves a target changes only ``b`` and ``h``: phase 1 is then
updated through cached columns of its inverse for the moved entries
(O(frames), :meth:`SpatialSolver._phase1`), phase 2 is one back-substitution
(its right-hand side depends on phase 1 everywhere), plus O(F) vector work.

The metric-target iteration, the hard-row checks and the conflict diagnosis
(:meth:`SpatialSolver.soft_conflicts`) all read the same factors, so the
solver stays one class (about 500 lines).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence
from typing import Any

import numpy as np
import scipy.sparse as sp
from numpy.typing import NDArray

from .constraints import ConstraintError
from .laplacian import (
    MetricTargets,
    TangentRows,
    metric_linearization,
    metric_targets,
    rigid_rows,
    scale_matrix,
    shape_matrix,
)
from .lsq import (
    KKT,
    HardRows,
    Layout,
    Rows,
    affine_modes,
    assemble,
    gauge_rows,
    independent_hard_rows,
    label_text,
    segment_redundancy,
    similarity_modes,
)
from .paths import MotionPath, rot90

__all__ = ["SpatialFactors", "SpatialSolution", "SpatialSolver"]

Array = NDArray[np.float64]

_ANDERSON = 5  # iterates mixed by the metric-target iteration
# Iterations without a smaller change before the metric-target iteration stops.  A chain of tied
# characters turned far swings before it settles: 150 walkers in two columns (75 deep) grew their
# changes from 187 to 777 mm over three solves, then settled to 0.1 mm in six more; stopping after
# three solves without a smaller change left them 24 cm off (the 1000-walker formation 25 cm).
_STALE = 12
_HARD_MISS = 100.0  # a hard relative missed by this many metric tolerances (10 cm by default) raises
_DIVERGE = 100.0  # a change this many times the best one so far: the metric-target iteration diverges
_INFLUENCE = 8  # at most this many moved right-hand-side entries update phase 1 through cached columns
_INFLUENCE_CACHE = 16  # supports kept per factorisation
_UPDATE_RANGE = 1e6  # phase 1 is updated from the previous solution only within this many scene extents


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
    stalled : bool
        It was stopped because its changes stopped shrinking.
    settled : bool
        The corrections settled to the solver's ``metric_tolerance`` (True
        without relative constraints).
    warm : bool
        The iteration started from a previous solution's corrections (a
        drag); False: from the constraints alone.
    """

    pbar: Array
    phat: Array
    bw: Array
    h: Array
    iterations: int
    change: float
    corrections: Array
    diverged: bool = False
    stalled: bool = False
    settled: bool = True
    warm: bool = False


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
        self.tangent_rows = TangentRows(self.paths)
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
        self,
        f: SpatialFactors,
        bw: Array,
        h: Array,
        *,
        previous: SpatialSolution | None = None,
        iterations: int | None = None,
    ) -> SpatialSolution:
        """Both phases for the right-hand sides ``bw`` (weighted soft) and ``h`` (hard).

        With relative constraints, the solve is repeated with their rows'
        right-hand sides corrected to the metric targets measured on the
        last solution until no correction changes by more than
        ``metric_tolerance`` metres, at most ``iterations`` solves (default
        ``metric_iterations``).  The step mixes the last few iterates
        (Anderson) while the changes shrink; when a change grows the mixing
        restarts from the plain step (a long chain of tied characters swings
        for a few solves before it settles, and mixing across the swing sends
        it off).  The iterate with the smallest change is kept; the
        iteration stops when the changes grow past ``_DIVERGE`` times the
        best (a conflict) or stop improving for ``_STALE`` solves.

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
        its = self.metric_iterations if iterations is None else max(1, int(iterations))
        start = None if previous is None else previous.corrections
        warm = start is not None and start.shape == (M.n, 2)
        if start is None or not warm:
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
        last = np.inf
        diverged = stalled = False
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
            if change <= self.metric_tolerance or it >= its:
                break
            if stale >= _STALE:
                stalled = True
                break
            if change > last:
                xs, gs = [], []  # the change grew: restart the mixing from the plain step
            last = change
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
        if change > self.metric_tolerance and (diverged or stalled):  # not merely out of iterations
            self._check_hard_relatives(f, phat, h1)
        return SpatialSolution(
            pbar,
            phat,
            bw1,
            h1,
            it,
            change,
            x.reshape(-1, 2),
            diverged,
            stalled=stalled,
            settled=change <= self.metric_tolerance,
            warm=warm,
        )

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
            metric_linearization(tuple(M.coef[hard[q]]), t0)[0] if np.linalg.norm(t0) > 1e-12 else M.linear[hard[q]]
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
            f"The hard relative constraint {label_text(own)} is missed by {err[q]:.3g} m: "
            + (
                "it fights " + " and ".join(label_text(o) for o in others) + ", which fix what it asks for"
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
