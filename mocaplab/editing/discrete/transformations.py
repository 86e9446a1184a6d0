"""Discrete transformations of a character's motion (Kim et al. 2009, section 5.1).

Representation
--------------
Each character's current motion is a sequence of motion-graph nodes
(:class:`~mocaplab.editing.graph.MotionGraph`, by default built from the
character's own clip): ``nodes[p]`` is the graph frame played at current
frame ``p`` (:class:`Track`).  Every transformation is "replace current
frames ``[a, b)`` by graph frames ``[s, e)``" (:class:`Transformation`; these
two intervals are half-open, like Python slices, and are outputs, never
``frames=`` arguments), with two seams ``nodes[a-1] -> s`` and ``e-1 ->
nodes[b]`` (for a deletion, the single seam ``nodes[a-1] -> nodes[b]``).  A
seam is allowed if it is a transition of the graph (``i -> j + 1`` for a
similar pair ``(i, j)``) or the natural continuation ``n -> n + 1``.  This
gives exactly the three types of section 5.1 (Figure 7):

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
before and ``-d w / 2`` after the seam, ``w`` falling from 1 to 0 over ``blend``
seconds on each side by :func:`~mocaplab.displacement.blend_ramp` (no velocity or
acceleration jump where the blend ends), rotations as ``q exp(c d)`` (the one displacement
convention of :mod:`mocaplab.displacement`), so there is no pop.  (A frame
that ends its clip has no successor to compare with; its seam is not
blended.)  The motion path and the time track (uniform, one frame step per
frame) follow from the new motion; constraints follow their frames
(:func:`map_constraint`).

The arrays of a motion graph that these operations read (poses, ground
poses, arc lengths, adjacency) are gathered once into :class:`GraphArrays`,
which every :class:`Track` of that graph shares (no module-level cache).
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Sequence
from functools import cached_property
from typing import Any

import numpy as np
import scipy.sparse as sp
from numpy.typing import NDArray

from ... import quat
from ...displacement import blend_ramp, displace, rotation_displacement
from ...goals import EndEffector
from ...motion import Motion
from ..constraints import SPATIAL, TEMPORAL, EndEffectorConstraint, Relative, Sync
from ..graph import MotionGraph, _above
from ..paths import apply_path

__all__ = [
    "TYPES",
    "Transformation",
    "GraphArrays",
    "Track",
    "apply_transformation",
    "enumerate_transformations",
    "map_constraint",
]

Array = NDArray[np.float64]
IntArray = NDArray[np.int64]

#: The transformation types (duplication is the special insertion of section 5.1).
TYPES: tuple[str, ...] = ("deletion", "insertion", "duplication", "replacement")


@dataclasses.dataclass(frozen=True)
class Transformation:
    """One discrete transformation: current frames ``[a, b)`` become graph frames ``[s, e)``.

    Parameters
    ----------
    character : int
        Index of the character in the scene.
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

    Examples
    --------
    >>> cut = Transformation(0, "deletion", (40, 70), (0, 0), 30.0)
    >>> str(cut), cut.length_change, cut.removed_duration
    ('character 0: delete frames 40..69 (1.00 s)', -30, 1.0)
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



def _rot2(theta: Any, v: Array) -> Array:
    """Rotate ground vectors ``(x, z)`` by yaw ``theta`` (the rotation of :func:`mocaplab.quat.from_yaw`)."""
    c, s = np.cos(theta), np.sin(theta)
    x, z = v[..., 0], v[..., 1]
    return np.stack([c * x + s * z, -s * x + c * z], axis=-1)


class GraphArrays:
    """Arrays of a motion graph gathered once: poses, ground poses, arc lengths, adjacency.

    Build one per graph (:meth:`Track.from_motion` does, or takes one to
    share); tracks of the same graph share it.  Read-only after construction.
    """

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


def _runs(nodes: IntArray, gd: GraphArrays) -> IntArray:
    """Start positions of runs of consecutive graph frames (first is 0)."""
    if len(nodes) == 0:
        return np.zeros(0, np.int64)
    brk = (np.diff(nodes) != 1) | gd.last[nodes[:-1]]
    return np.concatenate([[0], np.flatnonzero(brk) + 1]).astype(np.int64)


def _placement(nodes: IntArray, gd: GraphArrays, first: tuple[float, float, float]) -> tuple[Array, Array]:
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
    """Seam weights, 1 at the seam falling to 0 at ``n`` frames: the package's one blend ramp."""
    return blend_ramp((n - np.arange(n)) / n)


