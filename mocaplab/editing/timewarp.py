"""Interactive time warping (Kim et al. 2009, section 4.4, equations 8 and 9).

Unknowns: the reference time ``t`` of every frame of every character,
stacked (character after character).  One phase only (no scale compensation,
which the paper finds harmful in 1D):

    minimise ``|T t - h|^2 + |B t - b|^2_W``  subject to ``H t = h_hard``

where ``T`` keeps every step ``t[i+1] - t[i]`` at the frame time ``h`` of its
clip, ``B`` holds the soft temporal constraints and ``H`` the hard ones.

Monotonicity ``h_min <= t[i+1] - t[i] <= h_max`` is enforced as in the paper:
solve, then turn every violated step into the equality ``t[i+1] - t[i] =
h_min`` (or ``h_max``), and repeat until no step is violated.  Inserted
equalities are only ever added within one solve, so the loop ends after at
most as many rounds as there are steps.  Each set of inserted equalities
has its own factorisation, cached, so repeated drags with the same active set
cost one back-substitution per round.  The bounds are reached with equality
(``h_min > 0``, so time still strictly increases).

Defaults (our choice; the paper gives no numbers): ``h_min = h / 4``,
``h_max = 4 h`` (at most four times faster or slower than captured).
A character whose timing no constraint touches would leave the system
singular (time shifts cost nothing); its shift is fixed by a hard gauge row
keeping its mean time at the undeformed clock ``t0 = start + i h`` (see
:func:`mocaplab.editing.lsq.gauge_rows`), so no constraint is biased.

How far times may reach: the edited characters are played on one shared
clock that spans every character's times, so a time target far from the
clips (a ``Sync`` offset of 10,000 s) would size that clock, and the memory of
the edited motions, by the target rather than by the clips.  Start times
(``start_times``), ``Sync`` offsets, ``AbsoluteTime`` times (from the
character's start time) and ``Duration`` targets must lie within
:func:`time_reach` of the scene: :data:`TIME_REACH` (10) times the scene's
duration, the sum of its clips' durations.  Anything else is a
``ValueError`` naming the value and the limit, raised before any solve.
"""

from __future__ import annotations

import dataclasses
import math
from collections import OrderedDict
from collections.abc import Sequence
from typing import Any

import numpy as np
import scipy.sparse as sp
from numpy.typing import NDArray

from .constraints import AbsoluteTime, ConstraintError, Duration, Sync
from .lsq import KKT, HardRows, Layout, Rows, assemble, gauge_rows, independent_hard_rows, mode_matrix

__all__ = ["TimeSolver", "TimeFactors", "temporal_rows", "uniformity_matrix", "time_reach", "TIME_REACH"]

Array = NDArray[np.float64]

#: Time options and targets reach at most this many times the scene's duration (:func:`time_reach`).
TIME_REACH = 10.0


def time_reach(n_frames: Sequence[int], dts: Sequence[float] | NDArray[np.float64]) -> float:
    """Seconds that time options and targets may reach: :data:`TIME_REACH` times the scene's duration.

    The scene's duration is the sum of its clips' ``F_k h_k`` (characters
    played one after another), so a scene of longer clips may place them
    farther apart.

    Parameters
    ----------
    n_frames : sequence of int
    dts : sequence of float
        Frame time of each character's clip, seconds.

    Examples
    --------
    >>> time_reach([118, 118], [1 / 120, 1 / 120])  # two 0.98-second clips
    19.666666666666664
    """
    return TIME_REACH * float(sum(int(n) * float(d) for n, d in zip(n_frames, dts, strict=True)))


def _within(value: float, centre: float, reach: float, what: str) -> str | None:
    """Why ``value`` is out of reach (None when it is within ``centre +- reach``)."""
    if math.isfinite(value) and abs(value - centre) <= reach:
        return None
    span = f"from {centre - reach:.6g} to {centre + reach:.6g} s" if centre else f"within +-{reach:.6g} s"
    return (
        f"Expected {what} {span} ({TIME_REACH:g} times the scene's duration, "
        f"mocaplab.editing.timewarp.TIME_REACH), got {value!r}: a time that far from the clips would size the shared "
        "clock of the edited motions by itself"
    )


def uniformity_matrix(layout: Layout) -> sp.csr_matrix:
    """``T`` of equation 8: one row ``t[g+1] - t[g]`` per within-character step."""
    s = layout.steps()
    r = np.arange(len(s))
    return sp.csr_matrix(
        (np.concatenate([np.ones(len(s)), -np.ones(len(s))]), (np.concatenate([r, r]), np.concatenate([s + 1, s]))),
        shape=(len(s), layout.total),
    )


