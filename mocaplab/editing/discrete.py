"""Discrete motion editing during interactive manipulation (Kim et al. 2009, section 5).

While the user drags constraints, Laplacian path editing
(:mod:`~mocaplab.editing.scene`) deforms the paths continuously; discrete
editing lets the *structure* of a motion change too: steps are added when a
walk is stretched, an idle stretch is duplicated when it is slowed down.

Representation
--------------
Each character's current motion is a sequence of motion-graph nodes
(:class:`~mocaplab.editing.graph.MotionGraph`, by default built from the
character's own clip): ``nodes[p]`` is the graph frame played at current
frame ``p``.  Every transformation is "replace current frames ``[a, b)`` by
graph frames ``[s, e)``" (:class:`Transformation`), with two seams
``nodes[a-1] -> s`` and ``e-1 -> nodes[b]`` (for a deletion, the single seam
``nodes[a-1] -> nodes[b]``).  A seam is allowed if it is a transition of the
graph (``i -> j + 1`` for a similar pair ``(i, j)``) or the natural
continuation ``n -> n + 1``.  This gives exactly the three types of section
5.1 (Figure 7):

* **deletion** (``s == e``): transition ``i -> j + 1`` removes ``i+1 .. j``;
* **insertion** (``a == b``): transitions ``i -> j + 1`` and ``k -> i + 1``
  copy ``j+1 .. k`` between ``i`` and ``i + 1``; **duplication** is the
  special case where the copied frames are the ones that follow (the backward
  transition ``j -> i + 1`` alone plays ``i+1 .. j`` twice);
* **replacement** (both non-empty, neither seam natural): transitions
  ``i -> k + 1`` and ``l -> j + 1`` replace ``i+1 .. j`` by ``k+1 .. l``.

Applying a transformation (:func:`apply_transformation`) rebuilds the motion
from its node sequence: each run of consecutive graph frames is placed on
the ground by the 2D rigid motion (heading + translation) that puts the
graph frame before the run (``s - 1``, similar to the frame before the seam)
on the pose before the seam, so the root path and heading continue without
a jump.  Each seam is then blended (displacement-map style): the jump ``d``
between the frame after the seam and the natural successor of the frame
before it (every joint rotation, root included, as a rotation vector, and
the root height) is spread as ``+d w / 2`` before and ``-d w / 2`` after the
seam, ``w`` a raised cosine over ``blend`` seconds on each side (rotations
by slerp-style ``exp(c d) q``), so there is no pop.  (A frame that ends its
clip has no successor to compare with; its seam is not blended.)  The motion path and the time track
(uniform, one frame step per frame) follow from the new motion; constraints
follow their frames (see :class:`DiscreteSession`).

Pruning (section 5.2)
---------------------
* **duration**: the removed and the inserted intervals each last between
  ``min_duration`` and ``max_duration`` (0.3 and 2.0 s);
* **enclosing**: among transformations of the same character and type, one
  whose interval strictly contains another's is dropped (deletions and
  replacements compare the removed current frames, duplications the copied
  current frames, insertions the inserted graph frames at the same place;
  replacements must contain both intervals).  We compare within a type:
  an enclosed deletion would happen first as the user drags, but it says
  nothing about, e.g., a duplication;
* **constraints**: a transformation may not remove (delete or replace) a
  frame under an instant constraint, nor the first or last frame of a
  variational one; inserting frames anywhere is allowed;
* **locality**: :class:`Locality` enables transformations per character, per
  type, per time zone (reference-clock seconds of the edited motion) and per
  spatial region (ground positions of the edited path): the frames around
  the seams must all lie in an enabled zone and region.

Greedy optimisation (Algorithm 1)
---------------------------------
On every constraint update, every surviving transformation of every
character is evaluated by Laplacian editing of the transformed scene and
scored with equation 10,

    ``E = E_shape + E_scale + E_time + c_s sum_k |L_s(P'_k) - L_s(P_k)|
    + c_t sum_k |L_t(P'_k) - L_t(P_k)|``.

Following Algorithm 1 (``DeformationEnergy(P_c, P'_c, C)``), ``P`` here is
the *transformed, undeformed* path and ``P'`` its deformed, time-warped
version: the last two terms measure how much continuous editing had to
lengthen or shorten the paths and durations, which a well chosen discrete
transformation avoids (with the untransformed clip as reference, a
stretched walk would score the same with or without extra steps, because
scale compensation (equation 7) lets a straight path stretch at no cost).
The best candidate is applied if it lowers ``E`` by more than ``min_gain``;
at most one transformation per update (section 5.2).  ``edit(...,
discrete=True)`` and the first solve of a :class:`SceneEditor` repeat the
greedy step up to ``max_initial`` times (a jump from no constraints to the
given ones is like a long drag).

Evaluation uses subsampled paths (section 6): every ``subsample``-th frame
(25 by default), plus the first and last frames, every frame a constraint
row reads (constraint frames and the neighbours their tangents use),
stationary-segment boundaries, and the seam frames with their neighbours.
On the subsampled paths the three energies of section 4 are minimised with
non-uniform steps (time steps span several frames and are weighted by
``1/sqrt(m)`` so a uniform warp costs the same as on all frames), hard
constraints and rigid stationary segments are heavily weighted rows, and
modes no constraint determines are held by a tiny regulariser.  The length
change is measured on the full path: each subsampled chord's change scales
the arc length of the frames it spans.  Only the characters linked to the
transformed one by constraints are re-solved; the candidates of one
character are evaluated together in one batch (padded arrays, batched
dense solves), each character's systems coupled to the others' by the
Woodbury identity.  After a transformation is chosen the full scene is
solved once (the returned :class:`~mocaplab.editing.scene.EditResult`).
Our addition (``DiscreteOptions.verify``): the few best candidates are
re-scored on paths subsampled 1 in 5, and the chosen one is kept only if
the full solve confirms the gain, because the 1/25 subsampling sometimes
misjudges strongly curved paths and the transformation would be undone at
the next update.
"""

from __future__ import annotations

import dataclasses
import math
import time
import weakref
from collections.abc import Iterable, Mapping, Sequence
from typing import Any, Literal, cast

import numpy as np
import scipy.sparse as sp
from numpy.typing import NDArray
from scipy.linalg.lapack import dpbsv as _lapack_pbsv

from .. import quat
from ..motion import Motion
from .constraints import SPATIAL, TEMPORAL, ConstraintError, EndEffectorConstraint, Relative, Sync
from .energy import deformation_energy
from .graph import MotionGraph, SimilarityWeights, build_graph
from .laplacian import Layout, spatial_rows
from .paths import MotionPath
from .timewarp import temporal_rows

__all__ = [
    "TYPES",
    "Transformation",
    "Box",
    "Disk",
    "Locality",
    "DiscreteOptions",
    "Track",
    "DiscreteSession",
    "enumerate_transformations",
    "prune",
    "pruning_violations",
    "protected_frames",
    "apply_transformation",
    "discrete_update",
    "session",
]

Array = NDArray[np.float64]
IntArray = NDArray[np.int64]
Kind = Literal["deletion", "insertion", "duplication", "replacement"]

#: The transformation types (duplication is the special insertion of section 5.1).
TYPES: tuple[str, ...] = ("deletion", "insertion", "duplication", "replacement")


# ======================================================================
# transformations
# ======================================================================
@dataclasses.dataclass(frozen=True)
class Transformation:
    """One discrete transformation: current frames ``[a, b)`` become graph frames ``[s, e)``.

    Attributes
    ----------
    character : int
    kind : {"deletion", "insertion", "duplication", "replacement"}
    removed : (a, b)
        Half-open interval of the character's *current* frames removed
        (``a == b`` for an insertion: the new frames go before frame ``a``).
    inserted : (s, e)
        Half-open interval of motion-graph nodes inserted (``s == e`` for a
        deletion).
    fps : float
        Frame rate (durations below).
    cost : float
        Sum of the graph distances of its transitions (0 for natural seams).
    energy : float
        Equation-10 energy of the scene with this transformation (NaN if not
        evaluated).
    baseline : float
        The energy without it, at the same update (NaN if not evaluated).
    update : int
        Index of the constraint update at which it was applied (-1 if not).
    full_energy, full_baseline : float
        The same two energies from the full-resolution solve that verified
        it (NaN if not verified; see ``DiscreteOptions.verify``).
    """

    character: int
    kind: str
    removed: tuple[int, int]
    inserted: tuple[int, int]
    fps: float
    cost: float = 0.0
    energy: float = math.nan
    baseline: float = math.nan
    update: int = -1
    full_energy: float = math.nan
    full_baseline: float = math.nan

    @property
    def removed_duration(self) -> float:
        """Seconds of motion removed."""
        return (self.removed[1] - self.removed[0]) / self.fps

    @property
    def inserted_duration(self) -> float:
        """Seconds of motion inserted."""
        return (self.inserted[1] - self.inserted[0]) / self.fps

    @property
    def length_change(self) -> int:
        """Change of the frame count."""
        return (self.inserted[1] - self.inserted[0]) - (self.removed[1] - self.removed[0])

    @property
    def frames(self) -> tuple[int, int]:
        """Half-open interval of the new frames in the transformed motion (empty for a deletion)."""
        a = self.removed[0]
        return (a, a + self.inserted[1] - self.inserted[0])

    @property
    def span(self) -> tuple[int, int]:
        """Inclusive range of current frames the transformation touches (seams included).

        A duplication touches the copied frames too.
        """
        a, b = self.removed
        if self.kind == "duplication":
            return (a - 1, a + self.inserted[1] - self.inserted[0])
        return (a - 1, b)

    def __str__(self) -> str:
        a, b = self.removed
        s, e = self.inserted
        if self.kind == "deletion":
            what = f"delete frames {a}..{b - 1} ({self.removed_duration:.2f} s)"
        elif self.kind == "duplication":
            what = f"duplicate frames {a}..{a + e - s - 1} ({self.inserted_duration:.2f} s)"
        elif self.kind == "insertion":
            what = f"insert graph frames {s}..{e - 1} before frame {a} ({self.inserted_duration:.2f} s)"
        else:
            what = f"replace frames {a}..{b - 1} by graph frames {s}..{e - 1}"
        return f"character {self.character}: {what}"


