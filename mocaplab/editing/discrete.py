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
on the pose before the seam, so the path and heading continue without a
jump.  "Root" here is the path joint (:attr:`mocaplab.motion.Motion.path_joint`,
the pelvis role): the placement follows its ground position and heading and
moves the whole body rigidly (:func:`~mocaplab.editing.paths.apply_path`),
whatever the skeleton's layout; per-joint translations (``Motion.translations``)
are carried along.  Each seam is then blended (displacement-map style): the
jump ``d`` between the frame after the seam and the natural successor of the
frame before it (every body joint's local rotation and the path joint's
placed world rotation as rotation vectors ``d = log(q^-1 q')``, the path
joint's height and the body joints' translations) is spread as ``+d w / 2``
before and ``-d w / 2`` after the seam, ``w`` a raised cosine over ``blend``
seconds on each side, rotations as ``q exp(c d)`` (the one displacement
convention of :mod:`mocaplab.displacement`), so there is no pop.  (A frame
that ends its clip has no successor to compare with; its seam is not
blended.)  The motion path and the time track (uniform, one frame step per
frame) follow from the new motion; constraints follow their frames (see
:class:`DiscreteSession`).

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
the arc length of the frames it spans.  All candidates of all characters
are evaluated in one batch: every transformed path and every untransformed
one is a padded "part" whose three banded systems (shape, scale, time) are
solved together (one LAPACK call per system for the whole batch: the
parts are the blocks of one block-diagonal banded matrix), and each
candidate's scene couples its parts through the constraint rows linking
characters by the Woodbury identity.  So an update costs a fixed number of
array operations, whatever the number of candidates (per-call overhead,
not arithmetic, dominates at these sizes).  A candidate's energy does not
depend on which others are evaluated with it.  After a transformation is
chosen the full scene is solved once (the returned
:class:`~mocaplab.editing.scene.EditResult`).
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
from ..displacement import displace, rotation_displacement
from ..motion import Motion
from .constraints import SPATIAL, TEMPORAL, ConstraintError, EndEffectorConstraint, Relative, Sync
from .energy import deformation_energy
from .graph import MotionGraph, SimilarityWeights, _above, build_graph
from .laplacian import Layout, spatial_rows
from .paths import MotionPath, apply_path
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
        if any(t is not None for t in trs):  # every clip's, offsets where a clip has none
            self.translations: Array | None = np.concatenate(
                [
                    np.asarray(m.translations)
                    if m.translations is not None
                    else np.broadcast_to(m.skeleton.offsets, (m.n_frames, m.n_joints, 3))
                    for m in g.clips
                ]
            )
        else:
            self.translations = None
        # the path joint (pelvis role) carries the ground pose; it and the joints above it are
        # the "root" of the blend, the joints below it the body
        self.path_joint = int(g.clips[0].path_joint)
        self.body = ~_above(np.asarray(g.clips[0].skeleton.parents), self.path_joint)
        pelvis = np.concatenate([np.asarray(m.pelvis_positions) for m in g.clips])
        self.wrot = np.concatenate([np.asarray(m.pelvis_rotations) for m in g.clips])  # world, (N, 4)
        self.height = pelvis[:, 1]
        self.pos = pelvis[:, [0, 2]]
        self.yaw = np.unwrap(quat.yaw(self.wrot))
        self.clip = g.clip_of
        self.first = np.zeros(g.n_frames, bool)
        self.first[g.offsets[:-1]] = True
        self.last = np.zeros(g.n_frames, bool)
        self.last[g.offsets[1:] - 1] = True
        self._last: list[bool] = self.last.tolist()
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
        self._lists: tuple[list[list[int]], list[list[int]], list[bool], list[bool], list[int], list[int]] | None = None

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

    def lists(self) -> tuple[list[list[int]], list[list[int]], list[bool], list[bool], list[int], list[int]]:
        """Plain-Python views for the enumeration loops (built once per graph).

        ``(out, into, last, first, clip, last_cum)``: transition targets and
        sources of each node, the clip-end / clip-start flags, the clip
        index, and ``last_cum[i]`` = number of clip ends before node ``i``.
        """
        if self._lists is None:
            n = self.graph.n_frames

            def split(M: sp.csr_matrix) -> list[list[int]]:
                ind = M.indices.tolist()
                ptr = M.indptr.tolist()
                return [ind[ptr[i] : ptr[i + 1]] for i in range(n)]

            lc = np.concatenate([[0], np.cumsum(self.last)]).tolist()
            self._lists = (
                split(self.T),
                split(self.Tt),
                self.last.tolist(),
                self.first.tolist(),
                np.asarray(self.clip).tolist(),
                lc,
            )
        return self._lists

    def natural(self, a: int, b: int) -> bool:
        return b == a + 1 and not self._last[a]

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
    """The motion playing graph ``nodes``, runs placed on the ground and seams blended.

    Each frame is moved rigidly over the ground (:func:`~mocaplab.editing.paths.apply_path`)
    so that its path joint follows the placement of its run.  A seam's jump
    is a displacement in the convention of :mod:`mocaplab.displacement`,
    ``q' = q exp(d)`` with ``d = log(q^-1 q')``: per body joint (below the
    path joint) between local rotations, for the path joint between its
    placed world rotations (applied to its local rotation, which turns its
    world rotation the same way: ``W exp(d) = parent (local exp(d))``), plus
    the path joint's height and the body joints' translations.
    """
    theta, trans = _placement(nodes, gd, first)
    raw = Motion(
        skeleton,
        gd.rot[nodes],
        gd.root[nodes],
        fps,
        translations=None if gd.translations is None else gd.translations[nodes],
        name=name,
    )
    placed = apply_path(raw, _rot2(theta, gd.pos[nodes]) + trans, theta)
    F = len(nodes)
    n = int(round(blend * fps))
    starts = _runs(nodes, gd)[1:]
    if not (n >= 1 and len(starts)):
        return placed
    rot = np.array(placed.rotations)
    root = np.array(placed.root_positions)
    tr = None if placed.translations is None else np.array(placed.translations)
    pj, body = gd.path_joint, gd.body
    w = _blend_weights(n)
    dr = np.zeros((F,) + rot.shape[1:-1] + (3,))
    dy = np.zeros(F)
    dt = None if tr is None else np.zeros_like(tr)
    for a in starts:
        prev = int(nodes[a - 1])
        if gd.last[prev]:
            continue  # no natural successor to compare with: the similar frame is the best guess
        exp_node = prev + 1
        act = int(nodes[a])
        d = np.zeros(rot.shape[1:-1] + (3,))
        d[body] = rotation_displacement(gd.rot[exp_node, body], gd.rot[act, body])
        exp_world = quat.mul(quat.from_yaw(theta[a - 1]), gd.wrot[exp_node])
        act_world = quat.mul(quat.from_yaw(theta[a]), gd.wrot[act])
        d[pj] = rotation_displacement(exp_world, act_world)
        d_h = gd.height[act] - gd.height[exp_node]
        before = a - 1 - np.arange(n)
        after = a + np.arange(n)
        okb = before >= 0
        oka = after < F
        cb = 0.5 * w[okb]
        ca = -0.5 * w[oka]
        dr[before[okb]] += cb[:, None, None] * d
        dr[after[oka]] += ca[:, None, None] * d
        dy[before[okb]] += cb * d_h
        dy[after[oka]] += ca * d_h
        if dt is not None and gd.translations is not None:
            d_t = np.where(body[:, None], gd.translations[act] - gd.translations[exp_node], 0.0)
            dt[before[okb]] += cb[:, None, None] * d_t
            dt[after[oka]] += ca[:, None, None] * d_t
    touched = np.flatnonzero(np.any(dr != 0, axis=(1, 2)) | (dy != 0))
    rot[touched] = displace(rot[touched], dr[touched])
    root[:, 1] += dy  # at joint 0: the whole body, path joint included, rises
    if tr is not None and dt is not None:
        tr += dt
    return placed.replace(rotations=rot, root_positions=root, translations=tr)


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
                "among its clips (build_graph([motion, ...]), with the same roles= as the editor)"
            )
        nodes = graph.offsets[c] + np.arange(motion.n_frames, dtype=np.int64)
        origin = np.arange(motion.n_frames, dtype=np.int64)
        p = motion.pelvis_positions[0]
        first = (float(p[0]), float(p[2]), float(quat.yaw(motion.pelvis_rotations[0])))
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