def temporal_rows(c: Any, layout: Layout, dts: Sequence[float] | Array, step: int) -> Rows:
    """The linear rows (unweighted) of one temporal constraint."""
    off = layout.offsets
    cols: list[NDArray[np.int64]] = []
    vals: list[Array] = []
    rhs: list[float] = []
    samples = c.samples(step)
    for sample in samples:
        if isinstance(c, AbsoluteTime):
            (i,) = sample
            cols.append(np.array([off[c.character] + i]))
            vals.append(np.array([1.0]))
            start = c.frames[0] if c.frames is not None else i
            rhs.append(c.time + (i - start) * dts[c.character])
        elif isinstance(c, Duration):
            i, e = sample
            cols.append(np.array([off[c.character] + e, off[c.character] + i]))
            vals.append(np.array([1.0, -1.0]))
            rhs.append(c.duration)
        elif isinstance(c, Sync):
            i, j = sample
            cols.append(np.array([off[c.character] + i, off[c.other] + j]))
            vals.append(np.array([1.0, -1.0]))
            rhs.append(c.offset)
        else:  # pragma: no cover - filtered by the scene
            raise TypeError(f"not a temporal constraint: {c!r}")
    return Rows([np.asarray(x, dtype=np.int64) for x in cols], vals, np.asarray(rhs, dtype=float))


@dataclasses.dataclass(frozen=True)
class TimeFactors:
    """Factorisations for one temporal constraint structure.

    Attributes
    ----------
    N : sparse
        Normal matrix ``T^T T + B^T W B``.
    Bw, BwT : sparse
        Weighted soft rows and their transpose.
    Hu : sparse
        User hard rows.
    G, g : sparse, ndarray
        Gauge rows (time shifts no constraint fixes) and their values.
    groups : list of (label, rows)
        The user hard rows per constraint (for messages).
    hard : HardRows
        The user hard rows with their independent subset.
    cache : OrderedDict
        ``active steps -> (KKT, HardRows)`` for each set of inserted
        monotonicity equalities (the one mutable part: a bounded cache).
    base : KKT
        The factorisation with no inserted equality.
    """

    N: sp.csr_matrix
    Bw: sp.csr_matrix
    BwT: sp.csr_matrix
    Hu: sp.csr_matrix
    G: sp.csr_matrix
    g: Array
    groups: list[tuple[Any, NDArray[np.int64]]]
    hard: HardRows
    cache: OrderedDict[tuple[int, ...], tuple[KKT, HardRows]]
    base: KKT

    def notes(self) -> tuple[str, ...]:
        return self.hard.notes()


