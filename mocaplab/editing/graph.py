"""Motion graphs for discrete motion editing (Kim et al. 2009, section 5.1).

The nodes of a motion graph are the frames of one or more clips; an edge is
a *transition* from a frame to another one that may follow it plausibly.
Following Lee et al. 2002, two frames ``i`` and ``j`` are *similar* when the
distance ``D(i, j)`` between their feature vectors is small; a similar pair
``(i, j)`` gives the two transitions ``i -> j + 1`` and ``j -> i + 1`` (after
playing ``i`` the motion may continue where ``j`` continues, and vice
versa).  Section 5.1 builds its deletions, insertions and replacements from
those transitions (:mod:`mocaplab.editing.discrete.transformations`).

Frame distance (in the spirit of Lee and Lee 2006)
--------------------------------------------------
``D(i, j) = |f_i - f_j|^2`` with ``f`` the concatenation of weighted
features (:func:`frame_features`, weights in :class:`SimilarityWeights`):

"Root" is the motion's path joint (:attr:`mocaplab.motion.Motion.path_joint`,
the pelvis role): its world position and rotation, whatever its index; the
joints above it (a static reference joint) are part of the ground placement
and are left out like it.

* **joint angles**: each other joint's local rotation as a quaternion
  ``2 q`` (sign chosen with ``w >= 0``): ``|2 q_a - 2 q_b|^2 ~ theta^2`` for a
  small angle ``theta`` between them, so the term is in squared radians.
  Joint ``j`` is weighted by the length of the bones it moves (sum of the
  bone lengths of its subtree), normalised to 1 for the largest subtree:
  a spine or hip rotation matters, a finger hardly;
* **root height** (metres);
* **root orientation without the heading**: the root rotation with its yaw
  removed (pitch and roll only, the ``2 q`` form again): where the
  character faces on the ground does not matter;
* **joint velocities**: local angular velocities (rad/s, central
  differences over :data:`VELOCITY_SPAN` seconds, so that the same clip at
  24 or 120 fps gives the same features: over one frame each side the
  capture's noise grows with the frame rate, and 16_15 at 120 fps had
  twice the distance of the same pair of moments at 24 fps), with the
  joint-angle weights;
* **root velocities in the body frame**: the root's linear velocity (m/s)
  and angular velocity (rad/s) expressed in its heading frame (yaw removed),
  so a walk is similar to the same walk in another direction.

With the default weights one squared "unit" of ``D`` is about one radian of
rotation on the largest joint, 10 cm of root height, 1 rad of pelvis tilt,
10 rad/s of joint rotation speed, 3 m/s of root velocity or 5 rad/s of root
turning speed.  Joints whose weight is below ``min_joint_weight`` (fingers,
thumbs) are left out entirely, which also makes the features shorter.

Transitions: local minima, threshold, sparse storage
----------------------------------------------------
Many neighbouring pairs are similar (motion is coherent in time), so only the
*local minima* of ``D`` (local maxima of similarity) within a window of
``window`` seconds in both ``i`` and ``j`` are kept, then only those with
``D < threshold``.  Pairs closer than ``min_gap`` seconds in the same clip
are dropped (they are the trivial neighbours of a frame).  The matrix ``D``
is computed in row blocks of ``chunk`` frames (each with a halo of the
window), only for ``j >= i - window`` (it is symmetric), so memory is
``O(chunk * N)``, never ``N x N``; only the kept pairs are stored, as arrays
``pairs (M, 2)`` and ``costs (M,)`` (and a :mod:`scipy.sparse` matrix on
demand).

Examples
--------
>>> from mocaplab import data
>>> walk = data.cmu("16_15").resample(30)
>>> g = build_graph([walk])
>>> src, dst, cost = g.transitions()
>>> len(src) == 2 * len(g.pairs)
True
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np
import scipy.sparse as sp
from numpy.typing import NDArray
from scipy.ndimage import minimum_filter

from .. import quat
from ..kinematics import angular_velocities, velocities
from ..motion import Motion
from .paths import with_roles

__all__ = [
    "SimilarityWeights",
    "MotionGraph",
    "build_graph",
    "frame_features",
    "joint_weights",
    "frame_distances",
    "VELOCITY_SPAN",
]

Array = NDArray[np.float64]

#: Seconds over which the features' velocities are differenced (one frame each side at 30 fps, four at 120).
VELOCITY_SPAN = 1.0 / 15.0


@dataclasses.dataclass(frozen=True)
class SimilarityWeights:
    """Weights of the frame distance (squared units; see the module docstring).

    Attributes
    ----------
    joint_angles : float
        Per squared radian of a joint of weight 1.
    root_height : float
        Per squared metre (100: 10 cm counts like 1 rad).
    root_tilt : float
        Per squared radian of root pitch/roll.
    joint_velocities : float
        Per (rad/s)^2 of a joint of weight 1.
    root_velocity : float
        Per (m/s)^2 of the root's body-frame linear velocity.
    root_angular_velocity : float
        Per (rad/s)^2 of the root's body-frame angular velocity.
    min_joint_weight : float
        Joints whose subtree weight is below this are ignored.
    """

    joint_angles: float = 1.0
    root_height: float = 100.0
    root_tilt: float = 1.0
    joint_velocities: float = 0.01
    root_velocity: float = 0.1
    root_angular_velocity: float = 0.04
    min_joint_weight: float = 0.05

    def __post_init__(self) -> None:
        for f in dataclasses.fields(self):
            v = float(getattr(self, f.name))
            if not np.isfinite(v) or v < 0:
                raise ValueError(f"Expected SimilarityWeights.{f.name} >= 0, got {getattr(self, f.name)!r}")
            object.__setattr__(self, f.name, v)


def _above(parents: NDArray[np.int64], j: int) -> NDArray[np.bool_]:
    """Mask of joint ``j`` and its ancestors."""
    out = np.zeros(len(parents), bool)
    while j >= 0:
        out[j] = True
        j = int(parents[j])
    return out


def joint_weights(skeleton: Any, *, path_joint: int = 0) -> Array:
    """Weight of each joint: total bone length of its subtree, max 1 over the other joints.

    Parameters
    ----------
    skeleton : Skeleton
    path_joint : int
        The root of the features (:attr:`mocaplab.motion.Motion.path_joint`).

    Returns
    -------
    ndarray, shape (J,)
        ``path_joint`` and its ancestors weigh 1 by convention; the others
        are normalised so that the largest of them weighs 1.
    """
    parents = np.asarray(skeleton.parents)
    J = len(parents)
    L = np.zeros(J)
    offs = np.linalg.norm(np.asarray(skeleton.offsets, dtype=float), axis=-1)
    # bone from a joint to each child, plus end sites
    for j in range(1, J):
        L[parents[j]] += offs[j]
    es_par = np.asarray(getattr(skeleton, "end_site_parents", ()), dtype=np.int64).reshape(-1)
    es_off = np.asarray(getattr(skeleton, "end_site_offsets", ()), dtype=float).reshape(-1, 3)
    np.add.at(L, es_par, np.linalg.norm(es_off, axis=1))
    # accumulate subtrees (parents[j] < j)
    for j in range(J - 1, 0, -1):
        L[parents[j]] += L[j]
    w = np.ones(J)
    rest = ~_above(parents, int(path_joint))
    if rest.any():
        m = float(L[rest].max())
        w[rest] = L[rest] / m if m > 0 else 1.0
    return w


def _canonical(q: Array) -> Array:
    return np.where(q[..., 3:4] < 0, -q, q)


def frame_features(
    motion: Motion, weights: SimilarityWeights | None = None, *, roles: Mapping[str, Any] | None = None
) -> NDArray[np.float32]:
    """Weighted feature vectors whose squared distances are ``D`` (module docstring).

    Parameters
    ----------
    motion : Motion
    weights : SimilarityWeights, optional
    roles : mapping, optional
        Joint roles fixed by hand (:func:`~mocaplab.editing.paths.with_roles`).

    Returns
    -------
    ndarray of float32, shape (F, D)
    """
    if not isinstance(motion, Motion):
        raise TypeError(f"Expected `motion` to be a Motion, got {type(motion).__name__}")
    w = SimilarityWeights() if weights is None else weights
    if not isinstance(w, SimilarityWeights):
        raise TypeError(f"Expected `weights` to be SimilarityWeights, got {type(w).__name__}")
    motion = with_roles(motion, roles)
    rot = np.asarray(motion.rotations, dtype=float)
    F = rot.shape[0]
    pj = motion.path_joint
    jw = joint_weights(motion.skeleton, path_joint=pj)
    keep = np.flatnonzero((jw >= w.min_joint_weight) & ~_above(np.asarray(motion.skeleton.parents), pj))
    sj = np.sqrt(jw[keep])
    local = rot[:, keep]
    parts = [2.0 * _canonical(local) * (np.sqrt(w.joint_angles) * sj)[None, :, None]]
    root_q = np.asarray(motion.pelvis_rotations, dtype=float)
    root_p = np.asarray(motion.pelvis_positions, dtype=float)
    heading = quat.yaw(root_q)
    unyaw = quat.from_yaw(-heading)
    tilt = quat.mul(unyaw, root_q)
    parts.append(2.0 * _canonical(tilt)[:, None, :] * np.sqrt(w.root_tilt))
    parts.append(root_p[:, 1:2, None] * np.sqrt(w.root_height))
    qu = quat.unroll(local, axis=0)
    fps = motion.fps
    parts.append(angular_velocities(qu, fps, span=VELOCITY_SPAN) * (np.sqrt(w.joint_velocities) * sj)[None, :, None])
    vel = velocities(root_p, fps, span=VELOCITY_SPAN)
    parts.append(quat.rotate(unyaw, vel)[:, None, :] * np.sqrt(w.root_velocity))
    omega = angular_velocities(quat.unroll(root_q, axis=0), fps, span=VELOCITY_SPAN)
    parts.append(quat.rotate(unyaw, omega)[:, None, :] * np.sqrt(w.root_angular_velocity))
    return np.concatenate([p.reshape(F, -1) for p in parts], axis=1).astype(np.float32)


def frame_distances(a: Any, b: Any = None, *, weights: SimilarityWeights | None = None) -> Array:
    """Dense distance matrix ``D`` between the frames of two clips (small clips only).

    Parameters
    ----------
    a, b : Motion or ndarray of features (F, D)
        ``b`` defaults to ``a``.
    weights : SimilarityWeights, optional

    Returns
    -------
    ndarray, shape (F_a, F_b)
    """
    fa = frame_features(a, weights) if isinstance(a, Motion) else np.asarray(a, dtype=np.float32)
    fb = fa if b is None else (frame_features(b, weights) if isinstance(b, Motion) else np.asarray(b, np.float32))
    return _sqdist(fa.astype(float), fb.astype(float))


def _sqdist(fa: Any, fb: Any) -> Any:
    d = np.einsum("ij,ij->i", fa, fa)[:, None] + np.einsum("ij,ij->i", fb, fb)[None, :] - 2.0 * (fa @ fb.T)
    np.maximum(d, 0.0, out=d)
    return d


@dataclasses.dataclass(frozen=True, eq=False)
class MotionGraph:
    """Sparse transitions between the frames of one or more clips.

    Frames are numbered globally: clip ``c``'s frame ``f`` is node
    ``offsets[c] + f``.  Build one with :func:`build_graph`.

    Parameters
    ----------
    clips : tuple of Motion
        Same joint names and frame rate.
    offsets : ndarray of int, shape (C + 1,)
        First node of each clip, then the node count N.
    pairs : ndarray of int, shape (M, 2)
        Similar frame pairs ``(i, j)``, ``i < j`` (global numbering).
    costs : ndarray, shape (M,)
        Their distances ``D(i, j)``.
    threshold, window, min_gap : float
        The parameters used (distance, seconds, seconds).
    weights : SimilarityWeights
        The weights of the frame distance.

    Examples
    --------
    A 30 fps walk: frame 10 looks like frame 45, one gait cycle (1.17 s) later:

    >>> from mocaplab.data import cmu
    >>> g = build_graph([cmu("16_15").resample(30)])
    >>> g.n_frames, g.offsets.tolist(), g.pairs[0].tolist(), round(float(g.costs[0]), 3)
    (118, [0, 118], [10, 45], 0.012)
    """

    clips: tuple[Motion, ...]
    offsets: NDArray[np.int64]
    pairs: NDArray[np.int64]
    costs: Array
    threshold: float
    window: float
    min_gap: float
    weights: SimilarityWeights

    @property
    def n_frames(self) -> int:
        return int(self.offsets[-1])

    @property
    def fps(self) -> float:
        return float(self.clips[0].fps)

    @property
    def clip_of(self) -> NDArray[np.int64]:
        """Clip index of every node, shape (N,)."""
        return np.repeat(np.arange(len(self.clips)), np.diff(self.offsets))

    def locate(self, node: int) -> tuple[int, int]:
        """``(clip, frame)`` of a global node index."""
        if not 0 <= node < self.n_frames:
            raise IndexError(f"Expected a node in 0..{self.n_frames - 1}, got {node}")
        c = int(np.searchsorted(self.offsets, node, side="right") - 1)
        return c, int(node - self.offsets[c])

    def transitions(self) -> tuple[NDArray[np.int64], NDArray[np.int64], Array]:
        """Directed transitions ``src -> dst`` with their costs.

        Each pair ``(i, j)`` gives ``i -> j + 1`` and ``j -> i + 1`` when the
        target exists in the same clip.

        Returns
        -------
        src, dst : ndarray of int, shape (T,)
        cost : ndarray, shape (T,)
        """
        i, j = self.pairs[:, 0], self.pairs[:, 1]
        clip = self.clip_of
        last = np.zeros(self.n_frames, bool)
        last[self.offsets[1:] - 1] = True
        ok1 = ~last[j]
        ok2 = ~last[i]
        src = np.concatenate([i[ok1], j[ok2]])
        dst = np.concatenate([j[ok1] + 1, i[ok2] + 1])
        cost = np.concatenate([self.costs[ok1], self.costs[ok2]])
        del clip
        order = np.lexsort((dst, src))
        return src[order], dst[order], cost[order]

    def transition_matrix(self) -> sp.csr_matrix:
        """Sparse ``(N, N)`` matrix, entry ``[src, dst]`` = cost (explicit zeros kept)."""
        src, dst, cost = self.transitions()
        m = sp.csr_matrix((cost, (src, dst)), shape=(self.n_frames, self.n_frames))
        return m

    def similar(self) -> sp.csr_matrix:
        """Symmetric sparse ``(N, N)`` matrix of the kept pairs' costs."""
        i, j = self.pairs[:, 0], self.pairs[:, 1]
        n = self.n_frames
        return sp.csr_matrix(
            (np.concatenate([self.costs, self.costs]), (np.concatenate([i, j]), np.concatenate([j, i]))), shape=(n, n)
        )

    def clip_index(self, motion: Motion) -> int | None:
        """Index of the clip whose poses equal ``motion``'s (up to its ground placement), or None.

        Compared: the local rotations (and per-joint translations) of the
        joints below the path joint and the path joint's height.
        """
        for c, m in enumerate(self.clips):
            if m.n_frames != motion.n_frames or m.skeleton.names != motion.skeleton.names:
                continue
            pj = m.path_joint
            if motion.path_joint != pj:
                continue
            body = ~_above(np.asarray(m.skeleton.parents), pj)
            if not np.allclose(m.rotations[:, body], motion.rotations[:, body], atol=1e-9):
                continue
            if (m.translations is None) != (motion.translations is None):
                continue
            if m.translations is not None and motion.translations is not None:
                if not np.allclose(m.translations[:, body], motion.translations[:, body], atol=1e-9):
                    continue
            if not np.allclose(m.pelvis_positions[:, 1], motion.pelvis_positions[:, 1], atol=1e-9):
                continue
            return c
        return None

    def __repr__(self) -> str:
        return (
            f"<MotionGraph: {len(self.clips)} clip(s), {self.n_frames} frames, {len(self.pairs)} similar pairs "
            f"(threshold {self.threshold:g}, window {self.window:g} s)>"
        )