# ======================================================================
# locality
# ======================================================================
@dataclasses.dataclass(frozen=True)
class Box:
    """Axis-aligned ground rectangle ``lo <= (x, z) <= hi`` (metres)."""

    lo: tuple[float, float]
    hi: tuple[float, float]

    def __post_init__(self) -> None:
        lo = np.asarray(self.lo, dtype=float)
        hi = np.asarray(self.hi, dtype=float)
        if lo.shape != (2,) or hi.shape != (2,) or not np.all(lo <= hi):
            raise ValueError(f"Expected Box corners lo <= hi as (x, z) pairs, got lo={self.lo!r}, hi={self.hi!r}")
        object.__setattr__(self, "lo", (float(lo[0]), float(lo[1])))
        object.__setattr__(self, "hi", (float(hi[0]), float(hi[1])))

    def contains(self, points: Any) -> NDArray[np.bool_]:
        """Which ground points ``(..., 2)`` are inside."""
        p = np.asarray(points, dtype=float)
        return np.all((p >= self.lo) & (p <= self.hi), axis=-1)


@dataclasses.dataclass(frozen=True)
class Disk:
    """Ground disk of ``radius`` metres around ``center`` ``(x, z)``."""

    center: tuple[float, float]
    radius: float

    def __post_init__(self) -> None:
        c = np.asarray(self.center, dtype=float)
        if c.shape != (2,) or not float(self.radius) > 0:
            raise ValueError(f"Expected Disk center (x, z) and radius > 0, got {self.center!r}, {self.radius!r}")
        object.__setattr__(self, "center", (float(c[0]), float(c[1])))
        object.__setattr__(self, "radius", float(self.radius))

    def contains(self, points: Any) -> NDArray[np.bool_]:
        p = np.asarray(points, dtype=float)
        return np.linalg.norm(p - self.center, axis=-1) <= self.radius


@dataclasses.dataclass(frozen=True)
class Locality:
    """Where and what discrete transformations may happen (section 5.2, "Locality").

    Parameters
    ----------
    characters : iterable of int, optional
        Characters allowed to change (default: all).
    types : iterable of str
        Enabled types among :data:`TYPES` (default: all).
    time_zones : sequence of (t0, t1), optional
        Reference-clock intervals (seconds, of the current edit) in which the
        frames around a transformation's seams must all lie (in one zone).
    regions : sequence of Box or Disk, optional
        Ground regions (current edited positions) in which those frames must
        all lie (in one region).

    Examples
    --------
    >>> Locality(types=("duplication",), regions=[Disk((0.0, 0.0), 2.0)]).types
    frozenset({'duplication'})
    """

    characters: frozenset[int] | None = None
    types: frozenset[str] = frozenset(TYPES)
    time_zones: tuple[tuple[float, float], ...] | None = None
    regions: tuple[Any, ...] | None = None

    def __post_init__(self) -> None:
        if self.characters is not None:
            object.__setattr__(self, "characters", frozenset(int(k) for k in self.characters))
        types = frozenset([self.types] if isinstance(self.types, str) else self.types)
        bad = sorted(types - set(TYPES))
        if bad:
            raise ValueError(f"Unknown transformation type(s) {bad}; expected some of {list(TYPES)}")
        object.__setattr__(self, "types", types)
        if self.time_zones is not None:
            zones = []
            for z in self.time_zones:
                t0, t1 = (float(v) for v in z)
                if not t0 <= t1:
                    raise ValueError(f"Expected time zones (t0, t1) with t0 <= t1, got {z!r}")
                zones.append((t0, t1))
            object.__setattr__(self, "time_zones", tuple(zones))
        if self.regions is not None:
            regions = tuple(self.regions)
            for r in regions:
                if not hasattr(r, "contains"):
                    raise TypeError(f"Expected regions with a .contains(points) method (Box, Disk), got {r!r}")
            object.__setattr__(self, "regions", regions)

    def allows(self, t: Transformation, times: Array | None = None, positions: Array | None = None) -> bool:
        """Whether ``t`` is enabled, given the edited ``times`` (F,) and ``positions`` (F, 2) of its character."""
        if self.characters is not None and t.character not in self.characters:
            return False
        if t.kind not in self.types:
            return False
        lo, hi = t.span
        if self.time_zones is not None:
            if times is None:
                return False
            tt = np.asarray(times)[max(lo, 0) : hi + 1]
            if not any(bool(np.all((tt >= z0) & (tt <= z1))) for z0, z1 in self.time_zones):
                return False
        if self.regions is not None:
            if positions is None:
                return False
            pp = np.asarray(positions)[max(lo, 0) : hi + 1]
            if not any(bool(np.all(r.contains(pp))) for r in self.regions):
                return False
        return True


@dataclasses.dataclass(frozen=True)
class DiscreteOptions:
    """Options of discrete editing (pass as ``discrete=DiscreteOptions(...)``; ``True`` = defaults).

    Parameters
    ----------
    graphs : mapping {character: MotionGraph}, optional
        Motion graph of each character; it must contain a clip with the
        character's poses (:meth:`MotionGraph.clip_index`).  Default: a graph
        of the character's own clip (:func:`~mocaplab.editing.graph.build_graph`
        with ``threshold``, ``window``, ``min_gap``, ``weights``).
    locality : Locality or mapping {character: Locality}
    min_duration, max_duration : float
        Duration pruning, seconds (0.3 and 2.0 in the paper).
    cs, ct : float
        Weights of the length (per metre) and duration (per second) terms of
        equation 10.
    subsample : int
        One frame in ``subsample`` is kept for the evaluation (1/25 in the
        paper), plus the frames listed in the module docstring.
    blend : float
        Seconds blended on each side of a seam.
    min_gain : float
        A transformation is applied only if it lowers the energy by more than this.
    max_initial : int
        Greedy steps on the first solve (``edit``); later updates apply at most one.
    verify : int
        Our safeguard (0 turns it off: the paper's procedure).  The 1/25
        subsampling can misjudge strongly curved paths, so the best
        ``verify`` candidates are re-scored on paths subsampled
        ``verify_subsample``; the best that still gains is applied and
        solved at full resolution, and kept only if its full-resolution
        equation-10 energy is lower than the current one by more than
        ``min_gain`` (otherwise nothing changes at this update).  This
        keeps a transformation from being applied and undone at the next
        update.
    verify_subsample : int
        Subsampling ratio of that second scoring (1 in 5 frames).
    """

    graphs: Mapping[int, MotionGraph] | None = None
    locality: Locality | Mapping[int, Locality] = Locality()
    min_duration: float = 0.3
    max_duration: float = 2.0
    cs: float = 1.0
    ct: float = 1.0
    subsample: int = 25
    blend: float = 0.2
    min_gain: float = 0.1
    max_initial: int = 8
    verify: int = 3
    verify_subsample: int = 5
    threshold: float = 0.1
    window: float = 0.5
    min_gap: float = 0.3
    weights: SimilarityWeights | None = None

    def __post_init__(self) -> None:
        if not 0 < self.min_duration <= self.max_duration:
            raise ValueError(
                f"Expected 0 < min_duration <= max_duration, got {self.min_duration} and {self.max_duration}"
            )
        for name in ("cs", "ct", "blend", "min_gain"):
            v = float(getattr(self, name))
            if not (math.isfinite(v) and v >= 0):
                raise ValueError(f"Expected `{name}` >= 0, got {getattr(self, name)!r}")
        for name in ("subsample", "verify_subsample"):
            if int(getattr(self, name)) < 1:
                raise ValueError(f"Expected `{name}` >= 1, got {getattr(self, name)!r}")
        if int(self.verify) < 0:
            raise ValueError(f"Expected `verify` >= 0, got {self.verify!r}")
        if int(self.max_initial) < 0:
            raise ValueError(f"Expected `max_initial` >= 0, got {self.max_initial!r}")
        if not isinstance(self.locality, Locality) and not isinstance(self.locality, Mapping):
            raise TypeError(f"Expected `locality` as a Locality or a mapping of them, got {self.locality!r}")

    def locality_of(self, character: int) -> Locality:
        if isinstance(self.locality, Locality):
            return self.locality
        return self.locality.get(character, Locality())


# ======================================================================
# ground poses and motion assembly
# ======================================================================
def _rot2(theta: Any, v: Array) -> Array:
    """Rotate ground vectors ``(x, z)`` by yaw ``theta`` (the rotation of :func:`mocaplab.quat.from_yaw`)."""
    c, s = np.cos(theta), np.sin(theta)
    x, z = v[..., 0], v[..., 1]
    return np.stack([c * x + s * z, -s * x + c * z], axis=-1)


class _GraphData:
    """Arrays of a motion graph gathered once: poses, ground poses, arc lengths, adjacency."""

    _cache: weakref.WeakKeyDictionary[MotionGraph, _GraphData] = weakref.WeakKeyDictionary()

    def __init__(self, g: MotionGraph) -> None:
        self.graph = g
        self.rot = np.concatenate([np.asarray(m.rotations) for m in g.clips])
        self.root = np.concatenate([np.asarray(m.root_positions) for m in g.clips])
        trs = [m.translations for m in g.clips]
        self.translations = None if any(t is None for t in trs) else np.concatenate([np.asarray(t) for t in trs])
        self.pos = self.root[:, [0, 2]]
        self.yaw = np.unwrap(quat.yaw(self.rot[:, 0]))
        self.clip = g.clip_of
        self.first = np.zeros(g.n_frames, bool)
        self.first[g.offsets[:-1]] = True
        self.last = np.zeros(g.n_frames, bool)
        self.last[g.offsets[1:] - 1] = True
        step = np.linalg.norm(np.diff(self.pos, axis=0), axis=1)
        step[self.last[:-1]] = 0.0
        # arc length along the clips (only differences within one clip are used)
        self.arc = np.concatenate([[0.0], np.cumsum(step)])
        src, dst, cost = g.transitions()
        n = g.n_frames
        self.T = sp.csr_matrix((cost + 1e-300, (src, dst)), shape=(n, n))
        self.Tt = self.T.T.tocsr()
        self.costs = {(int(a), int(b)): float(c) for a, b, c in zip(src, dst, cost, strict=True)}
        self.n_out = np.diff(self.T.indptr)
        self.n_in = np.diff(self.Tt.indptr)

    @classmethod
    def of(cls, g: MotionGraph) -> _GraphData:
        d = cls._cache.get(g)
        if d is None:
            d = cls(g)
            cls._cache[g] = d
        return d

    def out(self, node: int) -> IntArray:
        """Transition targets from ``node`` (graph transitions only)."""
        s, e = self.T.indptr[node], self.T.indptr[node + 1]
        return self.T.indices[s:e]

    def into(self, node: int) -> IntArray:
        """Transition sources into ``node``."""
        s, e = self.Tt.indptr[node], self.Tt.indptr[node + 1]
        return self.Tt.indices[s:e]

    def natural(self, a: int, b: int) -> bool:
        return b == a + 1 and not self.last[a]

    def seam_cost(self, a: int, b: int) -> float | None:
        """Cost of going from node ``a`` to node ``b`` (0 natural, None if not allowed)."""
        if self.natural(a, b):
            return 0.0
        return self.costs.get((a, b))