class TimeSolver:
    """Constant parts of the time-warp problem for one set of characters.

    Parameters
    ----------
    n_frames : sequence of int
    dts : sequence of float
        Frame time ``h`` of each character's clip, seconds.
    start_times : sequence of float
        Reference time of each character's frame 0 before editing.
    min_step, max_step : float
        Bounds on ``t[i+1] - t[i]`` as ratios of ``h``.
    cache_size : int
        Factorisations kept per structure for sets of inserted equalities.
    """

    def __init__(
        self,
        n_frames: Sequence[int],
        dts: Sequence[float],
        start_times: Sequence[float],
        *,
        min_step: float = 0.25,
        max_step: float = 4.0,
        cache_size: int = 16,
    ) -> None:
        if not 0 < min_step < 1 < max_step:
            raise ValueError(f"Expected 0 < min_step < 1 < max_step, got min_step={min_step}, max_step={max_step}")
        self.layout = Layout(tuple(int(n) for n in n_frames))
        self.dts = np.asarray(dts, dtype=float)
        #: seconds that start times and time targets may reach (:func:`time_reach`)
        self.reach = time_reach(self.layout.n_frames, self.dts)
        self.start_times = tuple(float(s) for s in start_times)
        for k, s in enumerate(self.start_times):
            problem = _within(s, 0.0, self.reach, f"`start_times[{k}]`")
            if problem is not None:
                raise ValueError(problem)
        self.t0 = np.concatenate(
            [s + np.arange(n) * d for n, d, s in zip(self.layout.n_frames, self.dts, start_times, strict=True)]
        )
        self.T = uniformity_matrix(self.layout)
        #: the scene's duration in seconds (hard residuals are checked against it)
        self.extent = float(np.ptp(self.t0)) if len(self.t0) else 0.0
        self.steps = self.layout.steps()
        self.h = self.dts[self.layout.character_of()[self.steps]]
        self.TtT = (self.T.T @ self.T).tocsr()
        self.Tth = self.T.T @ self.h
        self.hmin = min_step * self.h
        self.hmax = max_step * self.h
        self.cache_size = int(cache_size)
        K = len(self.layout.n_frames)
        self.Q = mode_matrix(
            [
                (int(self.layout.offsets[k]), np.full((F, 1), 1.0 / np.sqrt(F)))
                for k, F in enumerate(self.layout.n_frames)
            ],
            self.layout.total,
            1,
        )
        self.owner = np.arange(K)

    def target_problem(self, c: Any) -> str | None:
        """Why temporal constraint ``c``'s target is out of the scene's reach (None when it is within).

        ``Sync.offset`` within +-:attr:`reach`; ``AbsoluteTime.time`` within
        :attr:`reach` of the character's start time; ``Duration.duration`` at
        most :attr:`reach`.
        """
        if isinstance(c, Sync):
            return _within(float(c.offset), 0.0, self.reach, "`offset`")
        if isinstance(c, AbsoluteTime):
            return _within(float(c.time), self.start_times[c.character], self.reach, "`time`")
        if isinstance(c, Duration):
            return _within(float(c.duration), 0.0, self.reach, "`duration`")
        return None

    def factorize(
        self, soft: Sequence[Rows], weights: Sequence[float], hard: Sequence[Rows], labels: Sequence[Any]
    ) -> tuple[TimeFactors, Array, Array]:
        n = self.layout.total
        Bw, bw = assemble(soft, n, [float(np.sqrt(w)) for w in weights])
        Hu, h = assemble(hard, n)
        groups: list[tuple[Any, NDArray[np.int64]]] = []
        r = 0
        for lab, block in zip(labels, hard, strict=True):
            groups.append((lab, np.arange(r, r + block.n)))
            r += block.n
        rows = independent_hard_rows(Hu, groups, "temporal")
        BwT = Bw.T.tocsr()
        N = (self.TtT + BwT @ Bw).tocsr()
        G = gauge_rows(self.Q, self.owner, sp.vstack([Bw, Hu], format="csr"), len(self.layout.n_frames))
        base = KKT(N, sp.vstack([rows.kept, G], format="csr"))
        return TimeFactors(N, Bw, BwT, Hu, G, G @ self.t0, groups, rows, OrderedDict(), base), bw, h

    def _kkt(self, f: TimeFactors, active: tuple[int, ...]) -> tuple[KKT, HardRows]:
        if not active:
            return f.base, f.hard
        if active in f.cache:
            f.cache.move_to_end(active)
            return f.cache[active]
        a = np.asarray(active, dtype=np.int64)
        E = self.T[a]
        H = sp.vstack([f.Hu, E], format="csr")
        groups = list(f.groups) + [
            (f"time-step bounds [h_min, h_max] of {len(a)} steps", np.arange(f.Hu.shape[0], H.shape[0]))
        ]
        hard = independent_hard_rows(H, groups, "temporal")
        kkt = KKT(f.N, sp.vstack([hard.kept, f.G], format="csr"))
        f.cache[active] = (kkt, hard)
        if len(f.cache) > self.cache_size:
            f.cache.popitem(last=False)
        return kkt, hard

    def solve(self, f: TimeFactors, bw: Array, h: Array) -> tuple[Array, tuple[int, ...]]:
        """Monotone time warp ``t`` (shape (total,)) and the inserted equalities (step rows)."""
        r = self.Tth + (f.BwT @ bw if len(bw) else 0.0)
        active: dict[int, float] = {}
        tol = 1e-9 * self.h
        for _ in range(len(self.steps) + 1):
            key = tuple(sorted(active))
            kkt, hard = self._kkt(f, key)
            full = np.concatenate([h, [active[s] for s in key]]) if key else h
            t = kkt.solve(r, np.concatenate([full[hard.keep], f.g]))
            # targets out of numeric range fail as such, whatever the round; only a conflict with the
            # step-bound rows of a later round is about [min_step, max_step]
            hard.check_range(t, full, self.extent)
            try:
                hard.check(t, full, scale=self.extent)
            except ConstraintError as exc:
                if not key:
                    raise
                raise ConstraintError(
                    "Hard temporal constraints cannot be met with time steps within [min_step, max_step] of the "
                    f"frame time: {exc}",
                    exc.constraints,
                    exc.indices,
                ) from None
            dt = t[self.steps + 1] - t[self.steps]
            low = np.flatnonzero(dt < self.hmin - tol)
            high = np.flatnonzero(dt > self.hmax + tol)
            new = [s for s in low if s not in active] + [s for s in high if s not in active]
            if not new:
                return t, key
            for s in low:
                active.setdefault(int(s), float(self.hmin[s]))
            for s in high:
                active.setdefault(int(s), float(self.hmax[s]))
        raise RuntimeError("time-step bounds not met")  # pragma: no cover - bounded loop

    def energy(self, f: TimeFactors, bw: Array, t: Array) -> float:
        """Objective ``|T t - h|^2 + |B t - b|^2_W`` at ``t``."""
        r = self.T @ t - self.h
        s = f.Bw @ t - bw if len(bw) else np.zeros(0)
        return float(r @ r + s @ s)