_HEADINGS: weakref.WeakKeyDictionary[Track, Array] = weakref.WeakKeyDictionary()


def _headings(track: Track) -> Array:
    """Unwrapped path-joint yaw of each current frame, shape (F,) (cached per track)."""
    h = _HEADINGS.get(track)
    if h is None:
        h = np.unwrap(quat.yaw(track.motion.pelvis_rotations))
        _HEADINGS[track] = h
    return h


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
def _positions_of(nodes: IntArray) -> dict[int, list[int]]:
    """Current frames playing each node."""
    out: dict[int, list[int]] = {}
    for p, n in enumerate(nodes.tolist()):
        out.setdefault(n, []).append(p)
    return out


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
    nl = track.nodes.tolist()
    F = len(nl)
    fps = float(track.motion.fps)
    lmin = max(1, int(math.ceil(min_duration * fps - 1e-9)))
    lmax = int(math.floor(max_duration * fps + 1e-9))
    where = _positions_of(track.nodes)
    out: dict[tuple[int, int, int, int], Transformation] = {}
    out_l, into_l, glast, gfirst, gclip, lcum = gd.lists()
    seam_cost = gd.seam_cost

    def add(kind: str, a: int, b: int, s: int, e: int, cost: float) -> None:
        key = (a, b, s, e)
        if key not in out:
            out[key] = Transformation(character, kind, (a, b), (s, e), fps, cost)

    def clean(s: int, u: int) -> bool:
        """Graph frames s..u lie in one clip, which does not end before u."""
        return gclip[s] == gclip[u] and lcum[u] == lcum[s]

    # breaks of consecutive numbering (bcum[i]: breaks among the steps before i) and seams in the sequence
    bcum = [0] * F
    seam_after = [False] * F
    for i in range(F - 1):
        brk = nl[i + 1] != nl[i] + 1
        bcum[i + 1] = bcum[i] + brk
        seam_after[i] = brk or glast[nl[i]]

    def plays(a: int, s: int, L: int) -> bool:
        """Current frames a .. a+L-1 play graph frames s .. s+L-1."""
        return nl[a] == s and bcum[a + L - 1] == bcum[a]

    # ---- deletions: seam x -> y with src[y] a successor of src[x]
    repeated = {n for n, g in where.items() if len(g) > 1}
    for x in range(F - 1):
        nx = nl[x]
        if not out_l[nx] and nx + 1 not in repeated:
            continue
        targets = list(out_l[nx])
        if not glast[nx]:
            targets.append(nx + 1)
        for d in targets:
            for y in where.get(d, ()):
                L = y - x - 1
                if lmin <= L <= lmax:
                    c = seam_cost(nx, d)
                    if c is not None:
                        add("deletion", x + 1, y, 0, 0, c)

    # ---- insertions (duplication included): before frame a, graph run [s, u]
    for a in range(1, F):
        prev, nxt = nl[a - 1], nl[a]
        if not (out_l[prev] or into_l[nxt] or seam_after[a - 1]):
            continue
        S = set(out_l[prev])
        if not glast[prev]:
            S.add(prev + 1)
        U = set(into_l[nxt])
        if not gfirst[nxt]:
            U.add(nxt - 1)
        for s in S:
            for u in U:
                L = u - s + 1
                if not lmin <= L <= lmax or not clean(s, u):
                    continue
                c1 = seam_cost(prev, s)
                c2 = seam_cost(u, nxt)
                if c1 is None or c2 is None:
                    continue
                if c1 == 0.0 and c2 == 0.0 and not seam_after[a - 1]:
                    continue
                # duplication: the run equals the current frames that follow (the copy goes first)
                if a + L <= F and plays(a, s, L):
                    add("duplication", a, a, s, u + 1, c1 + c2)
                elif a - L >= 1 and plays(a - L, s, L):
                    # the same sequence as duplicating before a - L: keep the canonical form
                    add("duplication", a - L, a - L, s, u + 1, c1 + c2)
                else:
                    add("insertion", a, a, s, u + 1, c1 + c2)

    # ---- replacements: seam x=a-1 -> s (s != src[a]) and u -> y=b (u != src[b-1])
    outs = [(x, so) for x in range(F - 1) for so in out_l[nl[x]] if so != nl[x + 1]]
    ins = [(y, ui) for y in range(1, F) for ui in into_l[nl[y]] if ui != nl[y - 1]]
    for x, s in outs:
        a = x + 1
        for y, u in ins:
            b = y
            if not lmin <= b - a <= lmax:
                continue
            L = u - s + 1
            if not lmin <= L <= lmax or not clean(s, u):
                continue
            net = abs(L - (b - a))
            if net and net < lmin:
                continue  # a replacement changing the duration by a sliver: too frequent (duration rule)
            if b - a == L and plays(a, s, L):
                continue
            c1 = seam_cost(nl[x], s)
            c2 = seam_cost(u, nl[y])
            if c1 is None or c2 is None:
                continue
            add("replacement", a, b, s, u + 1, c1 + c2)
    return sorted(out.values(), key=lambda t: (t.removed, t.inserted))