def _runs(nodes: IntArray, gd: _GraphData) -> IntArray:
    """Start positions of runs of consecutive graph frames (first is 0)."""
    if len(nodes) == 0:
        return np.zeros(0, np.int64)
    brk = (np.diff(nodes) != 1) | gd.last[nodes[:-1]]
    return np.concatenate([[0], np.flatnonzero(brk) + 1]).astype(np.int64)


def _placement(nodes: IntArray, gd: _GraphData, first: tuple[float, float, float]) -> tuple[Array, Array]:
    """Per-frame ground transforms ``(theta (F,), t (F, 2))`` placing each run after the previous.

    ``first`` = (x, z, yaw) where the first frame goes.
    """
    F = len(nodes)
    theta = np.empty(F)
    trans = np.empty((F, 2))
    starts = _runs(nodes, gd)
    ends = np.concatenate([starts[1:], [F]])
    x0, z0, y0 = first
    for r, (a, b) in enumerate(zip(starts, ends, strict=True)):
        s = int(nodes[a])
        if r == 0:
            th = y0 - gd.yaw[s]
            t = np.array([x0, z0]) - _rot2(th, gd.pos[s])
        else:
            prev_pos = _rot2(theta[a - 1], gd.pos[nodes[a - 1]]) + trans[a - 1]
            prev_yaw = gd.yaw[nodes[a - 1]] + theta[a - 1]
            ref = s - 1 if not gd.first[s] else s
            th = prev_yaw - gd.yaw[ref]
            t = prev_pos - _rot2(th, gd.pos[ref])
        theta[a:b] = th
        trans[a:b] = t
    return theta, trans


def _blend_weights(n: int) -> Array:
    m = np.arange(n)
    return 0.5 * (1.0 + np.cos(np.pi * m / n))


def _assemble(
    nodes: IntArray,
    gd: _GraphData,
    first: tuple[float, float, float],
    skeleton: Any,
    fps: float,
    blend: float,
    name: str,
) -> Motion:
    """The motion playing graph ``nodes``, runs placed on the ground and seams blended."""
    theta, trans = _placement(nodes, gd, first)
    rot = gd.rot[nodes].copy()
    rot[:, 0] = quat.mul(quat.from_yaw(theta), rot[:, 0])
    root = gd.root[nodes].copy()
    root[:, [0, 2]] = _rot2(theta, gd.pos[nodes]) + trans
    tr = None if gd.translations is None else gd.translations[nodes].copy()
    F = len(nodes)
    n = int(round(blend * fps))
    starts = _runs(nodes, gd)[1:]
    if n >= 1 and len(starts):
        w = _blend_weights(n)
        dr = np.zeros((F,) + rot.shape[1:-1] + (3,))
        dy = np.zeros(F)
        for a in starts:
            prev = int(nodes[a - 1])
            if gd.last[prev]:
                continue  # no natural successor to compare with: the similar frame is the best guess
            exp_node = prev + 1
            act = int(nodes[a])
            d_local = quat.log(quat.mul(gd.rot[act], quat.inv(gd.rot[exp_node])))
            exp_root = quat.mul(quat.from_yaw(theta[a - 1]), gd.rot[exp_node, 0])
            d_local[0] = quat.log(quat.mul(rot[a, 0], quat.inv(exp_root)))
            d_h = gd.root[act, 1] - gd.root[exp_node, 1]
            before = a - 1 - np.arange(n)
            after = a + np.arange(n)
            okb = before >= 0
            oka = after < F
            cb = 0.5 * w[okb]
            ca = -0.5 * w[oka]
            dr[before[okb]] += cb[:, None, None] * d_local
            dr[after[oka]] += ca[:, None, None] * d_local
            dy[before[okb]] += cb * d_h
            dy[after[oka]] += ca * d_h
        touched = np.flatnonzero(np.any(dr != 0, axis=(1, 2)) | (dy != 0))
        rot[touched] = quat.normalize(quat.mul(quat.exp(dr[touched]), rot[touched]))
        root[:, 1] += dy
    return Motion(skeleton, rot, root, fps, translations=tr, name=name)


# ======================================================================
# tracks: a character's current structure
# ======================================================================
@dataclasses.dataclass(frozen=True, eq=False)
class Track:
    """A character's current motion as a sequence of graph nodes.

    Attributes
    ----------
    graph : MotionGraph
    nodes : ndarray of int, shape (F,)
        Graph node played at each current frame.
    origin : ndarray of int, shape (F,)
        Frame of the character's input clip that each current frame *is*
        (constraints follow it), or -1 for frames added by a transformation.
        Of the two copies a duplication makes, the later one keeps the
        origin, so a constraint on a clip's last frame stays on the last frame.
    first : (x, z, yaw)
        Ground pose of the first frame.
    motion : Motion
        The assembled, blended motion.
    """

    graph: MotionGraph
    nodes: IntArray
    origin: IntArray
    first: tuple[float, float, float]
    motion: Motion

    @property
    def n_frames(self) -> int:
        return len(self.nodes)

    @classmethod
    def from_motion(cls, motion: Motion, graph: MotionGraph) -> Track:
        """The track of an unedited clip of ``graph``."""
        c = graph.clip_index(motion)
        if c is None:
            raise ValueError(
                f"The motion graph has no clip with the poses of {motion!r}: build it with the character's clip "
                "among its clips (build_graph([motion, ...]))"
            )
        nodes = graph.offsets[c] + np.arange(motion.n_frames, dtype=np.int64)
        origin = np.arange(motion.n_frames, dtype=np.int64)
        p = motion.root_positions[0]
        first = (float(p[0]), float(p[2]), float(quat.yaw(motion.rotations[0, 0])))
        return cls(graph, nodes, origin, first, motion)

    def frame_of(self, original: int) -> int:
        """Current frame of the input clip's frame ``original`` (the nearest surviving one if removed)."""
        live = np.flatnonzero(self.origin >= 0)
        orig = self.origin[live]
        i = int(np.searchsorted(orig, original))
        if i < len(orig) and orig[i] == original:
            return int(live[i])
        if i == 0:
            return int(live[0])
        if i >= len(orig):
            return int(live[-1])
        return int(live[i] if orig[i] - original < original - orig[i - 1] else live[i - 1])


def _check_transformation(track: Track, t: Transformation) -> None:
    F = track.n_frames
    a, b = t.removed
    s, e = t.inserted
    if not (1 <= a <= b <= F - 1):
        raise ValueError(f"Expected removed frames (a, b) with 1 <= a <= b <= {F - 1}, got {t.removed}")
    if not 0 <= s <= e <= track.graph.n_frames:
        raise ValueError(f"Expected inserted graph frames within 0..{track.graph.n_frames}, got {t.inserted}")
    if a == b and s == e:
        raise ValueError("Expected a transformation that removes or inserts frames, got an empty one")


def apply_transformation(track: Track, t: Transformation, *, blend: float = 0.2) -> Track:
    """The track after ``t`` (motion, path and time track rebuilt; see the module docstring).

    Parameters
    ----------
    track : Track
    t : Transformation
    blend : float
        Seconds blended on each side of each seam.

    Returns
    -------
    Track
    """
    _check_transformation(track, t)
    gd = _GraphData.of(track.graph)
    a, b = t.removed
    s, e = t.inserted
    ins = np.arange(s, e, dtype=np.int64)
    nodes = np.concatenate([track.nodes[:a], ins, track.nodes[b:]])
    new_origin = np.full(e - s, -1, dtype=np.int64)
    origin = np.concatenate([track.origin[:a], new_origin, track.origin[b:]])
    m = track.motion
    motion = _assemble(nodes, gd, track.first, m.skeleton, m.fps, blend, m.name)
    return Track(track.graph, nodes, origin, track.first, motion)


# ======================================================================
# enumeration and pruning
# ======================================================================
def _positions_of(nodes: IntArray) -> dict[int, IntArray]:
    """Current frames playing each node."""
    if len(nodes) == 0:
        return {}
    order = np.argsort(nodes, kind="stable")
    cuts = np.flatnonzero(np.diff(nodes[order])) + 1
    return {int(nodes[g[0]]): g for g in np.split(order, cuts)}


