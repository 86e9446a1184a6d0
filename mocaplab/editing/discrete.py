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
on the pose before the seam, so the root path continues smoothly.  Each
seam is then blended (displacement-map style): the jump ``d`` between the
frame after the seam and the natural successor of the frame before it
(joint rotations as rotation vectors, root height, root ground position) is
spread as ``+d w / 2`` before and ``-d w / 2`` after the seam, ``w`` a raised
cosine over ``blend`` seconds on each side (rotations by slerp-style
``exp(c d) q``), so there is no pop.  The motion path and the time track
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
transformed one by constraints are re-solved.  After a transformation is
chosen the full scene is solved once (the returned
:class:`~mocaplab.editing.scene.EditResult`).
"""

from __future__ import annotations

import dataclasses
import math
import weakref
from collections.abc import Iterable, Mapping, Sequence
from typing import Any, Literal

import numpy as np
import scipy.linalg as sla
import scipy.sparse as sp
import scipy.sparse.linalg as spla
from numpy.typing import NDArray

from .. import quat
from ..motion import Motion
from .constraints import SPATIAL, TEMPORAL, EndEffectorConstraint, Relative, Sync
from .graph import MotionGraph, SimilarityWeights, build_graph
from .laplacian import Layout, spatial_rows
from .paths import MotionPath, laplacian_coordinates
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
    """

    graphs: Mapping[int, MotionGraph] | None = None
    locality: Locality | Mapping[int, Locality] = Locality()
    min_duration: float = 0.3
    max_duration: float = 2.0
    cs: float = 1.0
    ct: float = 1.0
    subsample: int = 25
    blend: float = 0.2
    min_gain: float = 0.02
    max_initial: int = 8
    threshold: float = 0.1
    window: float = 0.25
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
        if int(self.subsample) < 1:
            raise ValueError(f"Expected `subsample` >= 1, got {self.subsample!r}")
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
        self.arc = np.concatenate([[0.0], np.cumsum(step)])  # along each clip (reset ignored: differences within a clip)
        src, dst, cost = g.transitions()
        n = g.n_frames
        self.T = sp.csr_matrix((cost + 1e-300, (src, dst)), shape=(n, n))
        self.Tt = self.T.T.tocsr()

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
        v = self.T[a, b]
        return float(v) if v != 0 else None


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
        dp = np.zeros((F, 2))
        for a in starts:
            prev = int(nodes[a - 1])
            exp_node = prev + 1 if not gd.last[prev] else prev
            act = int(nodes[a])
            d_local = quat.log(quat.mul(gd.rot[act], quat.inv(gd.rot[exp_node])))
            exp_root = quat.mul(quat.from_yaw(theta[a - 1]), gd.rot[exp_node, 0])
            d_local[0] = quat.log(quat.mul(rot[a, 0], quat.inv(exp_root)))
            d_h = gd.root[act, 1] - gd.root[exp_node, 1]
            exp_pos = _rot2(theta[a - 1], gd.pos[exp_node]) + trans[a - 1]
            d_p = root[a, [0, 2]] - exp_pos
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
            dp[before[okb]] += cb[:, None] * d_p
            dp[after[oka]] += ca[:, None] * d_p
        touched = np.flatnonzero(np.any(dr != 0, axis=(1, 2)) | (dy != 0))
        rot[touched] = quat.normalize(quat.mul(quat.exp(dr[touched]), rot[touched]))
        root[:, 1] += dy
        root[:, [0, 2]] += dp
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
    has_out = np.array([gd.T.indptr[n + 1] > gd.T.indptr[n] for n in nodes]) if F else np.zeros(0, bool)
    has_in = np.array([gd.Tt.indptr[n + 1] > gd.Tt.indptr[n] for n in nodes]) if F else np.zeros(0, bool)

    # ---- deletions: seam x -> y with src[y] a successor of src[x]
    repeated = np.array([n for n, g in where.items() if len(g) > 1], dtype=np.int64)
    for x in np.flatnonzero(has_out[: F - 1] | np.isin(nodes[: F - 1] + 1, repeated)):
        x = int(x)
        targets = list(gd.out(int(nodes[x])))
        if not gd.last[nodes[x]]:
            targets.append(int(nodes[x]) + 1)
        for d in targets:
            for y in where.get(int(d), ()):
                y = int(y)
                L = y - x - 1
                if lmin <= L <= lmax and y <= F - 1:
                    c = gd.seam_cost(int(nodes[x]), int(d))
                    if c is not None:
                        add("deletion", x + 1, y, 0, 0, c)

    # ---- insertions (duplication included): before frame a, graph run [s, u]
    cand_a = np.flatnonzero(
        np.concatenate([[False], has_out[: F - 1]]) | has_in | np.concatenate([[False], seam_after[: F - 1]])
    )
    for a in cand_a:
        a = int(a)
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
                if not lmin <= L <= lmax or gd.clip[s] != gd.clip[u] or gd.last[s : u].any():
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
    outs = []
    for x in np.flatnonzero(has_out[: F - 1]):
        for s in gd.out(int(nodes[x])):
            if int(s) != int(nodes[x + 1]):
                outs.append((int(x), int(s)))
    ins = []
    for y in np.flatnonzero(has_in):
        for u in gd.into(int(nodes[y])):
            if y >= 1 and int(u) != int(nodes[y - 1]):
                ins.append((int(y), int(u)))
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
    frames = getattr(c, "frames", None)
    if frames is None:
        for k, f in c.frame_refs():
            put(k, f)
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
    out = []
    eps = 1e-9
    for n in (t.removed[1] - t.removed[0], t.inserted[1] - t.inserted[0]):
        if n and not (min_duration - eps <= n / t.fps <= max_duration + eps):
            out.append("duration")
            break
    prot = protected_frames(constraints, t.character)
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
    for t in candidates:
        v = pruning_violations(
            t,
            constraints=constraints,
            min_duration=min_duration,
            max_duration=max_duration,
            locality=locality,
            times=None if times is None else times.get(t.character),
            positions=None if positions is None else positions.get(t.character),
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
_EPS = 1e-7  # regulariser of the free modes
_DENSE = 600  # dense solves up to this many unknowns


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
    """Constraint rows in (character, frame) form: entry arrays and per-row data."""

    row: IntArray
    char: IntArray
    frame: IntArray
    coord: IntArray
    val: Array
    rhs: Array
    w: Array  # sqrt of the weight (penalty for hard rows)
    hard: NDArray[np.bool_]
    chars: list[frozenset[int]]


def _compile(
    constraints: Sequence[Any], kinds: tuple[type, ...], make: Any, layout: Layout, dim: int, penalty: float
) -> _Rows:
    off = layout.offsets
    row, col, val, rhs, w, hard, chars = [], [], [], [], [], [], []
    r = 0
    for c in constraints:
        if not isinstance(c, kinds):
            continue
        rows = make(c)
        for cc, vv, bb in zip(rows.cols, rows.vals, rows.rhs, strict=True):
            row.append(np.full(len(cc), r))
            col.append(np.asarray(cc, dtype=np.int64))
            val.append(np.asarray(vv, dtype=float))
            rhs.append(float(bb))
            w.append(math.sqrt(penalty) if c.hard else math.sqrt(c.weight))
            hard.append(bool(c.hard))
            chars.append(frozenset(c.characters))
            r += 1
    cols = np.concatenate(col) if col else np.zeros(0, np.int64)
    g = cols // dim
    ch = np.searchsorted(off, g, side="right") - 1
    return _Rows(
        np.concatenate(row).astype(np.int64) if row else np.zeros(0, np.int64),
        ch.astype(np.int64),
        (g - off[ch]).astype(np.int64),
        (cols % dim).astype(np.int64),
        np.concatenate(val) if val else np.zeros(0),
        np.asarray(rhs, dtype=float),
        np.asarray(w, dtype=float),
        np.asarray(hard, dtype=bool),
        chars,
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
    lookup: IntArray  # full frame -> kept index (nearest kept for others), (n_frames,)


def _lookup(frames: IntArray, n: int) -> IntArray:
    idx = np.searchsorted(frames, np.arange(n))
    return np.clip(idx, 0, len(frames) - 1).astype(np.int64)


def _rigid(frames: IntArray, segments: Sequence[tuple[int, int]]) -> tuple[NDArray[np.bool_], NDArray[np.bool_]]:
    pt = np.zeros(len(frames), bool)
    st = np.zeros(max(len(frames) - 1, 0), bool)
    for a, b in segments:
        inside = (frames >= a) & (frames < b)
        pt |= (frames > a) & (frames < b - 1)
        st |= inside[:-1] & inside[1:]
    return pt, st


def _make_part(
    frames: IntArray,
    positions: Array,
    cumarc: Array,
    segments: Sequence[tuple[int, int]],
    n_frames: int,
    dt: float,
    start: float,
) -> _Part:
    pt, st = _rigid(frames, segments)
    return _Part(frames, positions, np.diff(cumarc), pt, st, n_frames, dt, start, _lookup(frames, n_frames))


def _lsq(blocks: list[tuple[IntArray, IntArray, Array]], rhs: Array, n: int, x0: Array) -> tuple[Array, Any]:
    """Least squares ``min |M x - rhs|^2 + eps |x - x0|^2``; returns x and M.

    Subsampled systems are small: dense normal equations (Cholesky) up to a
    few hundred unknowns, a sparse LU beyond.
    """
    r = np.concatenate([b[0] for b in blocks])
    c = np.concatenate([b[1] for b in blocks])
    v = np.concatenate([b[2] for b in blocks])
    m = len(rhs)
    if n <= _DENSE:
        M = np.bincount(r * n + c, weights=v, minlength=m * n).reshape(m, n)
        N = M.T @ M
        N.flat[:: n + 1] += _EPS
        try:
            x = sla.cho_solve(sla.cho_factor(N, check_finite=False), M.T @ rhs + _EPS * x0, check_finite=False)
        except np.linalg.LinAlgError:  # pragma: no cover - numerically indefinite
            x = np.linalg.lstsq(N, M.T @ rhs + _EPS * x0, rcond=None)[0]
        return x, M
    Ms = sp.csr_matrix((v, (r, c)), shape=(m, n))
    MT = Ms.T.tocsr()
    Ns = (MT @ Ms + _EPS * sp.identity(n, format="csr")).tocsc()
    x = spla.splu(Ns, permc_spec="MMD_AT_PLUS_A").solve(MT @ rhs + _EPS * x0)
    return x, Ms


class _Scene:
    """The current scene prepared for subsampled evaluation of candidates."""

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
        pen = _PENALTY * wmax
        self.pen = pen
        tang = _Tangents(paths)
        self.space = _compile(constraints, SPATIAL, lambda c: spatial_rows(c, paths, layout, tang, step), layout, 2, pen)
        self.time = _compile(constraints, TEMPORAL, lambda c: temporal_rows(c, layout, dts, step), layout, 1, pen)
        self.segments = [list(s) for s in segments]
        self.positions = [np.asarray(p.positions, dtype=float) for p in paths]
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
            for cs_ in rows.chars:
                cs_l = sorted(cs_)
                for o in cs_l[1:]:
                    ra, rb = find(cs_l[0]), find(o)
                    if ra != rb:
                        parent[rb] = ra
        self.comp = [find(k) for k in range(K)]
        # kept frames of the unmodified characters
        r = int(opts.subsample)
        self.base_frames: list[IntArray] = []
        for k, t in enumerate(tracks):
            F = t.n_frames
            keep = [np.arange(0, F, r), [0, F - 1]]
            for rows in (self.space, self.time):
                keep.append(rows.frame[rows.char == k])
            for a, b in self.segments[k]:
                keep.append([a, b - 1])
            fr = np.unique(np.clip(np.concatenate([np.asarray(x, dtype=np.int64) for x in keep]), 0, F - 1))
            self.base_frames.append(fr)
        self.base_parts = [
            _make_part(
                self.base_frames[k],
                self.positions[k][self.base_frames[k]],
                self.cumarc[k][self.base_frames[k]],
                self.segments[k],
                tracks[k].n_frames,
                dts[k],
                self.starts[k],
            )
            for k in range(K)
        ]
        self.base_energy: dict[int, float] = {}
        for root in set(self.comp):
            members = [k for k in range(K) if self.comp[k] == root]
            self.base_energy[root] = self._energy({k: self.base_parts[k] for k in members}, {})

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
        # ground pose of the frame before the seam, from the current motion
        head = quat.yaw(tr.motion.rotations[a - 1, 0])
        pa = P[a - 1]
        ins_pos = np.zeros((0, 2))
        ins_arc = np.zeros(0)
        if L:
            ref = s - 1 if not gd.first[s] else s
            th = head - gd.yaw[ref]
            t1 = pa - _rot2(th, gd.pos[ref])
            ins_pos = _rot2(th, gd.pos[s:e]) + t1
            g_arc = gd.arc[s:e] - gd.arc[s]
            ins_arc = C[a - 1] + np.linalg.norm(ins_pos[0] - pa) + g_arc
            last_pos, last_head, last_arc = ins_pos[-1], gd.yaw[e - 1] + th, ins_arc[-1]
        else:
            last_pos, last_head, last_arc = pa, head, C[a - 1]
        # suffix: rigidly moved so that its first frame follows the last new/prefix frame
        nb = int(tr.nodes[b])
        ref_b = nb - 1 if not gd.first[nb] else nb
        hb = quat.yaw(tr.motion.rotations[b, 0])
        # graph pose of ref_b placed like the current frame b is placed
        th_old = hb - gd.yaw[nb]
        pos_old_ref = _rot2(th_old, gd.pos[ref_b] - gd.pos[nb]) + P[b]
        yaw_old_ref = gd.yaw[ref_b] + th_old
        dth = last_head - yaw_old_ref
        suf = _rot2(dth, P[b:] - pos_old_ref) + last_pos
        suf_arc = last_arc + np.linalg.norm(suf[0] - last_pos) + (C[b:] - C[b])
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
            [a - 2, a - 1, a, a + 1, a + L - 2, a + L - 1, a + L, a + L + 1],
            a + np.arange(0, L, r),
        ]
        frames = np.unique(np.clip(np.concatenate([np.asarray(x, dtype=np.int64) for x in extra]), 0, F2 - 1))
        X = np.empty((len(frames), 2))
        arc = np.empty(len(frames))
        pre = frames < a
        ins = (frames >= a) & (frames < a + L)
        post = frames >= a + L
        X[pre] = P[frames[pre]]
        arc[pre] = C[frames[pre]]
        X[ins] = ins_pos[frames[ins] - a]
        arc[ins] = ins_arc[frames[ins] - a]
        X[post] = suf[frames[post] - a - L]
        arc[post] = suf_arc[frames[post] - a - L]
        segs = []
        for sa, sb in self.segments[k]:
            for lo, hi in ((sa, min(sb, a)), (max(sa, b), sb)):
                if hi - lo >= 3:
                    segs.append((int(fmap[lo]), int(fmap[hi - 1]) + 1))
        part = _make_part(frames, X, arc, segs, F2, self.dts[k], self.starts[k])
        return part, fmap

    def energy(self, t: Transformation) -> float:
        """Equation-10 energy of the scene with ``t`` applied (subsampled)."""
        k = t.character
        part, fmap = self.candidate_part(t)
        root = self.comp[k]
        parts = {j: (part if j == k else self.base_parts[j]) for j in range(self.K) if self.comp[j] == root}
        e = self._energy(parts, {k: fmap})
        return self.baseline - self.base_energy[root] + e

    # ------------------------------------------------------------- solver
    def _energy(self, parts: dict[int, _Part], fmaps: dict[int, IntArray]) -> float:
        chars = sorted(parts)
        offs = {}
        n = 0
        for k in chars:
            offs[k] = n
            n += len(parts[k].frames)

        def locate(rows: _Rows) -> tuple[NDArray[np.bool_], IntArray]:
            sel = np.isin(rows.char, chars)
            idx = np.zeros(len(rows.char), dtype=np.int64)
            for k in chars:
                m = rows.char == k
                if not m.any():
                    continue
                f = rows.frame[m]
                if k in fmaps:
                    f = fmaps[k][f]
                idx[m] = offs[k] + parts[k].lookup[f]
            return sel, idx

        # ---------------- space, phase 1
        blocks1: list[tuple[IntArray, IntArray, Array]] = []
        rhs1: list[Array] = []
        blocks2: list[tuple[IntArray, IntArray, Array]] = []
        rhs2_fixed: list[Array] = []
        nrow1 = 0
        lap_rows = []  # (row range) for energy of phase 1
        x0 = np.concatenate([parts[k].X for k in chars]).reshape(-1)
        for k in chars:
            p = parts[k]
            m = len(p.frames)
            if m < 3:
                continue
            o = offs[k]
            lc = laplacian_coordinates(p.X)[1:-1]
            g = o + np.arange(1, m - 1)
            x, y = lc[:, 0], lc[:, 1]
            wr = np.where(p.rigid_pt[1:-1], math.sqrt(self.pen), 1.0)
            rr = np.arange(m - 2)
            one = np.ones(m - 2)
            rx, rz = nrow1 + 2 * rr, nrow1 + 2 * rr + 1
            rows_ = [rx, rx, rx, rx, rx, rx, rz, rz, rz, rz, rz, rz]
            X_, Z_ = (lambda f: 2 * f), (lambda f: 2 * f + 1)
            cols_ = [
                X_(g), X_(g - 1), X_(g + 1), X_(g - 1), Z_(g + 1), Z_(g - 1),
                Z_(g), Z_(g - 1), Z_(g + 1), Z_(g - 1), X_(g + 1), X_(g - 1),
            ]  # fmt: skip
            vals_ = [one, -one, -x, x, -y, y, one, -one, -x, x, y, -y]
            blocks1.append(
                (
                    np.concatenate(rows_),
                    np.concatenate(cols_),
                    np.concatenate(vals_) * np.tile(wr, 12),
                )
            )
            lap_rows.append((nrow1, nrow1 + 2 * (m - 2), np.repeat(~p.rigid_pt[1:-1], 2)))
            rhs1.append(np.zeros(2 * (m - 2)))
            nrow1 += 2 * (m - 2)
        ssel, sidx = locate(self.space)
        srows_used = np.unique(self.space.row[ssel])
        if len(srows_used):
            rmap = np.full(len(self.space.rhs), -1, dtype=np.int64)
            rmap[srows_used] = np.arange(len(srows_used))
            wv = self.space.w[self.space.row[ssel]]
            cb = (
                nrow1 + rmap[self.space.row[ssel]],
                2 * sidx[ssel] + self.space.coord[ssel],
                self.space.val[ssel] * wv,
            )
            crhs = self.space.rhs[srows_used] * self.space.w[srows_used]
            csoft = ~self.space.hard[srows_used]
        else:
            cb = (np.zeros(0, np.int64), np.zeros(0, np.int64), np.zeros(0))
            crhs = np.zeros(0)
            csoft = np.zeros(0, bool)
        n2 = 2 * n
        if blocks1 or len(crhs):
            b1 = blocks1 + [cb]
            rhs = np.concatenate(rhs1 + [crhs])
            pbar, M1 = _lsq(b1, rhs, n2, x0)
            res = M1 @ pbar - rhs
        else:
            pbar, res = x0.copy(), np.zeros(0)
        e_shape = 0.0
        for r0, r1, ok in lap_rows:
            e_shape += float(np.sum(res[r0:r1][ok] ** 2))
        cres = res[nrow1:]
        e_shape += float(np.sum(cres[csoft] ** 2))
        # ---------------- space, phase 2 (scale compensation)
        PB = pbar.reshape(-1, 2)
        nrow2 = 0
        sec_rows = []
        for k in chars:
            p = parts[k]
            m = len(p.frames)
            if m < 2:
                continue
            o = offs[k]
            seg = PB[o + 1 : o + m] - PB[o : o + m - 1]
            ln = np.linalg.norm(seg, axis=1)
            L0 = np.linalg.norm(np.diff(p.X, axis=0), axis=1)
            vb = seg * np.divide(L0, ln, out=np.ones_like(ln), where=ln > 1e-12)[:, None]
            if m >= 3:
                g = o + np.arange(1, m - 1)
                rr = np.arange(m - 2)
                rows_l, cols_l, vals_l = [], [], []
                for c in (0, 1):
                    for df, v in ((-1, 1.0), (0, -2.0), (1, 1.0)):
                        rows_l.append(nrow2 + 2 * rr + c)
                        cols_l.append(2 * (g + df) + c)
                        vals_l.append(np.full(m - 2, v))
                blocks2.append((np.concatenate(rows_l), np.concatenate(cols_l), np.concatenate(vals_l)))
                rhs2_fixed.append((vb[1:] - vb[:-1]).reshape(-1))
                sec_rows.append((nrow2, nrow2 + 2 * (m - 2)))
                nrow2 += 2 * (m - 2)
            st = np.flatnonzero(p.rigid_step)
            if len(st):
                sq = math.sqrt(self.pen)
                rr = np.arange(len(st))
                rows_l, cols_l, vals_l = [], [], []
                for c in (0, 1):
                    rows_l += [nrow2 + 2 * rr + c, nrow2 + 2 * rr + c]
                    cols_l += [2 * (o + st + 1) + c, 2 * (o + st) + c]
                    vals_l += [np.full(len(st), sq), np.full(len(st), -sq)]
                blocks2.append((np.concatenate(rows_l), np.concatenate(cols_l), np.concatenate(vals_l)))
                rhs2_fixed.append((vb[st] * sq).reshape(-1))
                nrow2 += 2 * len(st)
        if blocks2 or len(crhs):
            cb2 = (cb[0] - nrow1 + nrow2, cb[1], cb[2])
            rhs = np.concatenate(rhs2_fixed + [crhs])
            phat, M2 = _lsq(blocks2 + [cb2], rhs, n2, pbar)
            res2 = M2 @ phat - rhs
        else:
            phat, res2 = pbar.copy(), np.zeros(0)
        e_scale = sum(float(np.sum(res2[r0:r1] ** 2)) for r0, r1 in sec_rows)
        e_scale += float(np.sum(res2[nrow2:][csoft] ** 2))
        # ---------------- time
        tsel, tidx = locate(self.time)
        blocks3 = []
        rhs3 = []
        t0 = np.concatenate([parts[k].start + parts[k].frames * parts[k].dt for k in chars])
        nrow3 = 0
        for k in chars:
            p = parts[k]
            m = len(p.frames)
            if m < 2:
                continue
            o = offs[k]
            span = np.diff(p.frames).astype(float)
            w = 1.0 / np.sqrt(np.maximum(span, 1.0))
            rr = nrow3 + np.arange(m - 1)
            blocks3.append(
                (
                    np.concatenate([rr, rr]),
                    np.concatenate([o + np.arange(1, m), o + np.arange(m - 1)]),
                    np.concatenate([w, -w]),
                )
            )
            rhs3.append(span * p.dt * w)
            nrow3 += m - 1
        trows_used = np.unique(self.time.row[tsel])
        if len(trows_used):
            rmap = np.full(len(self.time.rhs), -1, dtype=np.int64)
            rmap[trows_used] = np.arange(len(trows_used))
            wv = self.time.w[self.time.row[tsel]]
            blocks3.append((nrow3 + rmap[self.time.row[tsel]], tidx[tsel], self.time.val[tsel] * wv))
            rhs3.append(self.time.rhs[trows_used] * self.time.w[trows_used])
            tsoft = ~self.time.hard[trows_used]
        else:
            tsoft = np.zeros(0, bool)
        if blocks3:
            rhs = np.concatenate(rhs3)
            tt, M3 = _lsq(blocks3, rhs, n, t0)
            res3 = M3 @ tt - rhs
        else:
            tt, res3 = t0.copy(), np.zeros(0)
        e_time = float(np.sum(res3[:nrow3] ** 2)) + float(np.sum(res3[nrow3:][tsoft] ** 2))
        # ---------------- lengths and durations
        PH = phat.reshape(-1, 2)
        dL = dT = 0.0
        for k in chars:
            p = parts[k]
            o = offs[k]
            m = len(p.frames)
            if m >= 2:
                c0 = np.linalg.norm(np.diff(p.X, axis=0), axis=1)
                c1 = np.linalg.norm(np.diff(PH[o : o + m], axis=0), axis=1)
                ratio = np.divide(p.arc, c0, out=np.ones_like(c0), where=c0 > 1e-6)
                dL += abs(float(np.sum(ratio * (c1 - c0))))
                dT += abs(float(tt[o + m - 1] - tt[o]) - (p.n_frames - 1) * p.dt)
        return e_shape + e_scale + e_time + self.opts.cs * dL + self.opts.ct * dT


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
    if getattr(c, "frames", None) is not None:
        upd["frames"] = (tr.frame_of(c.frames[0]), tr.frame_of(c.frames[1]))
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
                g = built.get(id(m))
                if g is None:
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

    def _solve(self, tracks: Sequence[Track], mapped: tuple[Any, ...]) -> Any:
        from .scene import SceneEditor

        key = tuple(id(t) for t in tracks)
        inner = self._inner if self._inner_tracks == key else None
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
        import time as _time

        o = self.options
        t0 = _time.perf_counter()
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
        t1 = _time.perf_counter()
        if not cands:
            self.timings.append({"enumerate": t1 - t0, "evaluate": 0.0, "candidates": 0})
            return None
        starts = self.editor_options.get("start_times") or [0.0] * len(tracks)
        scene = _Scene(
            tracks,
            inner.paths,
            mapped,
            inner.segments,
            starts,
            o,
            int(self.editor_options.get("variational_step", 10)),
        )
        energies = [scene.energy(t) for t in cands]
        t2 = _time.perf_counter()
        self.timings.append({"enumerate": t1 - t0, "evaluate": t2 - t1, "candidates": len(cands)})
        i = int(np.argmin(energies))
        base = scene.baseline
        if not energies[i] < base - o.min_gain:
            return None
        best = dataclasses.replace(cands[i], energy=float(energies[i]), baseline=float(base), update=self.updates)
        info = {
            "transformation": best,
            "candidates": cands,
            "energies": energies,
            "baseline": base,
            "constraints": mapped,
            "times": result.times[best.character],
            "positions": result.paths[best.character],
        }
        return best, info

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
        for _ in range(steps):
            found = self._best(tracks, inner, result, mapped)
            if found is None:
                break
            best, info = found
            k = best.character
            tracks[k] = apply_transformation(tracks[k], best, blend=self.options.blend)
            applied.append(best)
            history.append(info)
            mapped = self.map_constraints(constraints, tracks)
            inner, key = self._solve(tracks, mapped)
            result = inner.result
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