def protected_frames(constraints: Iterable[Any], character: int) -> set[int]:
    """Frames of ``character`` that may not be removed (section 5.2, "Constraints").

    Every frame of an instant constraint, and the first and last frames of
    a variational one (also for end-effector constraints of
    :mod:`mocaplab.refinement`).
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
_SEAM = np.array([-2, -1, 0, 1], dtype=np.int64)  # frames kept around each seam


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
class _Table:
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
    def of(cls, rows: _Rows, K: int, dim: int) -> _Table:
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


@dataclasses.dataclass
class _Parts:
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
    c = max(w.shape[0], cols.shape[0])
    w = np.broadcast_to(w, (c,) + w.shape[1:])
    idx = np.broadcast_to(np.arange(c, dtype=np.int64)[:, None, None] * n + cols, w.shape)
    return np.bincount(idx.ravel(), w.ravel(), minlength=c * n).astype(float).reshape(c, n)


def _res(cols: IntArray, vals: Array, rhs: Array, x: Array) -> Array:
    """Batched residuals ``M x - rhs``: (c, R)."""
    return np.sum(vals * _gather(x, cols), axis=-1) - rhs


class _Sys:
    """The three subsampled least-squares systems of every part (see :meth:`_Scene.systems`)."""

    n: int
    # constraint rows on one character that fit the band: (P, R_k, W) columns, values, (P, R_k) rhs, soft
    s_loc: tuple[IntArray, Array, Array]
    s_soft: NDArray[np.bool_]
    t_loc: tuple[IntArray, Array, Array]
    t_soft: NDArray[np.bool_]
    # coupled rows (Woodbury): ids, U (P, g, unknowns), rows each part takes part in (P, g)
    Gs: IntArray
    Us: Array
    act_s: NDArray[np.bool_]
    Gt: IntArray
    Ut: Array
    act_t: NDArray[np.bool_]
    lap: tuple[IntArray, Array]
    lap_energy: NDArray[np.bool_]
    sec: tuple[IntArray, Array]
    wv: Array
    rig: tuple[IntArray, Array]
    rig_w: Array
    tim: tuple[IntArray, Array, Array]
    bs: Array  # (P, 2n) local constraint part of the spatial right-hand sides
    y1: Array
    Z1: Array
    N2: Array
    Z2: Array
    yt: Array
    Zt: Array
    pad2: NDArray[np.bool_]
    L0: Array
    span: Array
    arc: Array
    vstep: NDArray[np.bool_]
    last: IntArray
    nfr: Array
    dt: Array


class _Scene:
    """The current scene prepared for subsampled evaluation of candidates.

    Every candidate of every character is evaluated in one batch.  Each
    candidate's transformed path and each untransformed path is a *part*;
    the parts' three least-squares systems (shape, scale, time) are built
    and solved together (padded to a common size), the constraint rows
    linking characters (or too long for a part's band) are left out of
    them and added back by the Woodbury identity, per *variant* (the scene
    with one candidate applied; variant 0 is the untransformed scene).  So
    the cost of an update is a fixed number of batched array operations,
    whatever the number of candidates and characters.
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
        *,
        tangents: Any = None,
    ) -> None:
        self.tracks = list(tracks)
        self.opts = opts
        K = len(tracks)
        self.K = K
        layout = Layout(tuple(t.n_frames for t in tracks))
        dts = [t.motion.dt for t in tracks]
        self.dts = np.array(dts, dtype=float)
        self.starts = np.array([float(s) for s in starts], dtype=float)
        wmax = max([1.0] + [float(c.weight) for c in constraints if hasattr(c, "weight") and not c.hard])
        self.pen = _PENALTY * wmax
        tang = tangents if tangents is not None else _Tangents(paths)
        self.space = _compile(
            constraints, SPATIAL, lambda c: spatial_rows(c, paths, layout, cast(Any, tang), step), layout, 2, self.pen
        )
        self.time = _compile(constraints, TEMPORAL, lambda c: temporal_rows(c, layout, dts, step), layout, 1, self.pen)
        self._ts = _Table.of(self.space, K, 2)
        self._tt = _Table.of(self.time, K, 1)
        self.segments = [list(s) for s in segments]
        # per-character arrays, concatenated (character k's frame f is row poff[k] + f)
        self.F = np.array([t.n_frames for t in tracks], dtype=np.int64)
        self.poff = np.concatenate([[0], np.cumsum(self.F)]).astype(np.int64)
        pos = [np.asarray(p.positions, dtype=float) for p in paths]
        self.P = np.concatenate(pos)
        self.H = np.concatenate([_headings(t) for t in tracks])
        self.C = np.concatenate(
            [np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(p, axis=0), axis=1))]) for p in pos]
        )
        # motion graphs, concatenated (node i of character k's graph is goff[k] + i)
        gds: list[_GraphData] = []
        where: dict[int, int] = {}
        goff = []
        total = 0
        for t in tracks:
            gd = _GraphData.of(t.graph)
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
        ratio = int(opts.subsample)
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

    # ------------------------------------------------------------- parts
    def parts(self, ts: Sequence[Transformation]) -> _Parts:
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
            r = int(self.opts.subsample)
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
        return _Parts(char, a, b, L, frames, nv, X, arc, rpt, rst, nfr, self.dts[char], self.starts[char])

    # ------------------------------------------------------------ systems
    def _cols(self, tab: _Table, ids: IntArray, p: _Parts) -> IntArray:
        """Unknown indices (within each part) of the entries of rows ``ids`` (P, R) -> (P, R, W)."""
        kk = _bsearch(p.frames, p.nv, _fmap(tab.frame[ids], p.a, p.b, p.L))
        return tab.dim * kk + tab.coord[ids] if tab.dim == 2 else kk

    def _local(self, tab: _Table, p: _Parts) -> tuple[tuple[IntArray, Array, Array], NDArray[np.bool_], IntArray]:
        """Each part's own constraint rows that fit its band; also the ids of those that do not."""
        ids = tab.intra_of[p.char]
        cols = self._cols(tab, ids, p)
        val = tab.val[ids]
        ok = _fits(cols, val, tab.band)
        # rows that do not fit are emptied here (zero values, one column) and coupled instead
        cols = np.where(ok[..., None], cols, cols[..., :1])
        rows = (cols, np.where(ok[..., None], val, 0.0), np.where(ok, tab.rhs[ids], 0.0))
        return rows, ok & tab.soft[ids], np.unique(ids[~ok])

    def _coupled(self, tab: _Table, p: _Parts, far: IntArray, m: int) -> tuple[IntArray, Array, NDArray[np.bool_]]:
        """Rows coupled by the Woodbury identity: ids (g,), U (P, g, m) and which rows each part holds (P, g)."""
        G = np.union1d(tab.cross, far).astype(np.int64)
        P_, g = len(p.char), len(G)
        if g == 0:
            return G, np.zeros((P_, 0, m)), np.zeros((P_, 0), bool)
        cols = self._cols(tab, np.broadcast_to(G, (P_, g)), p)
        val = np.broadcast_to(tab.val[G], cols.shape)
        use = ~tab.intra[G][None, :] | ~_fits(cols, val, tab.band)
        mask = (tab.char[G][None] == p.char[:, None, None]) & (val != 0) & use[..., None]
        q = (np.arange(P_, dtype=np.int64)[:, None, None] * g + np.arange(g, dtype=np.int64)[None, :, None]) * m
        U = np.bincount((q + cols)[mask], val[mask], minlength=P_ * g * m).astype(float).reshape(P_, g, m)
        return G, U, mask.any(axis=-1)

    def systems(self, p: _Parts) -> _Sys:
        """Build and solve the parts' systems (everything that does not depend on the other characters)."""
        S = _Sys()
        P_, n = p.frames.shape
        S.n = n
        m = 2 * n
        sq = math.sqrt(self.pen)
        idx = np.arange(n)
        valid = idx[None, :] < p.nv[:, None]
        vstep = valid[:, 1:]
        X = p.X
        span = np.where(vstep, np.diff(p.frames, axis=1), 1).astype(float)
        S.span, S.vstep, S.arc = span, vstep, p.arc
        S.last, S.nfr, S.dt = p.nv - 1, p.nfr.astype(float), p.dt
        S.s_loc, S.s_soft, far_s = self._local(self._ts, p)
        S.t_loc, S.t_soft, far_t = self._local(self._tt, p)
        S.Gs, S.Us, S.act_s = self._coupled(self._ts, p, far_s, m)
        S.Gt, S.Ut, S.act_t = self._coupled(self._tt, p, far_t, n)
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
            S.lap_energy = np.repeat(vint & ~rig, 2, axis=1)
        else:
            lap_c, lap_v = np.zeros((1, 0, 6), np.int64), np.zeros((P_, 0, 6))
            S.lap_energy = np.zeros((P_, 0), bool)
        S.lap = (lap_c, lap_v)
        pad = np.repeat(~valid, 2, axis=1)
        u2 = _BAND[2]
        Nc = _band(P_, m, u2, *S.s_loc[:2])  # constraint rows: in both phases
        N1 = _band(P_, m, u2, *S.lap) + Nc
        N1[:, u2] += _EPS + pad
        x0 = np.where(pad, 0.0, X.reshape(P_, -1))
        S.bs = _rhs(m, *S.s_loc)
        sol = _spd_solve(N1, np.concatenate([(S.bs + _EPS * x0)[..., None], np.swapaxes(S.Us, 1, 2)], axis=2))
        S.y1, S.Z1 = sol[..., 0], sol[..., 1:]
        # ---- phase 2: equation 7 on per-frame velocities, rows weighted 1/sqrt(mean span)
        if n >= 3:
            ia, ib = 1.0 / span[:, :-1], 1.0 / span[:, 1:]
            wv = np.where(valid[:, 2:], (0.5 * (span[:, :-1] + span[:, 1:])) ** -0.5, 0.0)
            g = idx[1:-1]
            cols_ = [np.stack([2 * (g - 1) + q, 2 * g + q, 2 * (g + 1) + q], axis=-1) for q in (0, 1)]
            vals_ = [np.stack([ia, -ia - ib, ib], axis=-1) * wv[..., None]] * 2
            sec_c = np.stack(cols_, axis=1).reshape(1, -1, 3)
            sec_v = np.stack(vals_, axis=2).reshape(P_, -1, 3)
            S.wv = wv
        else:
            sec_c, sec_v = np.zeros((1, 0, 3), np.int64), np.zeros((P_, 0, 3))
            S.wv = np.zeros((P_, 0))
        S.sec = (sec_c, sec_v)
        st = idx[:-1]
        rc = np.stack([np.stack([2 * (st + 1) + q, 2 * st + q], axis=-1) for q in (0, 1)], axis=1).reshape(1, -1, 2)
        wrs = np.repeat(np.where(p.rst, sq, 0.0), 2, axis=1)
        S.rig_w = wrs
        S.rig = (rc, wrs[:, :, None] * np.array([1.0, -1.0]))
        N2 = _band(P_, m, u2, *S.sec) + _band(P_, m, u2, *S.rig) + Nc
        N2[:, u2] += _EPS + pad
        S.N2, S.pad2 = N2, pad
        S.L0 = np.linalg.norm(np.diff(X, axis=1), axis=-1)
        S.Z2 = _spd_solve(N2, np.swapaxes(S.Us, 1, 2)) if S.Us.shape[1] else np.zeros((P_, m, 0))
        # ---- time: t[i+1] - t[i] = m_i h, rows weighted 1/sqrt(m_i)
        wt = np.where(vstep, 1.0 / np.sqrt(np.maximum(span, 1.0)), 0.0)
        tc = np.stack([idx[1:], idx[:-1]], axis=-1)[None]
        tv = np.stack([wt, -wt], axis=-1)
        S.tim = (tc, tv, span * p.dt[:, None] * wt)
        u1 = _BAND[1]
        Nt = _band(P_, n, u1, tc, tv) + _band(P_, n, u1, *S.t_loc[:2])
        Nt[:, u1] += _EPS + ~valid
        t0 = np.where(valid, p.start[:, None] + p.frames * p.dt[:, None], 0.0)
        bt = _rhs(n, *S.tim) + _rhs(n, *S.t_loc) + _EPS * t0
        sol = _spd_solve(Nt, np.concatenate([bt[:, :, None], np.swapaxes(S.Ut, 1, 2)], axis=2))
        S.yt, S.Zt = sol[..., 0], sol[..., 1:]
        return S

    # ------------------------------------------------------------- solver
    def _evaluate(self, S: _Sys, p: _Parts, C: int) -> dict[str, Array]:
        """Equation 10 for every variant: the scene (0) and the scene with candidate ``i`` (``i + 1``).

        Per variant ``v`` and domain, ``(B + U^T U) x = b + U^T c`` with ``B``
        block diagonal (one block per character, taken from the variant's
        parts) and ``U`` the coupled rows: ``x = y + Z w``, ``w = S^-1 (c - U
        y)``, ``y = B^-1 b``, ``Z = B^-1 U^T`` and ``S = I + U Z`` (Woodbury).
        """
        K = self.K
        V = 1 + C
        qidx = np.tile(np.arange(K, dtype=np.int64), (V, 1))
        kc = p.char[K:]
        vc = np.arange(1, V)
        qidx[vc, kc] = K + np.arange(C)
        pq = qidx.ravel()
        n = S.n
        m = 2 * n
        VK = V * K

        def couple(
            yv: Array, Z: Array, U: Array, act: NDArray[np.bool_], G: IntArray, tab: _Table
        ) -> tuple[Array, Array]:
            if not len(G):
                return yv, np.zeros(V)
            Zq, Uq = Z[qidx], U[qidx]
            Sm = np.eye(len(G)) + np.sum((U @ Z)[qidx], axis=1)
            c = np.where(np.any(act[qidx], axis=1), tab.rhs[G], 0.0)
            uy = np.sum((Uq @ yv[..., None])[..., 0], axis=1)
            w = np.linalg.solve(Sm, (c - uy)[..., None])
            x = yv + (Zq @ w[:, None])[..., 0]
            r = np.sum((Uq @ x[..., None])[..., 0], axis=1) - c
            return x, np.sum(np.where(tab.soft[G], r, 0.0) ** 2, axis=1)

        def soft(loc: tuple[IntArray, Array, Array], mask: NDArray[np.bool_], x: Array) -> Array:
            cols, vals, rhs = loc
            if not cols.shape[1]:
                return np.zeros(x.shape[0])
            r = _res(cols[pq], vals[pq], rhs[pq], x)
            return np.sum(np.where(mask[pq], r, 0.0) ** 2, axis=1)

        def per_variant(e: Array) -> Array:
            return np.sum(e.reshape(V, K), axis=1)

        # phase 1 (shape)
        x1, e_shape = couple(S.y1[qidx], S.Z1, S.Us, S.act_s, S.Gs, self._ts)
        x1f = x1.reshape(VK, m)
        lr = np.sum(S.lap[1][pq] * _gather(x1f, S.lap[0]), axis=-1)
        e = np.sum(np.where(S.lap_energy[pq], lr, 0.0) ** 2, axis=1) + soft(S.s_loc, S.s_soft, x1f)
        e_shape = e_shape + per_variant(e)
        # phase 2 (scale): right-hand sides from phase 1, solved per part
        P2 = x1f.reshape(VK, n, 2)
        seg = P2[:, 1:] - P2[:, :-1]
        ln = np.linalg.norm(seg, axis=-1)
        L0 = S.L0[pq]
        vb = seg * np.divide(L0, ln, out=np.ones_like(ln), where=ln > 1e-12)[..., None]
        ub = vb / S.span[pq][..., None]
        rhs2 = S.bs[pq] + _EPS * x1f
        r_sec = np.zeros((VK, 0))
        if n >= 3:
            r_sec = ((ub[:, 1:] - ub[:, :-1]) * S.wv[pq][..., None]).reshape(VK, -1)
            rhs2 += _rhs(m, S.sec[0], S.sec[1][pq], r_sec)
        rhs2 += _rhs(m, S.rig[0], S.rig[1][pq], vb.reshape(VK, -1) * S.rig_w[pq])
        rhs2 = np.where(S.pad2[pq], 0.0, rhs2).reshape(V, K, m)
        y2 = np.transpose(_spd_solve(S.N2[:K], np.transpose(rhs2, (1, 2, 0))), (2, 0, 1)).copy()
        if C:
            y2[vc, kc] = _spd_solve(S.N2[K:], rhs2[vc, kc][..., None])[..., 0]
        x2, e_scale = couple(y2, S.Z2, S.Us, S.act_s, S.Gs, self._ts)
        x2f = x2.reshape(VK, m)
        e = soft(S.s_loc, S.s_soft, x2f)
        if n >= 3:
            e = e + np.sum(_res(S.sec[0], S.sec[1][pq], r_sec, x2f) ** 2, axis=1)
        e_scale = e_scale + per_variant(e)
        # time
        xt, e_time = couple(S.yt[qidx], S.Zt, S.Ut, S.act_t, S.Gt, self._tt)
        xtf = xt.reshape(VK, n)
        tc, tv, trhs = S.tim
        e = np.sum(_res(tc, tv[pq], trhs[pq], xtf) ** 2, axis=1) + soft(S.t_loc, S.t_soft, xtf)
        e_time = e_time + per_variant(e)
        # length and duration changes: full-path arcs scaled by the chords' change
        c1 = np.linalg.norm(np.diff(x2f.reshape(VK, n, 2), axis=1), axis=-1)
        ratio = np.divide(S.arc[pq], L0, out=np.ones_like(L0), where=L0 > 1e-6)
        dL = per_variant(np.abs(np.sum(np.where(S.vstep[pq], ratio * (c1 - L0), 0.0), axis=1)))
        last = xtf[np.arange(VK), S.last[pq]]
        dT = per_variant(np.abs(last - xtf[:, 0] - (S.nfr[pq] - 1) * S.dt[pq]))
        total = e_shape + e_scale + e_time + self.opts.cs * dL + self.opts.ct * dT
        return {"shape": e_shape, "scale": e_scale, "time": e_time, "length": dL, "duration": dT, "total": total}


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
            tangents=getattr(getattr(inner, "_space", None), "tangent_rows", None),
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