def enumerate_transformations(
    track: Track,
    *,
    character: int = 0,
    min_duration: float = 0.3,
    max_duration: float = 2.0,
) -> list[Transformation]:
    """Every deletion, insertion, duplication and replacement the graph allows (duration-pruned).

    Parameters
    ----------
    track : Track
    character : int
        Stored in the results.
    min_duration, max_duration : float
        Removed and inserted intervals must each last this long (seconds).

    Returns
    -------
    list of Transformation
        Distinct by their resulting node sequence.
    """
    gd = _GraphData.of(track.graph)
    nodes = track.nodes
    F = len(nodes)
    fps = float(track.motion.fps)
    lmin = max(1, int(math.ceil(min_duration * fps - 1e-9)))
    lmax = int(math.floor(max_duration * fps + 1e-9))
    where = _positions_of(nodes)
    out: dict[tuple[int, int, int, int], Transformation] = {}

    def add(kind: str, a: int, b: int, s: int, e: int, cost: float) -> None:
        key = (a, b, s, e)
        if key not in out:
            out[key] = Transformation(character, kind, (a, b), (s, e), fps, cost)

    # seams currently in the sequence (after earlier transformations)
    seam_after = np.zeros(F, bool)
    if F > 1:
        seam_after[:-1] = (np.diff(nodes) != 1) | gd.last[nodes[:-1]]
    # outgoing seams x -> node n (x = a - 1), incoming seams node u -> y (y = b)
    has_out = gd.n_out[nodes] > 0
    has_in = gd.n_in[nodes] > 0

    # ---- deletions: seam x -> y with src[y] a successor of src[x]
    repeated = np.array([n for n, g in where.items() if len(g) > 1], dtype=np.int64)
    for x in (int(v) for v in np.flatnonzero(has_out[: F - 1] | np.isin(nodes[: F - 1] + 1, repeated))):
        targets = list(gd.out(int(nodes[x])))
        if not gd.last[nodes[x]]:
            targets.append(int(nodes[x]) + 1)
        for d in targets:
            for y in (int(v) for v in where.get(int(d), ())):
                L = y - x - 1
                if lmin <= L <= lmax and y <= F - 1:
                    c = gd.seam_cost(int(nodes[x]), int(d))
                    if c is not None:
                        add("deletion", x + 1, y, 0, 0, c)

    # ---- insertions (duplication included): before frame a, graph run [s, u]
    cand_a = np.flatnonzero(
        np.concatenate([[False], has_out[: F - 1]]) | has_in | np.concatenate([[False], seam_after[: F - 1]])
    )
    for a in (int(v) for v in cand_a):
        if not 1 <= a <= F - 1:
            continue
        prev, nxt = int(nodes[a - 1]), int(nodes[a])
        S = set(int(v) for v in gd.out(prev))
        if not gd.last[prev]:
            S.add(prev + 1)
        U = set(int(v) for v in gd.into(nxt))
        if not gd.first[nxt]:
            U.add(nxt - 1)
        for s in S:
            for u in U:
                L = u - s + 1
                if not lmin <= L <= lmax or gd.clip[s] != gd.clip[u] or gd.last[s:u].any():
                    continue
                c1 = gd.seam_cost(prev, s)
                c2 = gd.seam_cost(u, nxt)
                if c1 is None or c2 is None:
                    continue
                if c1 == 0.0 and c2 == 0.0 and not seam_after[a - 1]:
                    continue
                # duplication: the run equals the current frames that follow (the copy goes first)
                if a + L <= F and np.array_equal(nodes[a : a + L], np.arange(s, u + 1)):
                    add("duplication", a, a, s, u + 1, c1 + c2)
                elif a - L >= 1 and np.array_equal(nodes[a - L : a], np.arange(s, u + 1)):
                    # the same sequence as duplicating before a - L: keep the canonical form
                    add("duplication", a - L, a - L, s, u + 1, c1 + c2)
                else:
                    add("insertion", a, a, s, u + 1, c1 + c2)

    # ---- replacements: seam x=a-1 -> s (s != src[a]) and u -> y=b (u != src[b-1])
    outs: list[tuple[int, int]] = []
    for xo in np.flatnonzero(has_out[: F - 1]):
        for so in gd.out(int(nodes[xo])):
            if int(so) != int(nodes[xo + 1]):
                outs.append((int(xo), int(so)))
    ins: list[tuple[int, int]] = []
    for yi in np.flatnonzero(has_in):
        for ui in gd.into(int(nodes[yi])):
            if yi >= 1 and int(ui) != int(nodes[yi - 1]):
                ins.append((int(yi), int(ui)))
    for x, s in outs:
        a = x + 1
        for y, u in ins:
            b = y
            if not lmin <= b - a <= lmax or b > F - 1:
                continue
            L = u - s + 1
            if not lmin <= L <= lmax or gd.clip[s] != gd.clip[u] or gd.last[s:u].any():
                continue
            net = abs(L - (b - a))
            if net and net < lmin:
                continue  # a replacement changing the duration by a sliver: too frequent (duration rule)
            if b - a == L and np.array_equal(nodes[a:b], np.arange(s, u + 1)):
                continue
            c1 = gd.seam_cost(int(nodes[x]), s)
            c2 = gd.seam_cost(u, int(nodes[y]))
            if c1 is None or c2 is None:
                continue
            add("replacement", a, b, s, u + 1, c1 + c2)
    return sorted(out.values(), key=lambda t: (t.removed, t.inserted))


def protected_frames(constraints: Iterable[Any], character: int) -> set[int]:
    """Frames of ``character`` that may not be removed (section 5.2, "Constraints").

    Every frame of an instant constraint, and the first and last frames of
    a variational one (also for end-effector constraints of
    :mod:`mocaplab.refine`).
    """
    out: set[int] = set()
    for c in constraints:
        out |= _protected(c).get(character, set())
    return out


def _protected(c: Any) -> dict[int, set[int]]:
    res: dict[int, set[int]] = {}

    def put(k: int, f: int) -> None:
        res.setdefault(int(k), set()).add(int(f))

    if isinstance(c, EndEffectorConstraint):
        inner = c.constraint
        k = c.character
        return {k: set(_effector_frames(inner))} if hasattr(inner, "frames") else {}
    if type(c).__name__ == "EndEffector" and hasattr(c, "frames"):
        return {int(c.character): set(_effector_frames(c))}
    if not isinstance(c, SPATIAL + TEMPORAL):
        return res
    cc: Any = c
    frames = getattr(cc, "frames", None)
    if frames is None:
        put(cc.character, cc.frame)
        if hasattr(cc, "end_frame"):
            put(cc.character, cc.end_frame)
        other = getattr(cc, "other", None)
        if other is not None:
            put(other, cc.other_frame)
        return res
    put(c.character, frames[0])
    put(c.character, frames[1])
    other = getattr(c, "other", None)
    if other is not None:
        of = getattr(c, "other_frames", None) or frames
        put(other, of[0])
        put(other, of[1])
    return res


def _effector_frames(e: Any) -> list[int]:
    f = e.frames
    if isinstance(f, (int, np.integer)):
        return [int(f)]
    if isinstance(f, tuple) and len(f) == 2:
        return [int(f[0]), int(f[1]) - 1]
    if isinstance(f, range):
        return [f[0], f[-1]] if len(f) else []
    return [int(v) for v in f]


def pruning_violations(
    t: Transformation,
    *,
    constraints: Sequence[Any] = (),
    min_duration: float = 0.3,
    max_duration: float = 2.0,
    locality: Locality | None = None,
    times: Array | None = None,
    positions: Array | None = None,
) -> tuple[str, ...]:
    """Which pruning rules ``t`` breaks (empty if none): "duration", "constraints", "locality".

    ``constraints`` refer to the current frames of the character at the
    time ``t`` is considered; ``times``/``positions`` are its edited ones
    (for locality zones and regions).
    """
    return _violations(
        t, protected_frames(constraints, t.character), min_duration, max_duration, locality, times, positions
    )


def _violations(
    t: Transformation,
    prot: set[int],
    min_duration: float,
    max_duration: float,
    locality: Locality | None,
    times: Array | None,
    positions: Array | None,
) -> tuple[str, ...]:
    out = []
    eps = 1e-9
    for n in (t.removed[1] - t.removed[0], t.inserted[1] - t.inserted[0]):
        if n and not (min_duration - eps <= n / t.fps <= max_duration + eps):
            out.append("duration")
            break
    a, b = t.removed
    if any(a <= f < b for f in prot):
        out.append("constraints")
    if locality is not None and not locality.allows(t, times, positions):
        out.append("locality")
    return tuple(out)


def _interval(t: Transformation) -> tuple[Any, int, int]:
    """Group key and interval compared by the enclosing rule."""
    if t.kind == "deletion":
        return ("del",), t.removed[0], t.removed[1]
    if t.kind == "duplication":
        return ("dup",), t.removed[0], t.removed[0] + t.inserted[1] - t.inserted[0]
    if t.kind == "insertion":
        return ("ins", t.removed[0]), t.inserted[0], t.inserted[1]
    return ("rep",), t.removed[0], t.removed[1]


def _encloses(A: Transformation, B: Transformation) -> bool:
    ka, a0, a1 = _interval(A)
    kb, b0, b1 = _interval(B)
    if A.character != B.character or ka != kb:
        return False
    if A.kind == "replacement":
        inner = B.inserted[0] >= A.inserted[0] and B.inserted[1] <= A.inserted[1]
        return a0 <= b0 and b1 <= a1 and inner and (A.removed, A.inserted) != (B.removed, B.inserted)
    return a0 <= b0 and b1 <= a1 and (a0, a1) != (b0, b1)


def prune(
    candidates: Sequence[Transformation],
    *,
    constraints: Sequence[Any] = (),
    locality: Locality | None = None,
    times: Mapping[int, Array] | None = None,
    positions: Mapping[int, Array] | None = None,
    min_duration: float = 0.3,
    max_duration: float = 2.0,
) -> list[Transformation]:
    """Apply the four pruning rules of section 5.2 (module docstring).

    Duration, constraint and locality rules first, then enclosing among
    the survivors.  ``times``/``positions`` map a character to its edited
    frame times and ground positions.
    """
    kept = []
    prot: dict[int, set[int]] = {}
    for c in constraints:
        for k, fs in _protected(c).items():
            prot.setdefault(k, set()).update(fs)
    for t in candidates:
        v = _violations(
            t,
            prot.get(t.character, set()),
            min_duration,
            max_duration,
            locality,
            None if times is None else times.get(t.character),
            None if positions is None else positions.get(t.character),
        )
        if not v:
            kept.append(t)
    groups: dict[tuple[Any, ...], list[Transformation]] = {}
    for t in kept:
        groups.setdefault((t.character, _interval(t)[0]), []).append(t)
    out = []
    for g in groups.values():
        for A in g:
            if not any(_encloses(A, B) for B in g if B is not A):
                out.append(A)
    return sorted(out, key=lambda t: (t.character, t.removed, t.inserted))


# ======================================================================
# subsampled evaluation (Algorithm 1, lines 4-8)
# ======================================================================
_PENALTY = 1e4  # weight of hard constraints and rigid rows in the evaluation
_EPS = 1e-8  # regulariser of the free modes
_BAND = {2: 5, 1: 1}  # bandwidth (in unknowns) of the path rows for 2D (space) and 1D (time)


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


@dataclasses.dataclass
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


@dataclasses.dataclass
class _Part:
    """One character's subsampled path for the evaluation."""

    frames: IntArray  # kept frames (sorted), shape (n,)
    X: Array  # their ground positions, (n, 2)
    arc: Array  # arc length of the full path between successive kept frames, (n - 1,)
    rigid_pt: NDArray[np.bool_]  # kept frame strictly inside a stationary segment, (n,)
    rigid_step: NDArray[np.bool_]  # both ends of the step in one segment, (n - 1,)
    n_frames: int  # full frame count
    dt: float
    start: float


def _rigid(frames: IntArray, segments: Sequence[tuple[int, int]]) -> tuple[NDArray[np.bool_], NDArray[np.bool_]]:
    pt = np.zeros(len(frames), bool)
    st = np.zeros(max(len(frames) - 1, 0), bool)
    for a, b in segments:
        inside = (frames >= a) & (frames < b)
        pt |= (frames > a) & (frames < b - 1)
        st |= inside[:-1] & inside[1:]
    return pt, st


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
    if cols.shape[0] == 1:  # the same columns for every path
        return x[:, cols[0]]
    flat = cols.reshape(c, -1)
    return np.take_along_axis(x, flat, axis=1).reshape(cols.shape)


def _band(c: int, n: int, u: int, cols: IntArray, vals: Array) -> Array:
    """Batched normal matrices ``sum_rows r r^T`` in LAPACK upper band storage (c, u + 1, n).

    Every row's columns must lie within ``u`` of each other.
    """
    ci = np.arange(c, dtype=np.int64)[:, None, None, None]
    c1 = cols[:, :, :, None]
    c2 = cols[:, :, None, :]
    v = vals[:, :, :, None] * vals[:, :, None, :]
    m = np.broadcast_to(c1 <= c2, v.shape)
    idx = (ci * (u + 1) + (u + c1 - c2)) * n + c2
    idx = np.broadcast_to(idx, v.shape)
    return np.bincount(idx[m], v[m], minlength=c * (u + 1) * n).astype(float).reshape(c, u + 1, n)