def build_graph(
    motions: Motion | Sequence[Motion],
    *,
    weights: SimilarityWeights | None = None,
    threshold: float = 0.1,
    window: float = 0.5,
    min_gap: float = 0.3,
    chunk: int = 1024,
    roles: Mapping[str, Any] | None = None,
) -> MotionGraph:
    """Build a motion graph over ``clips`` (section 5.1; see the module docstring).

    Parameters
    ----------
    motions : Motion or sequence of Motion
        Same skeleton (joint names) and frame rate.
    weights : SimilarityWeights, optional
    threshold : float
        Keep pairs with ``D(i, j) < threshold``.
    window : float
        Half-width (seconds) of the square window in which a kept pair is a
        local minimum of ``D``.
    min_gap : float
        Pairs closer than this (seconds) in the same clip are dropped.
    chunk : int
        Rows of ``D`` computed at once (memory ``~ 4 chunk N`` bytes).
    roles : mapping, optional
        Joint roles fixed by hand, given to every clip
        (:func:`~mocaplab.editing.paths.with_roles`; the graph's clips carry them).

    Returns
    -------
    MotionGraph

    Raises
    ------
    TypeError
        For an entry of ``motions`` that is not a Motion.
    ValueError
        For no motion, motions of other joint names or frame rates, or a
        ``threshold``, ``window``, ``min_gap`` or ``chunk`` out of range.

    Examples
    --------
    >>> from mocaplab.data import cmu
    >>> g = build_graph(cmu("16_15").resample(30), threshold=0.02)
    >>> g.pairs.tolist(), g.fps
    ([[10, 45], [10, 80], [44, 79], [64, 100]], 30.0)
    """
    if isinstance(motions, Motion):
        motions = (motions,)
    motions = tuple(motions)
    if roles is not None:
        motions = tuple(with_roles(m, roles) if isinstance(m, Motion) else m for m in motions)
    if not motions:
        raise ValueError("Expected at least one motion in `motions`, got none")
    for k, m in enumerate(motions):
        if not isinstance(m, Motion):
            raise TypeError(f"Expected motions[{k}] to be a Motion, got {type(m).__name__}")
        if m.skeleton.names != motions[0].skeleton.names:
            raise ValueError(f"motions[{k}] has a different skeleton (joint names) from motions[0]")
        if abs(m.fps - motions[0].fps) > 1e-6 * motions[0].fps:
            raise ValueError(f"motions[{k}] runs at {m.fps:g} fps, motions[0] at {motions[0].fps:g} fps: resample first")
    w = SimilarityWeights() if weights is None else weights
    threshold = float(threshold)
    if not threshold > 0:
        raise ValueError(f"Expected `threshold` > 0, got {threshold}")
    if not (window >= 0 and min_gap >= 0):
        raise ValueError(f"Expected `window` >= 0 and `min_gap` >= 0 seconds, got {window} and {min_gap}")
    chunk = int(chunk)
    if chunk < 1:
        raise ValueError(f"Expected `chunk` >= 1, got {chunk}")
    fps = float(motions[0].fps)
    feats = np.concatenate([frame_features(m, w) for m in motions])
    offsets = np.concatenate([[0], np.cumsum([m.n_frames for m in motions])]).astype(np.int64)
    N = int(offsets[-1])
    clip_of = np.repeat(np.arange(len(motions)), [m.n_frames for m in motions])
    r = int(round(window * fps))
    gap = int(np.ceil(min_gap * fps))
    sq = np.einsum("ij,ij->i", feats, feats)
    found_i: list[NDArray[np.int64]] = []
    found_j: list[NDArray[np.int64]] = []
    found_d: list[Array] = []
    for r0 in range(0, N, chunk):
        r1 = min(N, r0 + chunk)
        a0, a1 = max(0, r0 - r), min(N, r1 + r)
        c0 = max(0, r0 - 2 * r)  # columns j >= i - r suffice (j > i is kept; the halo needs r more)
        D = sq[a0:a1, None] + sq[None, c0:] - 2.0 * (feats[a0:a1] @ feats[c0:].T)
        np.maximum(D, 0.0, out=D)
        # trivial pairs (same clip, closer than min_gap) are masked before the
        # local-minimum test: an idle stretch, whose D only grows with the lag,
        # then still yields transitions at the smallest allowed lag
        rows = np.arange(a0, a1)[:, None]
        cols = np.arange(c0, N)[None, :]
        near = (np.abs(cols - rows) < max(gap, 1)) & (clip_of[a0:a1, None] == clip_of[None, c0:])
        D[near] = np.inf
        if r > 0:
            M = minimum_filter(D, size=2 * r + 1, mode="nearest")
            local = D <= M
        else:
            local = np.ones(D.shape, bool)
        core = local[r0 - a0 : r1 - a0]
        Dc = D[r0 - a0 : r1 - a0]
        ii, jj = np.nonzero(core & (Dc < threshold))
        ii = ii + r0
        jj = jj + c0
        ok = jj > ii
        same = clip_of[ii] == clip_of[jj]
        ok &= ~same | (jj - ii >= max(gap, 1))
        found_i.append(ii[ok])
        found_j.append(jj[ok])
        found_d.append(Dc[ii[ok] - r0, jj[ok] - c0].astype(float))
    pairs = np.stack([np.concatenate(found_i), np.concatenate(found_j)], axis=1).astype(np.int64)
    costs = np.concatenate(found_d)
    pairs.flags.writeable = False
    costs.flags.writeable = False
    offsets.flags.writeable = False
    return MotionGraph(motions, offsets, pairs, costs, threshold, float(window), float(min_gap), w)