def _assemble(
    nodes: IntArray,
    gd: GraphArrays,
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
    if tr is not None and dt is not None:
        tr += dt
    # the whole body, path joint included, rises (at the pelvis below a static reference root)
    rise = np.zeros((F, 3))
    rise[:, 1] = dy
    return placed.replace(rotations=rot, translations=tr).transformed(translation=rise)


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
    arrays : GraphArrays
        The graph's arrays (shared by the tracks of one graph).
    """

    graph: MotionGraph
    nodes: IntArray
    origin: IntArray
    first: tuple[float, float, float]
    motion: Motion
    arrays: GraphArrays

    @property
    def n_frames(self) -> int:
        return len(self.nodes)

    @cached_property
    def headings(self) -> Array:
        """Unwrapped path-joint yaw of each current frame, shape (F,)."""
        h = np.unwrap(quat.yaw(self.motion.pelvis_rotations))
        h.flags.writeable = False
        return h

    @classmethod
    def from_motion(cls, motion: Motion, graph: MotionGraph, arrays: GraphArrays | None = None) -> Track:
        """The track of an unedited clip of ``graph`` (``arrays``: the graph's, to share; built if None)."""
        if arrays is not None and arrays.graph is not graph:
            raise ValueError("Expected `arrays` of the same motion graph (GraphArrays(graph))")
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
        return cls(graph, nodes, origin, first, motion, GraphArrays(graph) if arrays is None else arrays)

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
    gd = track.arrays
    a, b = t.removed
    s, e = t.inserted
    ins = np.arange(s, e, dtype=np.int64)
    nodes = np.concatenate([track.nodes[:a], ins, track.nodes[b:]])
    new_origin = np.full(e - s, -1, dtype=np.int64)
    origin = np.concatenate([track.origin[:a], new_origin, track.origin[b:]])
    m = track.motion
    motion = _assemble(nodes, gd, track.first, m.skeleton, m.fps, blend, m.name)
    return Track(track.graph, nodes, origin, track.first, motion, gd)


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
    gd = track.arrays
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



def _map_interval(track: Track, frames: tuple[int, int]) -> tuple[int, int]:
    """A half-open interval of input-clip frames, moved to the track's current frames (first and last follow)."""
    return (track.frame_of(int(frames[0])), track.frame_of(int(frames[1]) - 1) + 1)


def _map_effector(e: EndEffector, track: Track) -> EndEffector:
    """``e`` with its frames (input clip) moved to the track's current frames."""
    f = e.frames
    if isinstance(f, (int, np.integer)):
        new: Any = track.frame_of(int(f))
    else:
        if isinstance(f, tuple) and len(f) == 2:
            new = _map_interval(track, f)
        elif isinstance(f, range):
            new = range(track.frame_of(f[0]), track.frame_of(f[-1]) + 1) if len(f) else f
        else:
            new = [track.frame_of(int(v)) for v in f]
    return dataclasses.replace(e, frames=new)


def map_constraint(c: Any, tracks: Sequence[Track], changed: Sequence[bool]) -> Any:
    """``c`` with its input-clip frames replaced by the current frames of ``tracks``.

    A frame follows its pose (:meth:`Track.frame_of`); ``changed[k]`` says
    whether character ``k``'s track differs from its input clip (others are
    left alone).  An :class:`~mocaplab.editing.constraints.EndEffectorConstraint`
    comes back in its wrapped form around the mapped end effector.
    """
    if isinstance(c, EndEffectorConstraint):
        if not changed[c.character]:
            return c
        return EndEffectorConstraint(c.character, _map_effector(c.constraint, tracks[c.character]))
    if isinstance(c, EndEffector):
        return _map_effector(c, tracks[c.character]) if changed[c.character] else c
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
        upd["frames"] = _map_interval(tr, frames)
    if hasattr(c, "end_frame"):
        upd["end_frame"] = tr.frame_of(c.end_frame)
    if isinstance(c, (Relative, Sync)):
        to = tracks[c.other]
        if c.other_frame is not None:
            upd["other_frame"] = to.frame_of(c.other_frame)
        if c.other_frames is not None:
            upd["other_frames"] = _map_interval(to, c.other_frames)
        elif c.frames is not None and c.other != c.character:
            # frames of `other` default to the same numbers: make them explicit
            upd["other_frames"] = _map_interval(to, c.frames)
    return dataclasses.replace(c, **upd)