def _pbsv(ab: Array, b: Array) -> Array:
    """Solve one banded SPD system (LAPACK ``pbsv``: an unblocked banded Cholesky, fast for small bands)."""
    _, x, info = _lapack_pbsv(ab, b)
    if info != 0:  # pragma: no cover - the regulariser keeps the matrices definite
        raise np.linalg.LinAlgError(f"banded Cholesky failed (info={info})")
    return x


def _pbsolve(ab: Array, b: Array) -> Array:
    """Batched banded solves: ab (c, u + 1, n), b (c, n, k) -> (c, n, k)."""
    return np.stack([_pbsv(ab[i], b[i]) for i in range(ab.shape[0])])


def _local(cols: IntArray, vals: Array, u: int) -> NDArray[np.bool_]:
    """Rows (of every path in the batch) whose columns fit in a band of width ``u``."""
    if cols.shape[1] == 0:
        return np.zeros(0, bool)
    big = np.where(vals != 0, cols, cols[..., :1])
    return np.all(big.max(axis=-1) - big.min(axis=-1) <= u, axis=0)


def _rhs(n: int, cols: IntArray, vals: Array, rhs: Array) -> Array:
    """Batched ``M^T rhs``: cols/vals (c, R, W), rhs (c, R) -> (c, n)."""
    w = vals * rhs[:, :, None]
    c = max(w.shape[0], cols.shape[0])
    w = np.broadcast_to(w, (c,) + w.shape[1:])
    idx = np.broadcast_to(np.arange(c, dtype=np.int64)[:, None, None] * n + cols, w.shape)
    return np.bincount(idx.ravel(), w.ravel(), minlength=c * n).astype(float).reshape(c, n)


def _res(cols: IntArray, vals: Array, rhs: Array, x: Array) -> Array:
    """Batched residuals ``M x - rhs``: (c, R)."""
    return np.sum(vals * _gather(x, cols), axis=-1) - rhs


def _pad(*groups: tuple[IntArray, Array]) -> tuple[IntArray, Array]:
    """Concatenate row groups (c, R_g, W_g) along rows, padding widths (value 0)."""
    W = max(g[0].shape[2] for g in groups)
    c = max(max(g[0].shape[0], g[1].shape[0]) for g in groups)
    cs, vs = [], []
    for cc, vv in groups:
        cc = np.broadcast_to(cc, (c,) + cc.shape[1:])
        _, R, w = cc.shape
        if w < W:
            cc = np.concatenate([cc, np.repeat(cc[:, :, :1], W - w, axis=2)], axis=2)
            vv = np.concatenate([vv, np.zeros((vv.shape[0], R, W - w))], axis=2)
        cs.append(cc)
        vs.append(np.broadcast_to(vv, (c, R, W)))
    return np.concatenate(cs, axis=1), np.concatenate(vs, axis=1)


class _Batch:
    """One character's three subsampled systems (shape, scale, time) for a batch of paths.

    ``parts`` (candidates, or the untransformed path) are padded to a common
    number of kept frames; padded unknowns are decoupled (identity rows).
    Each system is factorised per path; the constraint rows linking the
    character to others are kept apart (``U``) for the Woodbury identity.
    """

    def __init__(
        self,
        parts: Sequence[_Part],
        k: int,
        fmaps: Sequence[IntArray | None],
        space: _Rows,
        time: _Rows,
        cross_s: IntArray,
        cross_t: IntArray,
        pen: float,
    ) -> None:
        c = len(parts)
        self.c = c
        nv = np.array([len(p.frames) for p in parts], dtype=np.int64)
        n = int(nv.max())
        self.n, self.nv = n, nv
        idx = np.arange(n)
        valid = idx[None, :] < nv[:, None]
        self.valid = valid
        fr = np.full((c, n), 0, dtype=np.int64)
        X = np.zeros((c, n, 2))
        arc = np.zeros((c, max(n - 1, 0)))
        rpt = np.zeros((c, n), bool)
        rst = np.zeros((c, max(n - 1, 0)), bool)
        big = max(int(p.frames[-1]) for p in parts) + 1
        for i, p in enumerate(parts):
            m = nv[i]
            fr[i, :m] = p.frames
            fr[i, m:] = big
            X[i, :m] = p.X
            X[i, m:] = p.X[-1]
            arc[i, : m - 1] = p.arc
            rpt[i, :m] = p.rigid_pt
            rst[i, : m - 1] = p.rigid_step
        self.frames, self.X, self.arc = fr, X, arc
        self.n_frames = np.array([p.n_frames for p in parts], dtype=float)
        self.dt = parts[0].dt
        self.start = parts[0].start
        sq = math.sqrt(pen)
        vstep = valid[:, 1:]
        span = np.where(vstep, np.diff(fr, axis=1), 1).astype(float)
        self.span = span
        n2 = 2 * n

        # ---- constraint rows of this character: local (its own) and coupled (with others)
        def kidx(frames: IntArray) -> IntArray:
            q = np.stack([frames if f is None else f[np.minimum(frames, len(f) - 1)] for f in fmaps])
            return _bsearch(fr, nv, q)

        # rows on this character alone that fit the band go into its own system; the
        # others (and the rows linking characters) are coupled by the Woodbury identity
        touch_s = np.any((space.char == k) & (space.val != 0), axis=1)
        intra = np.flatnonzero(touch_s & space.intra)
        cols = 2 * kidx(space.frame[intra]) + space.coord[intra][None]
        ok = _local(cols, space.val[intra][None], _BAND[2])
        self.s_local = intra[ok]
        self.s_cols = cols[:, ok]
        sv = np.broadcast_to(space.val[self.s_local][None], self.s_cols.shape)
        s_rhs = np.broadcast_to(space.rhs[self.s_local][None], (c, len(self.s_local)))
        cross_s = np.union1d(cross_s, intra[~ok])
        touch_t = np.any((time.char == k) & (time.val != 0), axis=1)
        intra = np.flatnonzero(touch_t & time.intra)
        cols = kidx(time.frame[intra])
        ok = _local(cols, time.val[intra][None], _BAND[1])
        self.t_local = intra[ok]
        self.t_cols = cols[:, ok]
        tvl = np.broadcast_to(time.val[self.t_local][None], self.t_cols.shape)
        t_rhs = np.broadcast_to(time.rhs[self.t_local][None], (c, len(self.t_local)))
        cross_t = np.union1d(cross_t, intra[~ok])
        self.s_soft = space.soft[self.s_local]
        self.t_soft = time.soft[self.t_local]
        self.s_loc = (self.s_cols, sv, s_rhs)
        self.t_loc = (self.t_cols, tvl, t_rhs)
        # coupled rows: U (c, r, unknowns) on this character's entries
        self.cross_s, self.cross_t = cross_s.astype(np.int64), cross_t.astype(np.int64)
        self.Us = self._coupled(space, self.cross_s, k, kidx, 2, n2, c)
        self.Ut = self._coupled(time, self.cross_t, k, kidx, 1, n, c)
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
            rig = rpt[:, 1:-1]
            wr = np.where(vint, np.where(rig, sq, mbar**-1.5), 0.0)
            g = idx[1:-1]
            X0, X1, X2 = 2 * (g - 1), 2 * g, 2 * (g + 1)
            one = np.ones_like(lx)
            rx_c = np.stack([X1, X0, X2, X0, X2 + 1, X0 + 1], axis=-1)
            rz_c = np.stack([X1 + 1, X0 + 1, X2 + 1, X0 + 1, X2, X0], axis=-1)
            rx_v = np.stack([one, -one, -lx, lx, -ly, ly], axis=-1)
            rz_v = np.stack([one, -one, -lx, lx, ly, -ly], axis=-1)
            lap_c = np.stack([rx_c, rz_c], axis=1).reshape(1, -1, 6)
            lap_v = (np.stack([rx_v, rz_v], axis=2) * wr[:, :, None, None]).reshape(c, -1, 6)
            self.lap_energy = np.repeat(vint & ~rig, 2, axis=1)
        else:
            lap_c, lap_v = np.zeros((c, 0, 6), np.int64), np.zeros((c, 0, 6))
            self.lap_energy = np.zeros((c, 0), bool)
        self.lap = (lap_c, lap_v)
        pad = np.repeat(~valid, 2, axis=1)
        u2 = _BAND[2]
        c1, v1 = _pad(self.lap, self.s_loc[:2])
        N1 = _band(c, n2, u2, c1, v1)
        N1[:, u2] += _EPS + pad
        self.x0 = np.where(pad, 0.0, X.reshape(c, -1))
        b1 = _rhs(n2, self.s_cols, sv, s_rhs) + _EPS * self.x0
        sol = _pbsolve(N1, np.concatenate([b1[:, :, None], np.swapaxes(self.Us, 1, 2)], axis=2))
        self.y1, self.Z1 = sol[:, :, 0], sol[:, :, 1:]
        # ---- phase 2: equation 7 on per-frame velocities, rows weighted 1/sqrt(mean span)
        if n >= 3:
            ia, ib = 1.0 / span[:, :-1], 1.0 / span[:, 1:]
            wv = np.where(valid[:, 2:], (0.5 * (span[:, :-1] + span[:, 1:])) ** -0.5, 0.0)
            g = idx[1:-1]
            cols_ = [np.stack([2 * (g - 1) + q, 2 * g + q, 2 * (g + 1) + q], axis=-1) for q in (0, 1)]
            vals_ = [np.stack([ia, -ia - ib, ib], axis=-1) * wv[..., None]] * 2
            sec_c = np.stack(cols_, axis=1).reshape(1, -1, 3)
            sec_v = np.stack(vals_, axis=2).reshape(c, -1, 3)
            self.wv = wv
        else:
            sec_c, sec_v = np.zeros((c, 0, 3), np.int64), np.zeros((c, 0, 3))
            self.wv = np.zeros((c, 0))
        self.sec = (sec_c, sec_v)
        st = idx[:-1]
        rc = np.stack([np.stack([2 * (st + 1) + q, 2 * st + q], axis=-1) for q in (0, 1)], axis=1).reshape(1, -1, 2)
        wrs = np.repeat(np.where(rst, sq, 0.0), 2, axis=1)
        self.rig_w = wrs
        self.rig = (rc, wrs[:, :, None] * np.array([1.0, -1.0]))
        c2, v2 = _pad(self.sec, self.rig, self.s_loc[:2])
        N2 = _band(c, n2, u2, c2, v2)
        N2[:, u2] += _EPS + pad
        self.N2 = N2
        self.pad2 = pad
        self.L0 = np.linalg.norm(np.diff(X, axis=1), axis=-1)
        self.Z2 = _pbsolve(N2, np.swapaxes(self.Us, 1, 2)) if self.Us.shape[1] else np.zeros((c, n2, 0))
        # ---- time: t[i+1] - t[i] = m_i h, rows weighted 1/sqrt(m_i)
        wt = np.where(vstep, 1.0 / np.sqrt(np.maximum(span, 1.0)), 0.0)
        tc = np.stack([idx[1:], idx[:-1]], axis=-1)[None]
        tv = np.stack([wt, -wt], axis=-1)
        self.tim = (tc, tv, span * self.dt * wt)
        c3, v3 = _pad((tc, tv), self.t_loc[:2])
        u1 = _BAND[1]
        Nt = _band(c, n, u1, c3, v3)
        Nt[:, u1] += _EPS + ~valid
        self.t0 = np.where(valid, self.start + fr * self.dt, 0.0)
        bt = _rhs(n, tc, tv, self.tim[2]) + _rhs(n, self.t_cols, tvl, t_rhs) + _EPS * self.t0
        sol = _pbsolve(Nt, np.concatenate([bt[:, :, None], np.swapaxes(self.Ut, 1, 2)], axis=2))
        self.yt, self.Zt = sol[:, :, 0], sol[:, :, 1:]
        self.last = nv - 1

    @staticmethod
    def _coupled(rows: _Rows, ids: IntArray, k: int, kidx: Any, dim: int, nunk: int, c_: int) -> Array:
        U = np.zeros((c_, len(ids), nunk))
        if not len(ids):
            return U
        mask = (rows.char[ids] == k) & (rows.val[ids] != 0)
        pos, ent = np.nonzero(mask)
        if not len(pos):
            return U
        kk = kidx(rows.frame[ids][pos, ent])  # (c, E)
        col = dim * kk + rows.coord[ids][pos, ent][None] if dim == 2 else kk
        ci = np.repeat(np.arange(c_), len(pos))
        np.add.at(U, (ci, np.tile(pos, c_), col.ravel()), np.tile(rows.val[ids][pos, ent], c_))
        return U

    # ---------------------------------------------------------------- energies
    def phase2_rhs(self, pbar: Array) -> tuple[Array, Array]:
        """Right-hand sides of phase 2 for phase-1 results ``pbar`` (c', 2n); also the rescaled segments."""
        cc = pbar.shape[0]
        n = self.n
        P = pbar.reshape(cc, n, 2)
        seg = P[:, 1:] - P[:, :-1]
        ln = np.linalg.norm(seg, axis=-1)
        vb = seg * np.divide(self.L0, ln, out=np.ones_like(ln), where=ln > 1e-12)[..., None]
        ub = vb / self.span[..., None]
        out = _rhs(2 * n, *self._b(self.s_loc[0], cc), *self._bv(self.s_loc[1], self.s_loc[2], cc)) + _EPS * pbar
        if n >= 3:
            r = ((ub[:, 1:] - ub[:, :-1]) * self.wv[..., None]).reshape(cc, -1)
            out += _rhs(2 * n, *self._b(self.sec[0], cc), *self._bv(self.sec[1], r, cc))
        r = vb.reshape(cc, -1) * self.rig_w
        out += _rhs(2 * n, *self._b(self.rig[0], cc), *self._bv(self.rig[1], r, cc))
        return np.where(self.pad2, 0.0, out), ub

    @staticmethod
    def _b(cols: IntArray, cc: int) -> tuple[IntArray]:
        return (np.broadcast_to(cols, (cc,) + cols.shape[1:]),)

    @staticmethod
    def _bv(vals: Array, rhs: Array, cc: int) -> tuple[Array, Array]:
        return np.broadcast_to(vals, (cc,) + vals.shape[1:]), np.broadcast_to(rhs, (cc,) + rhs.shape[1:])

    def soft_local(self, x: Array, which: str) -> Array:
        cols, vals, rhs = self.s_loc if which == "s" else self.t_loc
        soft = self.s_soft if which == "s" else self.t_soft
        if not cols.shape[1]:
            return np.zeros(x.shape[0])
        r = _res(cols, vals, rhs, x)
        return np.sum(r[:, soft] ** 2, axis=1)

    def shape_energy(self, x: Array) -> Array:
        lr = np.sum(self.lap[1] * _gather(x, self.lap[0]), axis=-1)
        return np.sum(np.where(self.lap_energy, lr, 0.0) ** 2, axis=1) + self.soft_local(x, "s")

    def scale_energy(self, x: Array, ub: Array) -> Array:
        e = self.soft_local(x, "s")
        if self.n >= 3:
            r = ((ub[:, 1:] - ub[:, :-1]) * self.wv[..., None]).reshape(x.shape[0], -1)
            e = e + np.sum(_res(self.sec[0], self.sec[1], r, x) ** 2, axis=1)
        return e

    def time_energy(self, t: Array) -> Array:
        tc, tv, trhs = self.tim
        return np.sum(_res(tc, tv, trhs, t) ** 2, axis=1) + self.soft_local(t, "t")

    def changes(self, x2: Array, t: Array) -> tuple[Array, Array]:
        """``|L_s(P') - L_s(P)|`` (full-path arcs scaled by the chords' change) and ``|L_t(P') - L_t(P)|``."""
        cc = x2.shape[0]
        c1 = np.linalg.norm(np.diff(x2.reshape(cc, self.n, 2), axis=1), axis=-1)
        ratio = np.divide(self.arc, self.L0, out=np.ones_like(self.L0), where=self.L0 > 1e-6)
        dl = np.abs(np.sum(np.where(self.valid[:, 1:], ratio * (c1 - self.L0), 0.0), axis=1))
        last = np.take_along_axis(t, np.broadcast_to(self.last[:, None], (cc, 1)), axis=1)[:, 0]
        dt = np.abs(last - t[:, 0] - (self.n_frames - 1) * self.dt)
        return dl, dt


class _Scene:
    """The current scene prepared for subsampled evaluation of candidates.

    Each character's three least-squares systems are factorised once per
    update; constraint rows linking characters (or too long for a banded
    block) are added by the Woodbury identity, so a candidate costs one
    block factorisation per system for the transformed character plus small
    dense solves.
    """

    def __init__(
        self,
        tracks: Sequence[Track],
        paths: Sequence[MotionPath],
        constraints: Sequence[Any],
        segments: Sequence[Sequence[tuple[int, int]]],
        starts: Sequence[float],
        opts: DiscreteOptions,
        step: int,
    ) -> None:
        self.tracks = list(tracks)
        self.opts = opts
        K = len(tracks)
        self.K = K
        layout = Layout(tuple(t.n_frames for t in tracks))
        dts = [t.motion.dt for t in tracks]
        self.dts = dts
        self.starts = [float(s) for s in starts]
        wmax = max([1.0] + [float(c.weight) for c in constraints if hasattr(c, "weight") and not c.hard])
        self.pen = _PENALTY * wmax
        tang = _Tangents(paths)
        self.space = _compile(
            constraints, SPATIAL, lambda c: spatial_rows(c, paths, layout, cast(Any, tang), step), layout, 2, self.pen
        )
        self.time = _compile(constraints, TEMPORAL, lambda c: temporal_rows(c, layout, dts, step), layout, 1, self.pen)
        self.segments = [list(s) for s in segments]
        self.positions = [np.asarray(p.positions, dtype=float) for p in paths]
        self.headings = [np.unwrap(quat.yaw(t.motion.rotations[:, 0])) for t in tracks]
        self.cumarc = [
            np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(P, axis=0), axis=1))]) for P in self.positions
        ]
        # components of characters linked by constraint rows
        parent = list(range(K))

        def find(a: int) -> int:
            while parent[a] != a:
                parent[a] = parent[parent[a]]
                a = parent[a]
            return a

        for rows in (self.space, self.time):
            for r in np.flatnonzero(~rows.intra):
                ks = np.unique(rows.char[r][rows.val[r] != 0])
                for o in ks[1:]:
                    ra, rb = find(int(ks[0])), find(int(o))
                    if ra != rb:
                        parent[rb] = ra
        self.comp = [find(k) for k in range(K)]
        # rows linking characters (Woodbury terms), per character
        self.cross_s = [self._cross(self.space, k) for k in range(K)]
        self.cross_t = [self._cross(self.time, k) for k in range(K)]
        # kept frames and systems of the unmodified characters
        ratio = int(opts.subsample)
        self.base_frames: list[IntArray] = []
        self.base: list[_Batch] = []
        for k, t in enumerate(tracks):
            F = t.n_frames
            keep = [np.arange(0, F, ratio), [0, F - 1]]
            for rows in (self.space, self.time):
                keep.append(rows.frame[(rows.char == k) & (rows.val != 0)])
            for a, b in self.segments[k]:
                keep.append([a, b - 1])
            fr = np.unique(np.clip(np.concatenate([np.asarray(x, dtype=np.int64) for x in keep]), 0, F - 1))
            self.base_frames.append(fr)
            pt, st = _rigid(fr, self.segments[k])
            part = _Part(fr, self.positions[k][fr], np.diff(self.cumarc[k][fr]), pt, st, F, dts[k], self.starts[k])
            self.base.append(self._batch([part], k, [None]))
        self.base_energy: dict[int, float] = {}
        for root in set(self.comp):
            members = [k for k in range(K) if self.comp[k] == root]
            self.base_energy[root] = float(self._evaluate(members, members[0], self.base[members[0]])[0])

    @staticmethod
    def _cross(rows: _Rows, k: int) -> IntArray:
        return np.flatnonzero(~rows.intra & np.any((rows.char == k) & (rows.val != 0), axis=1))

    def _batch(self, parts: Sequence[_Part], k: int, fmaps: Sequence[IntArray | None]) -> _Batch:
        return _Batch(parts, k, fmaps, self.space, self.time, self.cross_s[k], self.cross_t[k], self.pen)

    @property
    def baseline(self) -> float:
        """Equation-10 energy of the untransformed scene (subsampled)."""
        return float(sum(self.base_energy.values()))

    # ------------------------------------------------------------ candidate
    def candidate_part(self, t: Transformation) -> tuple[_Part, IntArray]:
        """The subsampled transformed path of ``t``'s character and the old -> new frame map."""
        k = t.character
        tr = self.tracks[k]
        gd = _GraphData.of(tr.graph)
        a, b = t.removed
        s, e = t.inserted
        L = e - s
        F = tr.n_frames
        F2 = F - (b - a) + L
        P = self.positions[k]
        C = self.cumarc[k]
        H = self.headings[k]
        pa = P[a - 1]
        if L:
            ref = s - 1 if not gd.first[s] else s
            th = H[a - 1] - gd.yaw[ref]
            t1 = pa - _rot2(th, gd.pos[ref])
            ins_pos = _rot2(th, gd.pos[s:e]) + t1
            ins_arc = C[a - 1] + np.linalg.norm(ins_pos[0] - pa) + (gd.arc[s:e] - gd.arc[s])
            last_pos, last_head, last_arc = ins_pos[-1], gd.yaw[e - 1] + th, ins_arc[-1]
        else:
            ins_pos, ins_arc = np.zeros((0, 2)), np.zeros(0)
            last_pos, last_head, last_arc = pa, H[a - 1], C[a - 1]
        # suffix: moved rigidly so that the graph frame before nodes[b] sits on the last frame before it
        nb = int(tr.nodes[b])
        ref_b = nb - 1 if not gd.first[nb] else nb
        th_old = H[b] - gd.yaw[nb]
        pos_old_ref = _rot2(th_old, gd.pos[ref_b] - gd.pos[nb]) + P[b]
        dth = last_head - (gd.yaw[ref_b] + th_old)
        # old -> new frame map (removed frames go to the nearest seam side)
        fmap = np.arange(F, dtype=np.int64)
        fmap[b:] += L - (b - a)
        mid = np.arange(a, b)
        fmap[a:b] = np.where(mid - a < b - mid, a, a + L - 1)
        # kept frames
        r = int(self.opts.subsample)
        base = self.base_frames[k]
        base = base[(base < a) | (base >= b)]
        extra = [
            fmap[base],
            np.array([a - 2, a - 1, a, a + 1, a + L - 2, a + L - 1, a + L, a + L + 1]),
            a + np.arange(0, L, r),
        ]
        frames = np.unique(np.clip(np.concatenate(extra), 0, F2 - 1))
        X = np.empty((len(frames), 2))
        arc = np.empty(len(frames))
        pre = frames < a
        ins = (frames >= a) & (frames < a + L)
        post = frames >= a + L
        X[pre] = P[frames[pre]]
        arc[pre] = C[frames[pre]]
        X[ins] = ins_pos[frames[ins] - a]
        arc[ins] = ins_arc[frames[ins] - a]
        old = frames[post] - a - L + b
        X[post] = _rot2(dth, P[old] - pos_old_ref) + last_pos
        first_suf = _rot2(dth, P[b] - pos_old_ref) + last_pos
        arc[post] = last_arc + np.linalg.norm(first_suf - last_pos) + (C[old] - C[b])
        segs = []
        for sa, sb in self.segments[k]:
            for lo, hi in ((sa, min(sb, a)), (max(sa, b), sb)):
                if hi - lo >= 3:
                    segs.append((int(fmap[lo]), int(fmap[hi - 1]) + 1))
        pt, st = _rigid(frames, segs)
        part = _Part(frames, X, np.diff(arc), pt, st, F2, self.dts[k], self.starts[k])
        return part, fmap

    def energy(self, t: Transformation) -> float:
        """Equation-10 energy of the scene with ``t`` applied (subsampled)."""
        return float(self.energies([t])[0])

    def energies(self, ts: Sequence[Transformation]) -> Array:
        """Equation-10 energies of the scene with each of ``ts`` applied (evaluated in batches per character)."""
        out = np.zeros(len(ts))
        by: dict[int, list[int]] = {}
        for i, t in enumerate(ts):
            by.setdefault(t.character, []).append(i)
        for k, idx in by.items():
            built = [self.candidate_part(ts[i]) for i in idx]
            batch = self._batch([b[0] for b in built], k, [b[1] for b in built])
            root = self.comp[k]
            members = [j for j in range(self.K) if self.comp[j] == root]
            e = self._evaluate(members, k, batch)
            out[idx] = self.baseline - self.base_energy[root] + e
        return out

    # ------------------------------------------------------------- solver
    def _evaluate(self, members: list[int], k: int, B: _Batch, *, parts: bool = False) -> Any:
        """Equation 10 for one component, character ``k`` taking the paths of batch ``B`` (c of them).

        Each system is ``(B + U^T U) x = b + U^T c`` with ``B`` block diagonal
        (one block per character) and ``U`` the rows linking characters:
        ``x = y + Z S^-1 (c - U y)`` with ``y = B^-1 b``, ``Z = B^-1 U^T`` and
        ``S = I + U Z`` (Woodbury).  Returns the energies, shape (c,) (with
        ``parts=True``: a dict of the terms).
        """
        c = B.c
        bat = {j: (B if j == k else self.base[j]) for j in members}

        def solve(
            ys: dict[int, Array], Us: dict[int, Array], Zs: dict[int, Array], ids_j: dict[int, IntArray], rows: _Rows
        ) -> tuple[dict[int, Array], IntArray, Array]:
            pieces = [ids_j[j] for j in members if len(ids_j[j])]
            if not pieces:
                return (
                    {j: np.broadcast_to(ys[j], (c,) + ys[j].shape[1:]) for j in members},
                    np.zeros(0, np.int64),
                    np.zeros((c, 0)),
                )
            ids = np.unique(np.concatenate(pieces))
            r = len(ids)
            S = np.tile(np.eye(r), (c, 1, 1))
            Uy = np.zeros((c, r))
            loc = {}
            for j in members:
                if not len(ids_j[j]):
                    continue
                li = np.searchsorted(ids, ids_j[j])
                loc[j] = li
                Uy[:, li] += (Us[j] @ ys[j][..., None])[..., 0]
                S[:, li[:, None], li[None, :]] += Us[j] @ Zs[j]
            rhs = rows.rhs[ids]
            w = np.linalg.solve(S, (rhs - Uy)[..., None])[..., 0]
            xs = {}
            res = np.tile(-rhs, (c, 1))
            for j in members:
                if j not in loc:
                    xs[j] = np.broadcast_to(ys[j], (c,) + ys[j].shape[1:])
                    continue
                li = loc[j]
                xs[j] = ys[j] + (Zs[j] @ w[:, li][..., None])[..., 0]
                res[:, li] += (Us[j] @ xs[j][..., None])[..., 0]
            return xs, ids, res

        sp_, tm_ = self.space, self.time
        ids_s = {j: bat[j].cross_s for j in members}
        ids_t = {j: bat[j].cross_t for j in members}
        Us = {j: bat[j].Us for j in members}
        Ut = {j: bat[j].Ut for j in members}
        # phase 1 (shape)
        x1, i1, r1 = solve({j: bat[j].y1 for j in members}, Us, {j: bat[j].Z1 for j in members}, ids_s, sp_)
        e_shape = np.sum(r1[:, sp_.soft[i1]] ** 2, axis=1)
        for j in members:
            e_shape = e_shape + bat[j].shape_energy(x1[j])
        # phase 2 (scale)
        y2, ubs = {}, {}
        for j in members:
            rhs, ubs[j] = bat[j].phase2_rhs(x1[j])
            if bat[j].c == c:
                y2[j] = _pbsolve(bat[j].N2, rhs[..., None])[..., 0]
            else:
                y2[j] = _pbsv(bat[j].N2[0], rhs.T).T
        x2, i2, r2 = solve(y2, Us, {j: bat[j].Z2 for j in members}, ids_s, sp_)
        e_scale = np.sum(r2[:, sp_.soft[i2]] ** 2, axis=1)
        for j in members:
            e_scale = e_scale + bat[j].scale_energy(x2[j], ubs[j])
        # time
        xt, it, rt = solve({j: bat[j].yt for j in members}, Ut, {j: bat[j].Zt for j in members}, ids_t, tm_)
        e_time = np.sum(rt[:, tm_.soft[it]] ** 2, axis=1)
        dL = np.zeros(c)
        dT = np.zeros(c)
        for j in members:
            e_time = e_time + bat[j].time_energy(xt[j])
            dl, dt = bat[j].changes(x2[j], xt[j])
            dL = dL + dl
            dT = dT + dt
        total = e_shape + e_scale + e_time + self.opts.cs * dL + self.opts.ct * dT
        if parts:
            return {"shape": e_shape, "scale": e_scale, "time": e_time, "length": dL, "duration": dT, "total": total}
        return total


# ======================================================================
# the session plugged into SceneEditor
# ======================================================================
def _map_frames(value: Any, track: Track, *, stop: bool = False) -> Any:
    if value is None:
        return None
    return track.frame_of(int(value) - 1) + 1 if stop else track.frame_of(int(value))


def _map_effector(e: Any, track: Track) -> Any:
    f = e.frames
    if isinstance(f, (int, np.integer)):
        new: Any = track.frame_of(int(f))
    elif isinstance(f, tuple) and len(f) == 2:
        new = (track.frame_of(int(f[0])), track.frame_of(int(f[1]) - 1) + 1)
    elif isinstance(f, range):
        new = range(track.frame_of(f[0]), track.frame_of(f[-1]) + 1) if len(f) else f
    else:
        new = [track.frame_of(int(v)) for v in f]
    return dataclasses.replace(e, frames=new)


def _map_constraint(c: Any, tracks: Sequence[Track], changed: Sequence[bool]) -> Any:
    """``c`` with its input-clip frames replaced by current frames."""
    if isinstance(c, EndEffectorConstraint):
        if not changed[c.character] or not hasattr(c.constraint, "frames"):
            return c
        return dataclasses.replace(c, constraint=_map_effector(c.constraint, tracks[c.character]))
    if type(c).__name__ == "EndEffector" and hasattr(c, "frames"):
        k = int(c.character)
        return _map_effector(c, tracks[k]) if changed[k] else c
    if not isinstance(c, SPATIAL + TEMPORAL):
        return c
    ks = c.characters
    if not any(changed[k] for k in ks):
        return c
    k = c.character
    tr = tracks[k]
    upd: dict[str, Any] = {}
    if c.frame is not None:
        upd["frame"] = tr.frame_of(c.frame)
    frames: Any = getattr(c, "frames", None)
    if frames is not None:
        upd["frames"] = (tr.frame_of(frames[0]), tr.frame_of(frames[1]))
    if hasattr(c, "end_frame"):
        upd["end_frame"] = tr.frame_of(c.end_frame)
    if isinstance(c, (Relative, Sync)):
        to = tracks[c.other]
        if c.other_frame is not None:
            upd["other_frame"] = to.frame_of(c.other_frame)
        if c.other_frames is not None:
            upd["other_frames"] = (to.frame_of(c.other_frames[0]), to.frame_of(c.other_frames[1]))
        elif c.frames is not None and c.other != c.character:
            # frames of `other` default to the same numbers: make them explicit
            upd["other_frames"] = (to.frame_of(c.frames[0]), to.frame_of(c.frames[1]))
    return dataclasses.replace(c, **upd)


class DiscreteSession:
    """Discrete editing state of one :class:`~mocaplab.editing.scene.SceneEditor` (section 5).

    Created on the editor's first solve when ``discrete`` is on; get it with
    :func:`session`.  The editor's constraints keep referring to the frames
    of the *input* clips; the session maps them to the current frames of
    the transformed characters (a frame follows its pose: see
    :attr:`Track.origin`; constraints on removed frames, which the pruning
    rules never allow for existing constraints, go to the nearest surviving
    frame) and edits the transformed scene.  The returned
    :class:`~mocaplab.editing.scene.EditResult` is that of the transformed
    scene: ``result.characters`` are the transformed clips,
    ``result.constraints`` the mapped constraints (same order and indices),
    ``result.transformations`` every transformation applied so far.

    Attributes
    ----------
    tracks : list of Track
        Current structure of each character.
    applied : list of Transformation
    history : list of dict
        One entry per applied transformation: ``transformation``,
        ``candidates`` (the pruned candidate list), ``energies`` (their
        energies, same order), ``baseline``, ``constraints`` (mapped to the
        frames before the transformation), ``times``/``positions`` (edited,
        for locality checks).
    timings : list of dict
        Per greedy step: ``enumerate`` and ``evaluate`` seconds and the
        number of candidates.
    """

    def __init__(self, editor: Any, options: DiscreteOptions) -> None:
        self.options = options
        self.characters = tuple(editor.characters)
        opts = dict(editor.options)
        opts["discrete"] = False
        self.editor_options = opts
        graphs: dict[int, MotionGraph] = {}
        built: dict[int, MotionGraph] = {}
        given = dict(options.graphs or {})
        for k, m in enumerate(self.characters):
            if k in given:
                g = given[k]
                if not isinstance(g, MotionGraph):
                    raise TypeError(f"Expected graphs[{k}] to be a MotionGraph, got {type(g).__name__}")
            else:
                got = built.get(id(m))
                if got is not None:
                    g = got
                else:
                    g = build_graph(
                        [m],
                        weights=options.weights,
                        threshold=options.threshold,
                        window=options.window,
                        min_gap=options.min_gap,
                    )
                    built[id(m)] = g
            graphs[k] = g
        self.graphs = graphs
        self.tracks = [Track.from_motion(m, graphs[k]) for k, m in enumerate(self.characters)]
        self._nodes0 = [t.nodes for t in self.tracks]
        self.applied: list[Transformation] = []
        self.history: list[dict[str, Any]] = []
        self.timings: list[dict[str, float]] = []
        self.updates = 0
        self._inner: Any = None
        self._inner_tracks: tuple[int, ...] | None = None

    # ----------------------------------------------------------- mapping
    def _changed(self, tracks: Sequence[Track]) -> list[bool]:
        return [t.nodes is not self._nodes0[k] for k, t in enumerate(tracks)]

    def map_constraints(self, constraints: Sequence[Any], tracks: Sequence[Track] | None = None) -> tuple[Any, ...]:
        """``constraints`` (input-clip frames) with current frames."""
        tracks = self.tracks if tracks is None else tracks
        ch = self._changed(tracks)
        if not any(ch):
            return tuple(constraints)
        return tuple(_map_constraint(c, tracks, ch) for c in constraints)

    def _inner_options(self, tracks: Sequence[Track]) -> dict[str, Any]:
        opts = dict(self.editor_options)
        st = opts.get("stationary")
        if st is not None and not isinstance(st, (str, bool)):
            ch = self._changed(tracks)
            new = []
            for k, segs in enumerate(st):
                if not ch[k]:
                    new.append(list(segs))
                    continue
                out = []
                for a, b in segs:
                    a2, b2 = tracks[k].frame_of(a), tracks[k].frame_of(b - 1) + 1
                    if b2 - a2 >= 3:
                        out.append((a2, b2))
                new.append(out)
            opts["stationary"] = new
        return opts

    def _solve(self, tracks: Sequence[Track], mapped: tuple[Any, ...], *, reuse: bool = True) -> Any:
        from .scene import SceneEditor

        key = tuple(id(t) for t in tracks)
        inner = self._inner if reuse and self._inner_tracks == key else None
        if inner is None:
            inner = SceneEditor([t.motion for t in tracks], mapped, **self._inner_options(tracks))
        else:
            old = inner.constraints
            diff = [i for i, (x, y) in enumerate(zip(old, mapped, strict=False)) if x != y]
            if len(old) == len(mapped) and len(diff) == 1 and type(old[diff[0]]) is type(mapped[diff[0]]):
                inner.replace(diff[0], mapped[diff[0]])
            elif len(old) != len(mapped) or diff:
                inner.set_constraints(mapped)
        return inner, key

    # ------------------------------------------------------------ greedy
    def _best(self, tracks: list[Track], inner: Any, result: Any, mapped: tuple[Any, ...]) -> Any:
        o = self.options
        t0 = time.perf_counter()
        c0 = time.process_time()
        cands: list[Transformation] = []
        for k, tr in enumerate(tracks):
            loc = o.locality_of(k)
            if loc.characters is not None and k not in loc.characters:
                continue
            raw = enumerate_transformations(tr, character=k, min_duration=o.min_duration, max_duration=o.max_duration)
            cands += prune(
                raw,
                constraints=mapped,
                locality=loc,
                times={k: result.times[k]},
                positions={k: result.paths[k]},
                min_duration=o.min_duration,
                max_duration=o.max_duration,
            )
        t1 = time.perf_counter()
        if not cands:
            self.timings.append(
                {"enumerate": t1 - t0, "evaluate": 0.0, "cpu": time.process_time() - c0, "candidates": 0}
            )
            return None
        scene = self._scene(tracks, inner, mapped, subsample=int(o.subsample))
        energies = list(scene.energies(cands))
        t2 = time.perf_counter()
        self.timings.append(
            {"enumerate": t1 - t0, "evaluate": t2 - t1, "cpu": time.process_time() - c0, "candidates": len(cands)}
        )
        base = scene.baseline
        order = [int(i) for i in np.argsort(energies, kind="stable") if energies[i] < base - o.min_gain]
        if not order:
            return None
        best = [
            dataclasses.replace(cands[i], energy=float(energies[i]), baseline=float(base), update=self.updates)
            for i in order
        ]
        info = {
            "candidates": cands,
            "energies": energies,
            "baseline": base,
            "constraints": mapped,
            "times": result.times,
            "positions": result.paths,
        }
        return best, info

    def _refine_ranking(
        self, ranked: list[Transformation], tracks: list[Track], inner: Any, mapped: tuple[Any, ...]
    ) -> list[Transformation]:
        """Re-score the best ``verify`` candidates on paths subsampled ``verify_subsample``; keep those that still gain."""
        o = self.options
        top = ranked[: int(o.verify)]
        if int(o.verify_subsample) == int(o.subsample):
            return top
        scene = self._scene(tracks, inner, mapped, subsample=int(o.verify_subsample))
        fine = scene.energies(top)
        base = scene.baseline
        keep = [(float(e), i) for i, e in enumerate(fine) if e < base - o.min_gain]
        return [top[i] for _, i in sorted(keep)]

    def _scene(self, tracks: list[Track], inner: Any, mapped: tuple[Any, ...], *, subsample: int) -> _Scene:
        starts = self.editor_options.get("start_times") or [0.0] * len(tracks)
        return _Scene(
            tracks,
            inner.paths,
            mapped,
            inner.segments,
            starts,
            dataclasses.replace(self.options, subsample=subsample),
            int(self.editor_options.get("variational_step", 10)),
        )

    def update(self, constraints: Sequence[Any]) -> Any:
        """Algorithm 1 for one constraint update; returns the EditResult of the transformed scene."""
        constraints = tuple(constraints)
        steps = int(self.options.max_initial) if self.updates == 0 else 1
        tracks = list(self.tracks)
        applied = list(self.applied)
        history: list[dict[str, Any]] = []
        mapped = self.map_constraints(constraints, tracks)
        inner, key = self._solve(tracks, mapped)
        result = inner.result
        o = self.options
        for _ in range(steps):
            found = self._best(tracks, inner, result, mapped)
            if found is None:
                break
            ranked, info = found
            accepted = None
            t0 = time.perf_counter()
            if o.verify:
                ranked = self._refine_ranking(ranked, tracks, inner, mapped)
            current = deformation_energy(result, cs=o.cs, ct=o.ct) if o.verify else math.nan
            for best in ranked[:1] if o.verify else ranked:
                k = best.character
                trial = list(tracks)
                trial[k] = apply_transformation(tracks[k], best, blend=o.blend)
                trial_mapped = self.map_constraints(constraints, trial)
                try:
                    t_inner, t_key = self._solve(trial, trial_mapped, reuse=False)
                except ConstraintError:
                    continue  # the transformed scene cannot be edited under these constraints
                t_result = t_inner.result
                if o.verify:
                    full = deformation_energy(t_result, cs=o.cs, ct=o.ct)
                    if not full < current - o.min_gain:
                        continue
                    best = dataclasses.replace(best, full_energy=float(full), full_baseline=float(current))
                accepted = (best, trial, trial_mapped, t_inner, t_key, t_result)
                break
            self.timings[-1]["verify"] = time.perf_counter() - t0
            if accepted is None:
                break
            best, tracks, mapped, inner, key, result = accepted
            applied.append(best)
            info["transformation"] = best
            info["times"] = info["times"][best.character]
            info["positions"] = info["positions"][best.character]
            history.append(info)
        self.tracks = tracks
        self.applied = applied
        self.history += history
        self._inner, self._inner_tracks = inner, key
        self.updates += 1
        result.transformations = tuple(applied)
        return result


_SESSIONS: weakref.WeakKeyDictionary[Any, DiscreteSession] = weakref.WeakKeyDictionary()


def session(editor: Any) -> DiscreteSession:
    """The :class:`DiscreteSession` of a SceneEditor created with ``discrete`` on."""
    try:
        return _SESSIONS[editor]
    except KeyError:
        raise ValueError("This editor has no discrete-editing session: create it with discrete=True") from None


def discrete_update(editor: Any, result: Any) -> Any:
    """Run Algorithm 1 for ``editor``'s new constraints (called by the SceneEditor).

    ``editor.options["discrete"]`` is ``True`` or a :class:`DiscreteOptions`.
    Returns the :class:`~mocaplab.editing.scene.EditResult` of the
    transformed scene (see :class:`DiscreteSession`).
    """
    opt = editor.options.get("discrete")
    if opt is True:
        opt = DiscreteOptions()
    if not isinstance(opt, DiscreteOptions):
        raise TypeError(f"Expected `discrete` as a bool or a DiscreteOptions, got {type(opt).__name__}")
    sess = _SESSIONS.get(editor)
    if sess is None:
        sess = DiscreteSession(editor, opt)
        _SESSIONS[editor] = sess
    return sess.update(result.constraints)
