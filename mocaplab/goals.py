"""The goal layer: put joints on targets with a smooth correction, for all three papers.

Every method in mocaplab that plants a foot or puts a hand somewhere ends
here: Kim et al. 2009's full-body refinement (s4.3, in
:mod:`mocaplab.editing.refinement`), Shin et al. 2003's re-planting of the
feet after each physical adjustment (:mod:`mocaplab.physics`), and the
constraint layer of Coleman et al. 2008's staggered poses
(:mod:`mocaplab.staggered.constraints`).  It is a ground-floor module: it
imports only the kinematic core (:mod:`~mocaplab.motion`,
:mod:`~mocaplab.ik`, :mod:`~mocaplab.displacement`,
:mod:`~mocaplab.contacts`), and no paper package.

1. **Goals.**  A :class:`Goal` asks a joint to be at ``targets[i]`` on frame
   ``i`` with weight ``weights[i]`` in [0, 1].  Weights are 1 inside a
   constraint interval and fall smoothly to 0 over a short window on each
   side (:func:`blend_weights`), so a constraint is switched on and off
   without a jump (Coleman et al. 2008: "a smoothly-attenuated constraint
   solution in a small window adjacent in time").  Foot plants become goals
   with :func:`foot_goals` (one plant position per contact interval), user
   constraints with :class:`EndEffector` and :func:`effector_goals`
   (targets in the world, on a joint: :class:`RelativeTo`, or in a moving
   object's frame: :class:`ObjectFrame`).
2. **IK layer.**  :func:`solve_goals` moves each goal joint to
   ``current + w (target - current)`` on every frame at once: damped least
   squares for goals with an explicit chain, analytic two-bone IK for limbs
   (the end joint keeps its global orientation), legs last, then each foot
   is turned about its ankle so the toe meets its own plant (where ankle
   and toe cannot both hold, the foot rolls about the stiller one).  When a
   leg cannot reach, the root is first lowered just enough, smoothly (as in
   Kovar et al. 2002's footskate cleanup).  ``return_fk=True`` also returns
   the new motion's forward kinematics, cheaply (physical touch-up carries
   them from pass to pass).
3. **Smoothing.**  :func:`enforce_goals` fits a hierarchical displacement
   map (:class:`~mocaplab.displacement.DisplacementMap`, Lee and Shin 1999)
   to the per-frame IK corrections, constrained frames weighted more,
   applies it, and runs the IK layer once more toward the per-frame
   solution so constraints hold exactly; that last correction is small.
   Where a plant starts or ends it changes velocity in one frame, so the
   legs' corrections are finally smoothed over a tenth of a second except
   on the frames a goal holds fully (``_smooth_kinks``): no knee pop at
   heel strike.

Conventions: frame intervals are half-open ``(start, stop)`` (as
:attr:`mocaplab.contacts.Contacts.intervals`); ``window`` arguments of
:func:`interval_weights` and :func:`blend_weights` are frames, as their
keyword ``window_frames`` says (their callers already work in frames);
every other duration here (``blend``, ``spacing``, ``drop_window``) is
seconds.

Examples
--------
>>> import mocaplab as ml
>>> walk = ml.cmu("16_15")[:120]
>>> goals = ml.goals.foot_goals(walk, ml.contacts.foot_contacts(walk))
>>> planted = ml.goals.enforce_goals(walk, goals)
>>> planted.n_frames, [g.kind for g in goals]
(120, ['foot', 'toe', 'foot', 'toe'])

Longer than 800 lines because it is one mechanism: the goal types, the weights, the foot plants and the solver's steps (root lowering, chains, limbs, feet, smoothing) share private helpers over the same per-frame arrays, and every paper calls it as one.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping, Sequence
from types import MappingProxyType
from typing import Any, Literal, overload

import numpy as np
from numpy.typing import NDArray
from scipy import sparse
from scipy.linalg import solveh_banded
from scipy.ndimage import minimum_filter1d
from scipy.sparse.linalg import spsolve

from . import kinematics, quat
from ._api import reject_keywords
from ._checks import integer, real
from .contacts import Contacts, estimate_floor, intervals_from_mask
from .displacement import DisplacementMap, blend_ramp, displace, displacement_between, rotation_displacement
from .ik import (
    aim_deltas,
    dls_ik,
    end_parent_rotations,
    hinge_axes,
    limb_joints,
    two_bone_deltas,
    two_bone_ik,
    two_bone_locals,
)
from .motion import Motion, Skeleton, _owned, readonly

__all__ = [
    "Goal",
    "EndEffector",
    "RelativeTo",
    "ObjectFrame",
    "interval_weights",
    "blend_weights",
    "plant_positions",
    "STILL_SPEED",
    "foot_goals",
    "effector_goals",
    "world_targets",
    "solve_goals",
    "enforce_goals",
]

Array = NDArray[np.float64]
JointRef = str | int


# ----------------------------------------------------------------- blending
def _check_intervals(intervals: Sequence[tuple[int, int]], n_frames: int) -> list[tuple[int, int]]:
    out = []
    for iv in intervals:
        try:
            a, b = (int(x) for x in iv)
        except (TypeError, ValueError):
            raise ValueError(f"Expected intervals as (start, stop) pairs of ints, got {iv!r}") from None
        if not 0 <= a < b <= n_frames:
            raise ValueError(f"Expected intervals with 0 <= start < stop <= {n_frames}, got ({a}, {b})")
        out.append((a, b))
    return out


#: The frame-count window's old keyword (every other window of mocaplab is in seconds).
_WINDOW_RENAMED = MappingProxyType({"window": "the window is a number of frames: write window_frames=..."})


def interval_weights(
    n_frames: int, intervals: Sequence[tuple[int, int]], *, window_frames: int | None = None, **removed: Any
) -> Array:
    """One blending bump per interval, shape (K, F).

    Row ``k`` is 1 on frames ``start_k .. stop_k - 1`` and ramps
    (:func:`~mocaplab.displacement.blend_ramp`) to 0 over ``window_frames``
    frames on each side: the ``window_frames`` frames before ``start`` and
    after ``stop - 1`` get weights strictly between 0 and 1, the frames
    beyond are 0.

    Parameters
    ----------
    n_frames : int
        Number of frames F.
    intervals : sequence of (int, int)
        Half-open ``(start, stop)`` frame intervals, ``0 <= start < stop <= F``.
    window_frames : int
        Ramp length on each side, frames (>= 0); required.
    **removed
        Old keywords (``window=``), answered with a ``TypeError`` that says
        what to write instead.

    Returns
    -------
    ndarray, shape (K, F)
        One row per interval; ``(0, F)`` for none.

    Raises
    ------
    TypeError
        Without ``window_frames``, or with an old keyword.
    ValueError
        For a negative or fractional window, or an interval outside the clip.

    Examples
    --------
    >>> interval_weights(6, [(2, 3)], window_frames=1).round(2).tolist()
    [[0.0, 0.5, 1.0, 0.5, 0.0, 0.0]]
    """
    reject_keywords("interval_weights", removed, _WINDOW_RENAMED, ("window_frames",))
    if window_frames is None:
        raise TypeError("interval_weights() needs `window_frames`: the blending window, a number of frames")
    window = window_frames
    if int(window) != window or window < 0:
        raise ValueError(f"Expected `window_frames` to be an integer >= 0 frames, got {window!r}")
    ivs = _check_intervals(intervals, n_frames)
    i = np.arange(n_frames, dtype=float)
    if not ivs:
        return np.zeros((0, n_frames))
    ab = np.asarray(ivs, dtype=float)
    a, b = ab[:, :1], ab[:, 1:]
    w = float(window) + 1.0
    return np.minimum(blend_ramp((i - (a - w)) / w), blend_ramp(((b - 1 + w) - i) / w))


def blend_weights(
    n_frames: int, intervals: Sequence[tuple[int, int]], *, window_frames: int | None = None, **removed: Any
) -> Array:
    """Constraint weight per frame in [0, 1], shape (F,).

    1 inside the half-open ``intervals``, ramping smoothly to 0 over
    ``window_frames`` frames on each side (see :func:`interval_weights`);
    overlapping ramps add up, clipped at 1.  (A window in frames, as its
    name says: every other window of mocaplab is in seconds.)

    Parameters
    ----------
    n_frames : int
        Number of frames F (>= 1).
    intervals : sequence of (int, int)
        Half-open ``(start, stop)`` frame intervals.
    window_frames : int
        Ramp length on each side, frames (>= 0); required.
    **removed
        Old keywords (``window=``), answered with a ``TypeError``.

    Returns
    -------
    ndarray, shape (F,)

    Raises
    ------
    TypeError
        Without ``window_frames``, or with an old keyword.
    ValueError
        For ``n_frames < 1``, a bad window or an interval outside the clip.

    Examples
    --------
    >>> blend_weights(8, [(3, 5)], window_frames=2).round(3).tolist()
    [0.0, 0.21, 0.79, 1.0, 1.0, 0.79, 0.21, 0.0]
    """
    reject_keywords("blend_weights", removed, _WINDOW_RENAMED, ("window_frames",))
    if window_frames is None:
        raise TypeError("blend_weights() needs `window_frames`: the blending window, a number of frames")
    if n_frames < 1:
        raise ValueError(f"Expected `n_frames` >= 1, got {n_frames}")
    return np.clip(interval_weights(n_frames, intervals, window_frames=window_frames).sum(axis=0), 0.0, 1.0)


# -------------------------------------------------------------------- goals
@dataclasses.dataclass(frozen=True, eq=False)
class Goal:
    """A per-frame position goal for one joint: the input of the IK layer.

    Parameters
    ----------
    joint : str or int
    targets : array_like, shape (F, 3)
        World target on every frame (only frames of positive weight matter).
    weights : array_like, shape (F,)
        In [0, 1]: the joint goes to ``current + w (target - current)``.
    kind : {"limb", "foot", "toe"}
        ``"limb"``: an end effector moved by two-bone IK on
        ``limb_joints(joint)`` (or by ``chain``); ``"foot"``: an ankle, like a
        limb but the root may be lowered so the leg reaches; ``"toe"``: a toe,
        reached by moving its foot (its parent, solved with the leg) and
        turning the foot about the ankle.
    chain : sequence of joints, optional
        Solve with damped least squares over these joints (``"limb"`` only).
    stiffness : array_like, shape (F,), optional
        Relative priority of an ankle and its toe where both are planted and
        cannot both be met exactly (default 1): the foot rolls about the
        stiffer one.

    Raises
    ------
    ValueError
        For targets, weights or stiffness of the wrong shape or out of range,
        an unknown ``kind``, or a ``chain`` on a goal that is not a limb.

    Examples
    --------
    A goal that fades in over two frames and then holds the ankle at the
    origin (:func:`solve_goals` and :func:`enforce_goals` meet it):

    >>> import numpy as np
    >>> goal = Goal("ankle", np.zeros((4, 3)), [0.0, 0.5, 1.0, 1.0])
    >>> goal.n_frames, goal.kind, goal.stiffness.tolist()
    (4, 'limb', [1.0, 1.0, 1.0, 1.0])
    """

    joint: JointRef
    targets: Array
    weights: Array
    kind: Literal["limb", "foot", "toe"] = "limb"
    chain: tuple[JointRef, ...] | None = None
    stiffness: Array | None = None

    def __post_init__(self) -> None:
        t = np.array(self.targets, dtype=float)
        w = np.array(self.weights, dtype=float)
        k = np.ones(len(w)) if self.stiffness is None else np.array(self.stiffness, dtype=float)
        if k.shape != w.shape or np.any(k <= 0) or not np.all(np.isfinite(k)):
            raise ValueError(f"Expected positive finite Goal `stiffness` of shape {w.shape}, got shape {k.shape}")
        object.__setattr__(self, "stiffness", readonly(k))
        if t.ndim != 2 or t.shape[1] != 3:
            raise ValueError(f"Expected Goal `targets` of shape (F, 3), got {t.shape}")
        if w.shape != (t.shape[0],):
            raise ValueError(f"Expected Goal `weights` of shape ({t.shape[0]},), got {w.shape}")
        if np.any((w < 0) | (w > 1)) or not np.all(np.isfinite(w)):
            raise ValueError("Expected Goal `weights` in [0, 1]")
        if not np.all(np.isfinite(t[w > 0])):
            raise ValueError("Expected finite Goal `targets` on frames of positive weight")
        if self.kind not in ("limb", "foot", "toe"):
            raise ValueError(f"Expected Goal `kind` 'limb', 'foot' or 'toe', got {self.kind!r}")
        if self.chain is not None and self.kind != "limb":
            raise ValueError("A Goal `chain` is allowed only with kind='limb'")
        object.__setattr__(self, "targets", readonly(t))
        object.__setattr__(self, "weights", readonly(w))
        if self.chain is not None:
            object.__setattr__(self, "chain", tuple(self.chain))

    @property
    def n_frames(self) -> int:
        return int(self.weights.shape[0])


def _window_targets(positions: Array, targets: Array, mask: Array, weights: Array) -> Array:
    """Targets valid on ``mask`` (constrained frames), extended over the blending windows.

    With ``b`` the nearest constrained frame and ``w`` the blending weight,
    the target on a window frame is
    ``(1 - w) (p(i) + T(b) - p(b)) + w T(i)``, so the joint goes to
    ``p(i) + w [(1 - w) (T(b) - p(b)) + w (T(i) - p(i))]``.  Far from the
    constraint (small ``w``) the joint keeps its own motion plus a fading
    copy of the correction at ``b`` (it is not dragged toward a point it has
    not reached yet, like a toe still in the air before it lands); next to
    the constraint (``w`` near 1) it follows the target ``T(i)`` itself, so
    its velocity is continuous where the constraint starts or ends.  Where
    ``T(i)`` is not finite outside ``mask``, ``T(b)`` is used.
    """
    idx = np.flatnonzero(mask)
    if idx.size == 0:
        raise ValueError("Expected at least one constrained frame")
    frames = np.arange(len(mask))
    pos = np.searchsorted(idx, frames)
    left = idx[np.clip(pos - 1, 0, idx.size - 1)]
    right = idx[np.clip(pos, 0, idx.size - 1)]
    nearest = np.where(np.abs(frames - left) <= np.abs(right - frames), left, right)
    held = targets[nearest]
    own = np.where(np.isfinite(targets), targets, held)
    carried = positions + (held - positions[nearest])
    w = weights[:, None]
    out = (1.0 - w) * carried + w * own
    out[mask] = targets[mask]
    return out


def _spans(
    intervals: Sequence[Sequence[tuple[int, int]] | NDArray[np.int64]], n: int, pad: int
) -> dict[str, NDArray[np.int64]]:
    """The frames of every interval of every column, padded by ``pad`` frames (clipped to [0, n)).

    Returns int arrays with one entry per visited frame, intervals in order:
    ``"interval"`` (index over all intervals), ``"column"``, ``"start"``,
    ``"stop"``, ``"frame"``; and ``"first"``, the position of each
    interval's first visited frame.
    """
    ab = np.array([iv for ivs in intervals for iv in ivs], dtype=np.int64).reshape(-1, 2)
    col = np.repeat(np.arange(len(intervals)), [len(ivs) for ivs in intervals])
    lo = np.maximum(ab[:, 0] - pad, 0)
    size = np.minimum(ab[:, 1] + pad, n) - lo
    first = np.cumsum(size) - size
    frames = np.arange(int(size.sum())) - np.repeat(first - lo, size)
    k = np.repeat(np.arange(len(ab)), size)
    return {"interval": k, "column": col[k], "start": ab[k, 0], "stop": ab[k, 1], "frame": frames, "first": first}


def _plant_goal_targets(
    positions: Array,
    plants: Sequence[Array],
    heights: Array | None,
    intervals: Sequence[Sequence[tuple[int, int]]],
    window: int,
    still: Sequence[NDArray[np.int64]] | None = None,
    rolling: tuple[Array, Array] | None = None,
) -> tuple[Array, Array]:
    """Targets and weights of several joints from one plant per contact interval.

    Parameters
    ----------
    positions : ndarray, shape (F, n, 3)
        The joints' current positions.
    plants : sequence of n ndarrays, shape (K_c, 3)
        One plant per interval of each joint.
    heights : ndarray, shape (F, n), optional
        When given, the height of interval ``k``'s target field ``T_k``
        follows it frame by frame (else the plant's height).
    intervals : sequence of n sequences of (start, stop)
    window : int
        Blending frames on each side of an interval.
    still : sequence of n ndarrays, shape (K_c, 2), optional
        The frames ``[s0, s1)`` of each interval where the plant holds
        (:func:`_still_spans`); by default the whole interval.
    rolling : (ndarray, ndarray), shapes (F, n, 3) and (F, n), optional
        Where the joints' rolling travel outside the still spans comes from:
        their positions in the motion before editing, and the heading the
        edit turned each joint by (radians about +Y); by default their own
        travel in ``positions``.

    Returns
    -------
    targets : ndarray, shape (F, n, 3)
    weights : ndarray, shape (F, n)

    Notes
    -----
    Each interval's bump ``b_k`` (:func:`interval_weights`) carries its own
    field: the plant inside the interval, and around it the joint's own
    position plus the correction it needs at the interval's nearest frame
    (so a landing foot is not pulled toward its plant before it gets there:
    the correction is ``b_k (T(b) - p(b))``, as smooth as the ramp); a
    joint's goal is the bump-weighted mean of its fields with weight
    ``min(1, sum_k b_k)``, so the blended goal ``cur + w (T - cur) = cur +
    sum_k b_k (T_k - cur)`` stays continuous even where the ramps of two
    intervals overlap.  Vectorised over all intervals of all joints: only
    the frames where a bump is positive (the interval and ``window`` frames
    on each side) are visited.  The plant holds on the interval's still
    span; on the rest of the interval (the foot rolling onto its heel
    after the strike and off its toe before lifting, both at full weight)
    and around it, the nearest constrained frame is the span's first or
    last frame, so the joint keeps its own rolling travel there.
    """
    n, n_cols = positions.shape[:2]
    targets = np.array(positions, copy=True)
    if not any(len(ivs) for ivs in intervals):
        return targets, np.zeros((n, n_cols))
    sp = _spans(intervals, n, window)
    frames, fa, fb, col = sp["frame"], sp["start"], sp["stop"], sp["column"]
    i = frames.astype(float)
    w1 = float(window) + 1.0
    # the same expression as interval_weights, on the visited frames only
    bump = np.minimum(blend_ramp((i - (fa - w1)) / w1), blend_ramp(((fb - 1 + w1) - i) / w1))
    nearest = np.clip(frames, fa, fb - 1)
    plant = np.concatenate([np.asarray(p, dtype=float).reshape(-1, 3) for p in plants])[sp["interval"]]
    own = plant.copy()
    held = plant.copy()
    if heights is not None:
        own[:, 1] = heights[frames, col]
        held[:, 1] = heights[nearest, col]
    # around the interval the joint keeps its own motion plus the correction it needs at the
    # interval's nearest frame, faded in by the bump: it is never pulled toward the plant before it
    # gets there (a foot in the air just before heel strike), so the correction is as smooth as the ramp
    field = positions[frames, col] + (held - positions[nearest, col])
    w = bump[:, None]
    inside = (frames >= fa) & (frames < fb)
    field[inside] = own[inside]
    if still is not None:
        # on the ground plane the plant holds on the still span [s0, s1) only.  From the interval's ends to the
        # span's the joint rolls (r = 1 at the ends, 0 on the span, the blend ramp between: no velocity jump
        # where the plant takes over): the plant plus the travel of the rolling source since the span's
        # nearest frame, turned by the source's heading change; around the interval, as above, the joint's own
        # motion plus the correction at the interval's nearest frame
        span = np.concatenate([np.asarray(v, dtype=np.int64).reshape(-1, 2) for v in still])[sp["interval"]]
        s0, s1 = span[:, 0], span[:, 1]
        src, turn = (positions, None) if rolling is None else rolling

        def rolled(g: NDArray[np.int64]) -> Array:
            near = np.clip(g, s0, s1 - 1)
            u = g.astype(float)
            r = np.maximum(
                blend_ramp((s0 - u) / np.maximum(s0 - fa, 1)), blend_ramp((u - (s1 - 1)) / np.maximum(fb - s1, 1))
            )
            d = src[g, col] - src[near, col]
            if turn is not None:
                d = quat.rotate(quat.from_yaw(turn[near, col]), d)
            return plant[:, [0, 2]] + r[:, None] * d[:, [0, 2]]

        xz = rolled(frames)
        xz[~inside] = positions[frames, col][~inside][:, [0, 2]] + (
            rolled(nearest) - positions[nearest, col][:, [0, 2]]
        )[~inside]
        field[:, 0], field[:, 2] = xz[:, 0], xz[:, 1]
    slot = frames * n_cols + col  # flat (frame, column) index
    total = np.bincount(slot, weights=bump, minlength=n * n_cols).reshape(n, n_cols)
    contrib = w * field
    acc = np.stack([np.bincount(slot, weights=contrib[:, c], minlength=n * n_cols) for c in range(3)], axis=-1)
    acc = acc.reshape(n, n_cols, 3)
    pos = total > 0
    targets[pos] = acc[pos] / total[pos][:, None]
    return targets, np.clip(total, 0.0, 1.0)


def plant_positions(
    motion: Motion,
    contacts: Contacts,
    joint: str,
    *,
    reference: Motion | None = None,
) -> Array:
    """One plant position per contact interval of ``joint``, shape (K, 3).

    The ground-plane position ``(x, z)`` is the mean of the joint's position
    over the interval's still span in ``motion`` (where the edited foot is),
    the height its mean in ``reference`` when given (the foot's contact
    height before editing), else in ``motion``.  The still span runs from
    the first to the last frame of the interval where the joint moves slower
    than :data:`STILL_SPEED` (speed in ``reference``, else ``motion``): the
    detected intervals include the foot rolling onto its heel and off its
    toe, and the plant belongs where the foot rests.  Both means weight each
    frame by ``1 / (speed + 0.1 m/s)``.

    Parameters
    ----------
    motion : Motion
        The (edited) motion.
    contacts : Contacts
        Contact intervals, over the motion's frames.
    joint : str
        A joint of ``contacts``.
    reference : Motion, optional
        The motion before editing, same frames (heights and speeds).

    Returns
    -------
    ndarray, shape (K, 3)
        World positions, metres, one per contact interval of ``joint``.

    Examples
    --------
    >>> import mocaplab as ml
    >>> walk = ml.cmu("16_15")
    >>> plants = plant_positions(walk, ml.contacts.foot_contacts(walk), "LeftFoot")
    >>> plants.shape, plants[0].round(2).tolist()
    ((4, 3), [0.09, 0.09, -1.21])
    """
    j = motion.skeleton.index(joint)
    ref = reference if reference is not None else motion
    pos = motion.global_positions()[:, j, None]
    speed = _speed(ref, j)[:, None]
    return _plants(pos, ref.global_positions()[:, j, 1, None], speed, _still_spans(speed, [contacts.intervals(joint)]))[0]


def _speed(motion: Motion, j: int) -> Array:
    """World speed of one joint, m/s, shape (F,) (cheaper than all joints)."""
    return np.linalg.norm(kinematics.velocities(motion.global_positions()[:, j], motion.fps), axis=-1)


#: A planted joint holds its plant on the frames of its contact interval from the first to the last where it
#: moves slower than this, m/s (:func:`_still_spans`; its slowest frame when it never does); before and after
#: it rolls as captured.  A captured foot is in contact from heel strike to toe-off, but it rolls onto its heel
#: first and off its toe last: the ankle travels 58-77 mm over CMU 16_15's 0.46-0.64 s intervals, at 0.3-0.6
#: m/s at their ends.  Held at one spot over the whole interval, the ankle needed up to 54 mm of correction
#: faded in just before heel strike with the knee near straight (16_15 refined: left knee 110 -> 358 rad/s^2).
#: Rolling, the correction at heel strike is 13-36 mm (mean 26 against 45) and the knees stay within the
#: quality limits.  A rule that skips slow runs shorter than 40 ms (a dip of speed while the foot still
#: rolls) brought it to 13-23 mm but pushed the touched-up salsa's feet under the floor (2.4x the input's).  0.25 and 0.35 m/s also clear 16_15 but leave a knee pop on a 30 fps squeeze or a toe
#: slide on an exporter's walk (tests/test_quality_pipeline.py).
STILL_SPEED = 0.3


def _still_spans(speed: Array, ivs: Sequence[Sequence[tuple[int, int]]]) -> list[NDArray[np.int64]]:
    """Per joint, the still span ``[s0, s1)`` of each of its intervals, shape (K_c, 2).

    ``speed`` (F, n) in m/s.  The span runs from the interval's first to its
    last frame slower than :data:`STILL_SPEED` (or than the interval's
    slowest frame, when none is).  A brief dip of speed while the foot still
    rolls starts the plant early (CMU 16_15's right ankle: 0.22 m/s between
    0.37 and 0.64 just after heel strike); the run around the slowest frame
    alone avoids that, but left more of an edit's drift in the roll (the
    pipeline's bent HumanIK walk skates, its squeezed 02_01 pops).
    """
    out = [np.asarray(v, dtype=np.int64).reshape(-1, 2) for v in ivs]
    if not any(len(v) for v in out):
        return out
    sp = _spans(ivs, speed.shape[0], 0)
    frames, col, first = sp["frame"], sp["column"], sp["first"]
    v = speed[frames, col]
    slowest = np.minimum.reduceat(v, first)
    still = v <= np.maximum(STILL_SPEED, slowest)[sp["interval"]]
    big = np.iinfo(np.int64).max
    s0 = np.minimum.reduceat(np.where(still, frames, big), first)
    s1 = np.maximum.reduceat(np.where(still, frames, -1), first) + 1
    spans = np.stack([s0, s1], axis=-1)
    edges = np.cumsum([0] + [len(v) for v in out])
    return [spans[edges[c] : edges[c + 1]] for c in range(len(out))]


def _plants(
    pos: Array, hgt: Array, speed: Array, ivs: Sequence[Sequence[tuple[int, int]] | NDArray[np.int64]]
) -> list[Array]:
    """Plants of several joints: ``pos`` (F, n, 3), ``hgt`` and ``speed`` (F, n), the spans to average per joint."""
    out = [np.zeros((len(v), 3)) for v in ivs]
    if not any(len(v) for v in ivs):
        return out
    sp = _spans(ivs, pos.shape[0], 0)
    frames, col, first = sp["frame"], sp["column"], sp["first"]
    # where the joint rests counts most: weight frames by slowness
    slow = 1.0 / (speed[frames, col] + 0.1)
    total = np.add.reduceat(slow, first)
    plants = np.add.reduceat(slow[:, None] * pos[frames, col], first, axis=0) / total[:, None]
    plants[:, 1] = np.add.reduceat(slow * hgt[frames, col], first) / total
    edges = np.cumsum([0] + [len(v) for v in ivs])
    return [plants[edges[c] : edges[c + 1]] for c in range(len(ivs))]


def _frames(seconds: float, fps: float, what: str) -> int:
    if not (np.isfinite(seconds) and seconds >= 0):
        raise ValueError(f"Expected `{what}` >= 0 seconds, got {seconds!r}")
    return int(round(seconds * fps))


def _is_toe(skeleton: Skeleton, name: str, names: Sequence[str]) -> bool:
    j = skeleton.index(name)
    p = int(skeleton.parents[j])
    return p >= 0 and skeleton.names[p] in names


def foot_goals(
    motion: Motion,
    contacts: Contacts,
    *,
    reference: Motion | None = None,
    blend: float = 0.1,
    follow_height: bool = True,
) -> list[Goal]:
    """Goals that keep each planted joint on one spot per contact interval.

    Parameters
    ----------
    motion : Motion
        The edited motion (plants are placed where its feet are).
    contacts : Contacts
        Contact intervals, usually detected on the motion before editing.
    reference : Motion, optional
        The motion before editing (heights and speeds come from it).
    blend : float
        Blending window on each side of an interval, seconds.
    follow_height : bool
        ``True`` (default): a planted joint is pinned on the ground plane at
        its plant ``(x, z)`` (:func:`plant_positions`) while its height
        follows ``reference`` frame by frame, so the heel still rises and the
        toe still lands as captured.  ``False``: pinned in 3D at the plant.

    Returns
    -------
    list of Goal
        One per contact joint.  A joint whose parent is also a contact
        joint is a ``"toe"`` (it follows its foot); the others are
        ``"foot"`` goals, solved by two-bone IK on the limb they end (so
        give the ankle with the toe: a toe alone would be treated as the
        end of a leg ``shin -> ankle -> toe``).  Stiffness is
        ``1 / (speed + 0.05 m/s)`` (speed in ``reference``): where ankle and
        toe are both planted but the captured heel rises or the toe lands,
        the foot rolls about whichever joint was stiller.  On the ground
        plane a joint's plant holds on its interval's still span (slower
        than :data:`STILL_SPEED`); between the interval's ends and that
        span, where the foot rolls onto its heel or off its toe, the goal
        rolls too: the plant plus the joint's travel in ``reference`` (its
        own without one), turned by the heading the edit gave the joint.

    Notes
    -----
    Where a toe interval overlaps an interval of its ankle (flat foot), the
    toe plant is moved along the ankle-to-toe direction so that its ground
    distance from the ankle plant fits the foot's length at the two joints'
    mean heights, and both can hold at once.

    Raises
    ------
    TypeError
        If ``contacts`` is not a :class:`~mocaplab.contacts.Contacts`.
    ValueError
        If ``contacts`` or ``reference`` covers other frames than ``motion``.

    Examples
    --------
    >>> import mocaplab as ml
    >>> walk = ml.cmu("16_15")
    >>> goals = foot_goals(walk, ml.contacts.foot_contacts(walk))
    >>> [(g.joint, g.kind) for g in goals]
    [('LeftFoot', 'foot'), ('LeftToeBase', 'toe'), ('RightFoot', 'foot'), ('RightToeBase', 'toe')]
    """
    if not isinstance(contacts, Contacts):
        raise TypeError(f"Expected `contacts` to be a Contacts, got {type(contacts).__name__}")
    if contacts.n_frames != motion.n_frames:
        raise ValueError(
            f"Expected contacts over {motion.n_frames} frames (the motion's), got {contacts.n_frames}; "
            "contacts must come from a motion with the same frames"
        )
    if reference is not None and reference.n_frames != motion.n_frames:
        raise ValueError(f"Expected `reference` of {motion.n_frames} frames, got {reference.n_frames}")
    sk = motion.skeleton
    ref = reference if reference is not None else motion
    window = _frames(blend, motion.fps, "blend")
    names = tuple(contacts.joints)
    cols = [sk.index(name) for name in names]
    ref_pos = ref.global_positions()
    pos = motion.global_positions()[:, cols]
    heights = ref_pos[:, cols, 1]
    if reference is not None and (floor := estimate_floor(ref, contacts)) is not None:
        # on an inclined floor a foot the edit moved stands where the floor is higher or lower
        heights = heights + (pos[..., [0, 2]] - ref_pos[:, cols][..., [0, 2]]) @ floor.slope
    speeds = np.linalg.norm(kinematics.velocities(ref_pos[:, cols], ref.fps), axis=-1)  # (F, n)
    ivs = [contacts.intervals(name) for name in names]
    still = _still_spans(speeds, ivs)
    plants = _plants(pos, heights, speeds, still)
    kinds = ["toe" if _is_toe(sk, name, names) else "foot" for name in names]
    for k, name in enumerate(names):
        if kinds[k] == "toe":
            parent = names.index(sk.names[int(sk.parents[cols[k]])])
            length = float(np.linalg.norm(_bone(motion, name)))
            plants[k] = _consistent_toe(plants[k], ivs[k], plants[parent], ivs[parent], length)
    rolling = None
    if reference is not None:
        # the rolling travel as captured, turned by the heading the edit gave each joint
        change = quat.mul(motion.global_rotations()[:, cols], quat.inv(ref.global_rotations()[:, cols]))
        turn = 2.0 * np.arctan2(change[..., 1], change[..., 3])  # its twist about +Y
        rolling = (ref_pos[:, cols], turn)
    targets, weights = _plant_goal_targets(
        pos, plants, heights if follow_height else None, ivs, window, still, rolling
    )
    stiffness = 1.0 / (speeds + 0.05)
    return [
        Goal(name, targets[:, k], weights[:, k], kind=kinds[k], stiffness=stiffness[:, k])  # type: ignore[arg-type]
        for k, name in enumerate(names)
    ]


def _bone(motion: Motion, name: str) -> Array:
    j = motion.skeleton.index(name)
    if motion.translations is not None:
        return np.asarray(motion.translations[:, j].mean(axis=0))
    return np.asarray(motion.skeleton.offsets[j])


def _consistent_toe(
    toe: Array, toe_ivs: list[tuple[int, int]], ankle: Array, ankle_ivs: list[tuple[int, int]], length: float
) -> Array:
    out = np.array(toe, copy=True)
    if not toe_ivs or not ankle_ivs:
        return out
    t = np.asarray(toe_ivs, dtype=np.int64).reshape(-1, 2)
    an = np.asarray(ankle_ivs, dtype=np.int64).reshape(-1, 2)
    # frames shared by each toe interval (rows) and ankle interval (columns)
    overlap = np.minimum(t[:, 1, None], an[None, :, 1]) - np.maximum(t[:, 0, None], an[None, :, 0])
    m = np.argmax(overlap, axis=1)  # the first of the largest overlaps
    d = out[:, [0, 2]] - ankle[m][:, [0, 2]]
    n = np.linalg.norm(d, axis=-1)
    ground = np.sqrt(np.maximum(length**2 - (out[:, 1] - ankle[m, 1]) ** 2, 0.0))
    move = (overlap[np.arange(len(t)), m] > 0) & (n > 1e-9)
    moved = ankle[m][:, [0, 2]] + d * (ground / np.where(move, n, 1.0))[:, None]
    out[move, 0] = moved[move, 0]
    out[move, 2] = moved[move, 1]
    return out


# ----------------------------------------------------------------- IK layer
def _resolve_goals(skeleton: Skeleton, goals: Sequence[Goal], n_frames: int) -> tuple[list, list, list, dict]:
    dls, limbs, feet, toes = [], [], [], {}
    for g in goals:
        if not isinstance(g, Goal):
            raise TypeError(f"Expected Goal objects in `goals`, got {type(g).__name__}")
        if g.n_frames != n_frames:
            raise ValueError(f"Expected goals over {n_frames} frames, got one over {g.n_frames}")
        j = skeleton.index(g.joint, arg="Goal.joint")
        if g.kind == "toe":
            p = int(skeleton.parents[j])
            if p < 0 or p in toes:
                raise ValueError(f"Toe goal on {skeleton.names[j]!r} needs a parent foot with no other toe goal")
            toes[p] = (j, g)
        elif g.chain is not None:
            dls.append((j, g))
        elif g.kind == "foot":
            feet.append((j, g))
        else:
            limbs.append((j, g))
    ends = [j for j, _ in dls + limbs + feet]
    if len(set(ends)) != len(ends):
        raise ValueError("Expected at most one goal per joint")
    return dls, limbs, feet, toes


def _fk(rot: Array, root: Array, motion: Motion) -> tuple[Array, Array]:
    return kinematics.fk(rot, root, motion.skeleton.offsets, motion.skeleton.parents, translations=motion.translations)


def _refresh(rot: Array, fk: tuple[Array, Array], motion: Motion, changed: Sequence[int]) -> tuple[Array, Array]:
    """Forward kinematics again only below the ``changed`` joints (:func:`mocaplab.kinematics.fk_below`)."""
    sk = motion.skeleton
    return kinematics.fk_below(rot, fk, sk.offsets, sk.parents, changed, translations=motion.translations)


def _blend(cur: Array, goal: Goal) -> Array:
    return cur + goal.weights[:, None] * (goal.targets - cur)


# Stiffness of a planted joint as its weight goes to 1 is capped at 1 / _SOFT,
# so the ankle/toe share changes smoothly when one of them is released.
_SOFT = 0.02


def _stiffness(goal: Goal) -> Array:
    return np.ones(goal.n_frames) if goal.stiffness is None else goal.stiffness


def _foot_targets(
    gpos: Array, ankle: int, g_ankle: Goal | None, toe: tuple[int, Goal] | None, fps: float, hip: int
) -> Array:
    """Ankle positions that plant the ankle and/or the toe (see solve_goals), ``hip`` the leg's upper joint."""
    a_cur = gpos[:, ankle]
    if g_ankle is None:
        wa = np.zeros(len(a_cur))
        target = a_cur
    else:
        wa = g_ankle.weights
        target = _blend(a_cur, g_ankle)
    if toe is None:
        return target
    jt, gt = toe
    t_cur = gpos[:, jt]
    wt = gt.weights
    # where the ankle is free, carry the foot rigidly toward the toe plant, by the toe's correction smoothed
    # over a few frames: a captured toe joint can jitter by centimetres from frame to frame about a still
    # ankle (CMU 05_02: 40 mm), and carried as it is that jitter moved the ankle, the knee and the hip with it
    # (the slide below puts the ankle at the foot's length from the toe goal whatever the carry)
    carry = _whittaker(gt.targets - t_cur, np.ones(len(t_cur)), fps * _CARRY_SECONDS)
    target = target + ((1.0 - wa) * wt)[:, None] * carry
    # then slide the ankle until the foot's length fits, shared by stiffness
    # k w / (1 - w): (nearly) all on the ankle when only the toe is planted
    # (wt = 1), none when only the ankle is, by the goals' stiffness
    # (stillness) when both are
    toe_goal = _blend(t_cur, gt)
    length = np.linalg.norm(t_cur - a_cur, axis=-1)
    d = toe_goal - target
    dist = np.linalg.norm(d, axis=-1)
    ka = wa * (1.0 if g_ankle is None else _stiffness(g_ankle)) / (1.0 - wa + _SOFT)
    kt = wt * _stiffness(gt) / (1.0 - wt + _SOFT)
    den = ka + kt
    share = np.where(den > 1e-12, kt / np.maximum(den, 1e-12), 0.5)
    # along the ankle -> toe-goal line ...
    along_line = target + ((dist - length) * share / np.maximum(dist, 1e-12))[:, None] * d
    # ... or, better, across the leg (perpendicular to the hip -> ankle axis), where the slide changes the
    # leg's reach least: a near-straight knee bends fast for a small change of reach, and the fit takes up
    # whatever the toe goal's height does (it follows the captured toe's, jitter and all).  The line across
    # the leg meets the sphere of the foot's length about the toe goal where the foot is not along the leg
    # (the slide along the foot's line takes over, smoothly, as the foot turns toward the leg's axis)
    axis = target - gpos[:, hip]
    axis /= np.maximum(np.linalg.norm(axis, axis=-1), 1e-12)[:, None]
    across = d - np.sum(d * axis, axis=-1)[:, None] * axis
    across /= np.maximum(np.linalg.norm(across, axis=-1), 1e-12)[:, None]
    b = np.sum(across * d, axis=-1)
    disc = b**2 - dist**2 + length**2
    step = b - np.sqrt(np.maximum(disc, 0.0))  # the nearer of the line's two points on the sphere
    across_leg = target + (share * step)[:, None] * across
    f = blend_ramp((disc / np.maximum(length**2, 1e-12) - _ACROSS_FADE[0]) / (_ACROSS_FADE[1] - _ACROSS_FADE[0]))
    return f[:, None] * across_leg + (1.0 - f)[:, None] * along_line


# How well the line across the leg must meet the foot's sphere (its discriminant over the foot's length
# squared) for the ankle's slide to take it (_foot_targets): about where the foot is more than 8 to 18
# degrees from the leg's axis.
_ACROSS_FADE = (0.02, 0.1)
# The time scale over which a free ankle's carry toward its toe plant is smoothed, seconds (_foot_targets).
_CARRY_SECONDS = 0.05


def _whittaker(values: Array, weights: Array, frames: float, pinned: NDArray[np.bool_] | None = None) -> Array:
    """``values`` (F, k) refitted by a weighted second-difference (Whittaker) smoother, shape (F, k).

    Minimises ``sum_i W_i |x_i - v_i|^2 + lam sum_i |x_{i-1} - 2 x_i + x_{i+1}|^2`` with
    ``lam = frames^4 / 16``: with ``W = 1`` a smoother over about ``frames`` frames (it halves a
    sine of period ``pi * frames`` frames), much less where ``W`` is large.  One banded solve.
    Frames marked ``pinned`` (F,) keep their values exactly (the others are solved with them fixed).
    """
    n = len(values)
    if n < 4 or frames <= 0.0:
        return np.array(values, copy=True)
    lam = frames**4 / 16.0
    if pinned is not None and pinned.any():
        # the same normal equations, the pinned unknowns moved to the right-hand side
        free = ~pinned
        out = np.array(values, copy=True)
        if free.any():
            d2 = sparse.diags([1.0, -2.0, 1.0], [0, 1, 2], shape=(n - 2, n))
            a = (sparse.diags(weights) + lam * (d2.T @ d2)).tocsr()
            rhs = weights[free, None] * values[free] - a[free][:, pinned] @ values[pinned]
            out[free] = np.asarray(spsolve(a[free][:, free].tocsc(), rhs)).reshape(rhs.shape)
        return out
    # lam D2^T D2 in banded upper form (second differences over frames)
    ab = np.zeros((3, n))
    ab[0, 2:] = lam
    ab[1, 1:] = -4.0 * lam
    ab[1, 1] = ab[1, -1] = -2.0 * lam
    ab[2] = 6.0 * lam
    ab[2, [0, -1]] = lam
    ab[2, [1, -2]] = 5.0 * lam
    ab[2] += weights
    return solveh_banded(ab, weights[:, None] * values, check_finite=False)


_IDENTITY = np.array([0.0, 0.0, 0.0, 1.0])


def _leg_weight(g_ankle: Goal | None, toe: tuple[int, Goal] | None, n: int) -> Array:
    """How firmly a leg is held on each frame, (F,): the larger of its ankle's and its toe's goal weights."""
    w = np.zeros(n) if g_ankle is None else np.asarray(g_ankle.weights, dtype=float)
    return w if toe is None else np.maximum(w, toe[1].weights)


MAX_LEVELS = 16
"""Most levels of a displacement map (:func:`enforce_goals`, ``levels``).

Each level halves the knot spacing down to one frame; past that a level
only refits the same residual, so more levels buy nothing but work."""

MAX_WINDOW = 10.0
"""Longest blending window over frames, seconds: the root lowering's ``drop_window`` (:func:`solve_goals`)
and the touch-up's ``flight_window`` (:func:`mocaplab.physics.touch_up`).

The defaults are 0.1 to 0.5 s; a window of several seconds already spreads
one change over a whole walk cycle, and a bound keeps ``seconds * fps``
a frame count (1e308 s is infinitely many frames)."""


def map_options(spacing: Any, levels: Any) -> tuple[float, int]:
    """The displacement map's ``spacing`` (seconds, > 0) and ``levels`` (1 to :data:`MAX_LEVELS`), checked.

    Raises TypeError or ValueError naming the option; the one check of these
    options for :func:`enforce_goals` and Kim's refine.

    Examples
    --------
    >>> map_options(0.25, 3)
    (0.25, 3)
    """
    return (
        real(spacing, "spacing", low=0.0, low_open=True, unit="seconds"),
        integer(levels, "levels", low=1, high=MAX_LEVELS, why="each level halves the knot spacing"),
    )


def _lower_envelope(need: Array, half: int) -> Array:
    """A smooth curve below ``need`` (F,): erosion then a Hann average.

    Every value of the minimum filter over ``[k - half, k + half]`` is at most
    ``need(i)`` for ``|k - i| <= half``, so their weighted average over the
    same radius is too.
    """
    if half < 1 or not np.any(need < 0):
        return need
    eroded = minimum_filter1d(need, size=2 * half + 1, mode="nearest")
    kernel = np.hanning(2 * half + 3)[1:-1]
    kernel /= kernel.sum()
    padded = np.pad(eroded, half, mode="edge")
    return np.minimum(np.convolve(padded, kernel, mode="valid"), 0.0)


@overload
def solve_goals(
    motion: Motion,
    goals: Sequence[Goal],
    *,
    adjust_root: bool = ...,
    reach: float = ...,
    max_drop: float = ...,
    drop_window: float = ...,
    dls_options: dict[str, Any] | None = ...,
    fk: tuple[Array, Array] | None = ...,
    hinges: Mapping[JointRef, Any] | None = ...,
    max_reach: float = ...,
    return_fk: Literal[False] = ...,
) -> Motion: ...


@overload
def solve_goals(
    motion: Motion,
    goals: Sequence[Goal],
    *,
    adjust_root: bool = ...,
    reach: float = ...,
    max_drop: float = ...,
    drop_window: float = ...,
    dls_options: dict[str, Any] | None = ...,
    fk: tuple[Array, Array] | None = ...,
    hinges: Mapping[JointRef, Any] | None = ...,
    max_reach: float = ...,
    return_fk: Literal[True],
) -> tuple[Motion, tuple[Array, Array]]: ...


def solve_goals(
    motion: Motion,
    goals: Sequence[Goal],
    *,
    adjust_root: bool = True,
    reach: float = 0.99,
    max_drop: float = 0.15,
    drop_window: float = 0.15,
    dls_options: dict[str, Any] | None = None,
    fk: tuple[Array, Array] | None = None,
    hinges: Mapping[JointRef, Any] | None = None,
    max_reach: float = 1.0,
    return_fk: bool = False,
) -> Motion | tuple[Motion, tuple[Array, Array]]:
    """The IK layer: meet every goal on every frame (no temporal smoothing).

    Parameters
    ----------
    motion : Motion
    goals : sequence of Goal
    adjust_root : bool
        Lower the root where a ``"foot"`` goal is beyond ``reach`` times the
        leg's length (at most ``max_drop`` metres).
    reach : float
        Fraction of the leg's full length the root adjustment aims for: a
        little short of straight, where the knee angle is very sensitive to
        the ankle's position.  A leg already straighter than that may stay
        as straight as it is, up to ``max_reach``, less by however far its
        target lies beyond its current reach.  In (0, 1].
    max_drop : float
        Largest root lowering, metres (>= 0).
    drop_window : float
        Seconds, from 0 to :data:`MAX_WINDOW`.  The lowering is a smooth lower envelope of the per-frame need over
        this many seconds on each side (never less than the need), because
        near full extension a small jump of the hip is a large jump of the
        knee angle.
    dls_options : dict, optional
        Passed to :func:`~mocaplab.ik.dls_ik` for goals with a chain.
    fk : (global_rotations, global_positions), optional
        The motion's forward kinematics when already at hand (saves a pass;
        physical touch-up carries them along).
    hinges : mapping, optional
        For two-bone goals (``"foot"`` and ``"limb"`` without a chain), keyed
        by the goal's joint: the hinge of the limb's middle joint in that
        joint's local frame, shape (3,) (see :func:`~mocaplab.ik.hinge_axes`),
        for instance measured on the motion before an edit so a knee keeps
        the input's bending direction.  Default: estimated from ``motion``
        itself.
    max_reach : float
        Fraction of a leg's full length beyond which the root is lowered
        even for a leg that is already that straight (1: never).  Near
        full extension the knee angle goes as the square root of the
        distance left, so a target that brushes past straight makes the
        knee dip and come back in a few frames; a cap below 1 lowers the
        root (smoothly, by ``drop_window``) instead.  In (0, 1].
    return_fk : bool
        Also return the new motion's forward kinematics
        ``(global_rotations (F, J, 4), global_positions (F, J, 3))``.  They
        come cheaply: joints the IK layer did not turn keep their
        transforms (shifted by the root lowering, if any; a static
        reference root above the pelvis stays where it is, as in the
        motion), the legs' subtrees are recomputed once.

    Returns
    -------
    Motion, or (Motion, (global_rotations, global_positions))
        A new motion (``motion`` is not modified).

    Notes
    -----
    Order: root lowering; chain goals (damped least squares, each on the
    frames where its weight is positive); limb goals (two-bone, end joint
    keeps its global orientation); feet.  A foot's ankle goes to
    ``A + wa (Pa - A) + (1 - wa) wt (Pt - T)`` (ankle plant ``Pa``, toe plant
    ``Pt``, current ankle ``A`` and toe ``T``), then slid along the line to
    the blended toe goal until the foot's length fits, by the share
    ``kt / (ka + kt)`` with ``k = stiffness * w / (1 - w + 0.02)``; then the
    foot turns about
    the ankle by ``wt`` of the shortest arc pointing the toe at ``Pt``.  With
    both weights 1 the ankle and toe plants hold exactly; with both 0 the
    pose is unchanged.

    Examples
    --------
    >>> import numpy as np
    >>> from mocaplab.motion import Motion, Skeleton
    >>> sk = Skeleton(["hip", "knee", "ankle"], [-1, 0, 1], [[0, 1, 0], [0, -0.45, 0], [0, -0.45, 0]])
    >>> m = Motion(sk, np.tile([0.0, 0, 0, 1], (3, 3, 1)), np.zeros((3, 3)), fps=30)
    >>> goal = Goal("ankle", np.tile([0.2, 0.3, 0.0], (3, 1)), np.ones(3), kind="limb")
    >>> out = solve_goals(m, [goal], adjust_root=False)
    >>> np.round(out.global_positions()[0, 2], 3).tolist()
    [0.2, 0.3, 0.0]
    """
    reach = real(reach, "reach", low=0.0, high=1.0, low_open=True, unit="of the leg's length")
    max_reach = real(max_reach, "max_reach", low=0.0, high=1.0, low_open=True, unit="of the leg's length")
    max_drop = real(max_drop, "max_drop", low=0.0, unit="metres")
    drop_window = real(drop_window, "drop_window", low=0.0, high=MAX_WINDOW, unit="seconds")
    out = _solve_goals(
        motion, goals, adjust_root=adjust_root, reach=reach, max_drop=max_drop, drop_window=drop_window,
        dls_options=dls_options, fk=fk, hinges=hinges, max_reach=max_reach,
    )
    return out if return_fk else out[0]


def _keep_free_feet(
    targets: Sequence[Array], held: Array, ankles: Sequence[int], drop: Array
) -> tuple[list[Array], Array]:
    """Ankle targets and leg weights with the free part of each foot kept up when the root is lowered.

    A leg no goal holds (a swing leg) would go down with a lowered root, a
    swinging foot a few centimetres above the floor then passing through it
    (30 mm on a bent CMU walk).  On the frames where the root is lowered,
    the part of each ankle target that no goal holds (``1 - w`` of it: all
    of a swing foot, the ramp before a landing) is lifted back by the drop,
    and the leg solved with full weight there: the knee bends by what the
    drop needs, as smooth as the drop.  (Lifting only as far as the foot
    would sink below its planted height left 15 mm of the 30.)
    """
    lowered = drop < 0.0
    if not lowered.any():
        return list(targets), held
    out = [np.array(t, copy=True) for t in targets]
    held = np.array(held, copy=True)
    for k in range(len(ankles)):
        free = np.where(lowered, 1.0 - np.clip(held[:, k], 0.0, 1.0), 0.0)
        out[k][:, 1] -= free * drop  # back up by the part of the drop no goal asks for
        held[:, k] = np.where(lowered, 1.0, held[:, k])
    return out, held


def _solve_goals(
    motion: Motion,
    goals: Sequence[Goal],
    *,
    adjust_root: bool,
    reach: float,
    max_drop: float,
    drop_window: float,
    dls_options: dict[str, Any] | None,
    fk: tuple[Array, Array] | None,
    hinges: Mapping[JointRef, Any] | None = None,
    max_reach: float = 1.0,
) -> tuple[Motion, tuple[Array, Array]]:
    """:func:`solve_goals` with its forward kinematics (see ``return_fk`` there)."""
    if not isinstance(motion, Motion):
        raise TypeError(f"Expected `motion` to be a Motion, got {type(motion).__name__}")
    sk = motion.skeleton
    n = motion.n_frames
    dls, limbs, feet, toes = _resolve_goals(sk, goals, n)
    given = {} if hinges is None else {sk.index(j, arg="hinges"): np.asarray(h, dtype=float) for j, h in hinges.items()}
    for j, h in given.items():
        if h.shape != (3,) or not np.all(np.isfinite(h)):
            raise ValueError(f"Expected a finite hinge axis of shape (3,) for {sk.names[j]!r}, got shape {h.shape}")
    foot_of = {j: g for j, g in feet}
    foot_joints = sorted(set(foot_of) | set(toes))
    rot = np.array(motion.rotations, copy=True)
    root = np.array(motion.root_positions, copy=True)
    grot, gpos = (motion.global_rotations(), motion.global_positions()) if fk is None else fk
    root_moved = False
    drop = np.zeros(n)
    if adjust_root and foot_joints:
        for ankle in foot_joints:
            u, m, e = limb_joints(sk, ankle)
            target = _foot_targets(gpos, ankle, foot_of.get(ankle), toes.get(ankle), motion.fps, u)
            full = np.linalg.norm(gpos[:, m] - gpos[:, u], axis=-1) + np.linalg.norm(gpos[:, e] - gpos[:, m], axis=-1)
            # a leg may stay as straight as it already is (up to `max_reach`), else up to `reach`; less by however
            # far its target lies beyond that, so a target past a straight leg's reach does not press it to
            # exactly its current straightness (there a near-straight knee turns the peak of the leg's reach into
            # a kink: pymo's walk AV_8Walk under a staggered succession, 686 -> 453 rad/s^2, input 344)
            current = np.minimum(np.linalg.norm(gpos[:, e] - gpos[:, u], axis=-1), max_reach * full)
            r = target - gpos[:, u]
            current = current - np.maximum(np.linalg.norm(r, axis=-1) - current, 0.0)
            allowed = np.maximum(reach * full, current)
            s2 = allowed**2 - r[:, 0] ** 2 - r[:, 2] ** 2
            need = np.where(s2 > 0, r[:, 1] + np.sqrt(np.maximum(s2, 0.0)), r[:, 1])
            drop = np.minimum(drop, need)
        drop = np.where(drop < -1e-9, np.maximum(drop, -max_drop), 0.0)
        drop = _lower_envelope(drop, _frames(drop_window, motion.fps, "drop_window"))
        if np.any(drop < 0):
            root_moved = True
            root[:, 1] += drop
            gpos = gpos + np.stack([np.zeros(n), drop, np.zeros(n)], axis=-1)[:, None, :]
    for j, g in dls:
        active = np.flatnonzero(g.weights > 0)
        if active.size == 0:
            continue
        cur = gpos[active, j]
        tgt = cur + g.weights[active, None] * (g.targets[active] - cur)
        rot[active] = dls_ik(
            rot[active], root[active], sk, g.chain, j, tgt,
            translations=None if motion.translations is None else motion.translations[active],
            **(dls_options or {}),
        )
        grot, gpos = _fk(rot, root, motion)
    if limbs:
        fk = (grot, gpos)
        for j, g in limbs:
            solved = two_bone_ik(
                rot, root, sk, j, _blend(gpos[:, j], g), end_rotation=grot[:, j], fk=fk, bend_axis=given.get(j),
                warn_unreachable=False,  # refine() reports misses once, on the result
                weight=g.weights,
            )
            rot = np.where((g.weights > 0.0)[:, None, None], solved, rot)  # limbs no goal holds stay as they were
        grot, gpos = _fk(rot, root, motion)
    if foot_joints:
        legs = [limb_joints(sk, ankle) for ankle in foot_joints]
        targets = [
            _foot_targets(gpos, ankle, foot_of.get(ankle), toes.get(ankle), motion.fps, leg[0])
            for ankle, leg in zip(foot_joints, legs, strict=True)
        ]
        ankles = np.array(list(toes), dtype=np.int64)
        tips = np.array([jt for jt, _ in toes.values()], dtype=np.int64)
        if len({j for leg in legs for j in leg}) == 3 * len(legs):
            # independent legs: one batched two-bone solve (what two_bone_ik
            # does leg by leg, the same numbers)
            ju, jm, je = (np.array(j) for j in zip(*legs, strict=True))
            a, b, c = gpos[:, ju], gpos[:, jm], gpos[:, je]
            # each knee bends about its own hinge over the clip, never backwards
            local = hinge_axes(grot, gpos, legs)
            for k, ankle in enumerate(foot_joints):
                if ankle in given:
                    local[k] = given[ankle]
            hinge = quat.rotate(grot[:, jm], local)
            # a leg's goal weight: its ankle's or its toe's, whichever holds more
            held = np.stack([_leg_weight(foot_of.get(ankle), toes.get(ankle), n) for ankle in foot_joints], axis=1)
            targets, held = _keep_free_feet(targets, held, foot_joints, drop)
            q_up, q_mid = two_bone_deltas(a, b, c, np.stack(targets, axis=1), hinge=hinge, weight=held)
            # legs no goal holds on a frame stay exactly as they were
            free = held <= 0.0
            q_up = np.where(free[..., None], _IDENTITY, q_up)
            q_mid = np.where(free[..., None], _IDENTITY, q_mid)
            rot = two_bone_locals(rot, grot, sk.parents, (ju, jm, je), q_up, q_mid, grot[:, je])
            if toes:
                # where the solve put the ankles (the lower leg turned by
                # q_mid about the knee, then the leg by q_up about the hip)
                # and the toes (each ankle kept its global orientation)
                col = np.array([foot_joints.index(int(j)) for j in ankles], dtype=np.int64)
                ankle_pos = (a + quat.rotate(q_up, (b - a) + quat.rotate(q_mid, c - b)))[:, col]
                toe_pos = ankle_pos + (gpos[:, tips] - gpos[:, ankles])
                # the ankle hangs from its own parent (a twist joint below the knee, or the knee)
                g_parent = end_parent_rotations(grot, sk.parents, je, q_up, q_mid)[:, col]
                g_ankle = grot[:, ankles]
        else:
            weights = np.stack([_leg_weight(foot_of.get(ankle), toes.get(ankle), n) for ankle in foot_joints], axis=1)
            targets, weights = _keep_free_feet(targets, weights, foot_joints, drop)
            for k, (ankle, target) in enumerate(zip(foot_joints, targets, strict=True)):
                held = weights[:, k]
                solved = two_bone_ik(
                    rot, root, sk, ankle, target, end_rotation=grot[:, ankle], fk=(grot, gpos),
                    bend_axis=given.get(ankle), warn_unreachable=False, weight=held,
                )
                rot = np.where((held > 0.0)[:, None, None], solved, rot)  # legs no goal holds stay as they were
            if toes:
                grot2, gpos2 = _refresh(rot, (grot, gpos), motion, [leg[0] for leg in legs])
                ankle_pos, toe_pos = gpos2[:, ankles], gpos2[:, tips]
                g_parent, g_ankle = grot2[:, sk.parents[ankles]], grot2[:, ankles]
        if toes:
            q = aim_deltas(
                ankle_pos,
                toe_pos,
                np.stack([gt.targets for _, gt in toes.values()], axis=1),
                weight=np.stack([gt.weights for _, gt in toes.values()], axis=1),
            )
            new_global = quat.mul(q, g_ankle)
            rot[:, ankles] = quat.normalize(quat.mul(quat.inv(g_parent), new_global))
        grot, gpos = _refresh(rot, (grot, gpos), motion, [leg[0] for leg in legs])
    if not root_moved:
        new_motion = motion.replace(rotations=_owned(rot))
    else:
        # the drop as a ground-frame translation: onto the pelvis below a static reference root
        turned = motion.replace(rotations=_owned(rot))
        new_motion = turned.transformed(translation=root - motion.root_positions)
        top = turned.carrier_joint
        if top != 0:
            # the static joints above the pelvis did not move in the motion, so not in its kinematics either (the
            # forward kinematics above lowered joint 0 with the rest; a touch-up reading them placed the pelvis wrong)
            static = sk.chain(0, top)[:-1]
            gpos = np.array(gpos, copy=True)
            gpos[:, static, 1] -= drop[:, None]
    return new_motion, (grot, gpos)


def enforce_goals(
    motion: Motion,
    goals: Sequence[Goal],
    *,
    spacing: float = 0.25,
    levels: int = 3,
    exact: bool = True,
    adjust_root: bool = True,
    dls_options: dict[str, Any] | None = None,
) -> Motion:
    """Meet the goals with a smooth correction: IK, displacement map, IK.

    Parameters
    ----------
    motion : Motion
    goals : sequence of Goal
    spacing : float
        Knot spacing of the coarsest displacement-map level, seconds (> 0).
    levels : int
        Number of levels (each halves the spacing), 1 to :data:`MAX_LEVELS`.
    exact : bool
        Run the IK layer once more on the smoothed motion, aiming each goal
        joint at its position in the per-frame solution with the same
        weights (constraints hold exactly), then smooth the legs'
        corrections where no foot goal holds fully, so a plant's start or
        end puts no kink in a knee (end-effector arms stay exact).
    adjust_root, dls_options
        See :func:`solve_goals`.

    Returns
    -------
    Motion
        A new motion (``motion`` itself when there is no goal).

    Raises
    ------
    TypeError, ValueError
        For a ``spacing`` or ``levels`` of the wrong kind or out of range.

    Examples
    --------
    A leg reaches a point over frames 10-19, with three-frame ramps:

    >>> import numpy as np
    >>> from mocaplab.motion import Motion, Skeleton
    >>> sk = Skeleton(["hip", "knee", "ankle"], [-1, 0, 1], [[0, 1, 0], [0, -0.45, 0], [0, -0.45, 0]])
    >>> leg = Motion(sk, np.tile([0.0, 0, 0, 1], (30, 3, 1)), np.zeros((30, 3)), fps=30)
    >>> reach = Goal("ankle", np.tile([0.2, 0.3, 0.0], (30, 1)), blend_weights(30, [(10, 20)], window_frames=3))
    >>> ankle = enforce_goals(leg, [reach], adjust_root=False).global_positions()[:, 2]
    >>> ankle[15].round(3).tolist(), ankle[0].round(2).tolist()
    ([0.2, 0.3, 0.0], [0.0, -0.9, 0.0])
    """
    spacing, levels = map_options(spacing, levels)
    if not goals:
        return motion
    solved = solve_goals(motion, goals, adjust_root=adjust_root, dls_options=dls_options)
    d_root, d_rot = displacement_between(motion, solved)
    active = np.max([g.weights for g in goals], axis=0)
    dmap = DisplacementMap.fit(
        d_root, d_rot, weights=1.0 + 9.0 * active, spacing=max(spacing * motion.fps, 1.0), levels=levels,
    )
    smooth = dmap.apply(motion)
    if not exact:
        return smooth
    # Last pass: aim each goal joint at where the per-frame solution put it
    # (that is the constraint itself where w = 1), with the same weights, so
    # only the small smoothing residual is corrected and it fades out with
    # the blending windows.  The root correction is already in the map.
    reached = solved.global_positions()
    sk = motion.skeleton
    final = [dataclasses.replace(g, targets=reached[:, sk.index(g.joint, arg="Goal.joint")]) for g in goals]
    return _smooth_kinks(motion, solve_goals(smooth, final, adjust_root=False, dls_options=dls_options), goals)


# Kink smoothing after the exact pass (see _smooth_kinks): the smoother's time scale, seconds, the (much
# shorter) one on frames where a goal holds its joint fully, and how sharply a goal's weight counts as holding.
_KINK_SECONDS = 0.1
_HELD_SECONDS = 0.01
_HELD_POWER = 50
# How far (metres) the smoother may move a held toe before the foot is turned back toward it: not at all
# below the first, fully above the second.
_TOE_SLACK = (0.002, 0.008)


def _smooth_kinks(motion: Motion, out: Motion, goals: Sequence[Goal], *, pin: bool = False) -> Motion:
    """The correction ``out - motion`` of each joint above a goal, smoothed where no goal holds fully.

    The exact pass meets every goal on every frame, and where a goal starts
    or ends (a heel strike, a toe-off) the correction it needs changes its
    velocity in one frame: a landing foot moving at ``v`` is held still, so
    its correction starts growing at ``-v`` from one frame to the next, and
    a near-straight knee turns that into an angular-acceleration spike.
    Each joint's rotation displacement ``d = log(q^-1 q')`` is therefore
    refitted by a weighted second-difference smoother (a Whittaker
    smoother, one banded solve per joint): minimise
    ``sum_i W_i |x_i - d_i|^2 + lam sum_i |x_{i-1} - 2 x_i + x_{i+1}|^2``
    with ``lam = (fps * 0.1 s)^4 / 16`` and ``W = 1 + ((0.1 / 0.01)^4 - 1)
    w^50``, ``w`` the largest weight of the goals below the joint: the
    correction is smoothed over about a tenth of a second where no goal
    holds (free frames and the outer blending windows) and over about a
    hundredth where one holds fully, the same at any frame rate.  The
    velocity change moves out of the held frames into the blending windows
    (a plant moves by a millimetre or so where its foot rolls from heel to
    toe, where the exact pass's correction is least smooth).  Only the legs are smoothed: joints above an end
    effector (a ``"limb"`` goal: a hand on its target, met exactly), joints
    above no goal and uncorrected joints are left as they are, and so is
    the root's translation (its lowering is smooth already).  Last, where
    the smoother moved a fully held toe by more than 2 to 8 mm, the foot
    turns about its ankle back toward where the exact pass put the toe.
    With ``pin`` the frames a goal holds fully (weight 1) keep ``out``'s
    rotations exactly and the smoother works around them (the staggered
    constraint layer: its plants hold to a hundredth of a millimetre, where
    the soft weight above leaves a millimetre or two).
    """
    n = motion.n_frames
    if n < 4 or not goals:
        return out
    d = rotation_displacement(motion.rotations, out.rotations)
    moved = np.abs(d).max(axis=(0, 2)) > 1e-12
    sk = motion.skeleton
    held = np.zeros((sk.n_joints, n))
    exact = np.zeros(sk.n_joints, dtype=bool)  # above an end effector: its target is the user's, met exactly
    for g in goals:
        j = sk.index(g.joint, arg="Goal.joint")
        while j >= 0:
            if g.kind == "limb":
                exact[j] = True
            else:
                held[j] = np.maximum(held[j], g.weights)
            j = int(sk.parents[j])
    rot = np.array(out.rotations, copy=True)
    for j in np.flatnonzero(moved & ~exact & (held.max(axis=1) > 0.0)).tolist():
        w = 1.0 + ((_KINK_SECONDS / _HELD_SECONDS) ** 4 - 1.0) * held[j] ** _HELD_POWER
        pinned = held[j] >= 1.0 if pin else None
        rot[:, j] = displace(motion.rotations[:, j], _whittaker(d[:, j], w, _KINK_SECONDS * motion.fps, pinned))
    # a planted toe goes back where the exact pass put it: the foot turns about its ankle by the shortest arc,
    # on the frames its goal holds fully (w^50).  The smoother moves a held ankle by a millimetre or so, but
    # the foot's own correction is as jittery as the captured foot it steadies (a toe that jumps 40 mm a frame
    # about a still ankle, CMU 05_02), and smoothing it gave the toe back part of its jitter
    toes = [(sk.index(g.joint), g) for g in goals if g.kind == "toe"]
    feet = np.array([int(sk.parents[j]) for j, _ in toes], dtype=np.int64)
    if toes and not np.all(exact[feet]):
        grot, gpos = _fk(rot, out.root_positions, out)
        tips = np.array([j for j, _ in toes], dtype=np.int64)
        want = out.global_positions()[:, tips]
        # only where the smoother moved a held toe off by more than a few millimetres (weighted smoothly):
        # elsewhere the smoothed foot is kept, because it also took out the exact pass's own kinks
        off = np.linalg.norm(gpos[:, tips] - want, axis=-1)
        hold = np.stack([g.weights for _, g in toes], axis=1) ** _HELD_POWER * ~exact[feet]
        hold = hold * blend_ramp((off - _TOE_SLACK[0]) / (_TOE_SLACK[1] - _TOE_SLACK[0]))
        q = aim_deltas(gpos[:, feet], gpos[:, tips], want, weight=hold)
        parent = grot[:, sk.parents[feet]]
        rot[:, feet] = quat.normalize(quat.mul(quat.inv(parent), quat.mul(q, grot[:, feet])))
    return out.replace(rotations=_owned(rot))


# ------------------------------------------------------------ end effectors
@dataclasses.dataclass(frozen=True)
class RelativeTo:
    """A target attached to a joint: of another character, or of the same one.

    Parameters
    ----------
    joint : str
        Joint whose world position (plus ``offset``) is the target.
    offset : array_like, shape (3,)
        World-frame offset from that joint, metres.
    character : int, optional
        Index of the other character in :func:`refine_scene`; ``None`` means
        the constrained character itself (resolved on its motion before
        refinement).

    Two constraints that point at each other (A's hand relative to B's hand
    and B's hand relative to A's, as in a high five) meet halfway: both
    targets are the midpoint of the two hands (shifted by half the agreed
    offset), so each character reaches half the gap.

    Raises
    ------
    ValueError
        For an ``offset`` that is not 3 numbers.

    Examples
    --------
    >>> RelativeTo("RightHand", offset=[0, 0.1, 0], character=1)
    RelativeTo(joint='RightHand', offset=(0.0, 0.1, 0.0), character=1)
    """

    joint: str
    offset: tuple[float, float, float] = (0.0, 0.0, 0.0)
    character: int | None = None

    def __post_init__(self) -> None:
        off = tuple(float(x) for x in np.asarray(self.offset, dtype=float).reshape(-1))
        if len(off) != 3:
            raise ValueError(f"Expected RelativeTo `offset` of 3 numbers, got {self.offset!r}")
        object.__setattr__(self, "offset", off)


@dataclasses.dataclass(frozen=True, eq=False)
class ObjectFrame:
    """A target fixed in a moving object's frame (hands on a box).

    Parameters
    ----------
    positions : array_like, shape (3,) or (F, 3)
        Object origin in the world, per frame or constant.
    rotations : array_like, shape (4,) or (F, 4)
        Object orientation (quaternion), per frame or constant.
    offset : array_like, shape (3,)
        Target point in the object's frame.

    Examples
    --------
    A box at x = 1 m turned a quarter turn about Y: a point half a metre
    along its x axis is at z = -0.5 m in the world:

    >>> import numpy as np
    >>> box = ObjectFrame([1.0, 0, 0], rotations=[0, np.sin(np.pi / 4), 0, np.cos(np.pi / 4)], offset=[0.5, 0, 0])
    >>> box.world(2).round(3).tolist()
    [[1.0, 0.0, -0.5], [1.0, 0.0, -0.5]]
    """

    positions: Array
    rotations: Array = dataclasses.field(default_factory=lambda: np.array([0.0, 0.0, 0.0, 1.0]))
    offset: Array = dataclasses.field(default_factory=lambda: np.zeros(3))

    def world(self, n_frames: int) -> Array:
        """Target positions, shape (F, 3)."""
        pos = np.asarray(self.positions, dtype=float)
        rq = np.asarray(self.rotations, dtype=float)
        off = np.asarray(self.offset, dtype=float)
        if pos.shape not in ((3,), (n_frames, 3)):
            raise ValueError(f"Expected ObjectFrame `positions` of shape (3,) or ({n_frames}, 3), got {pos.shape}")
        if rq.shape not in ((4,), (n_frames, 4)):
            raise ValueError(f"Expected ObjectFrame `rotations` of shape (4,) or ({n_frames}, 4), got {rq.shape}")
        if off.shape != (3,):
            raise ValueError(f"Expected ObjectFrame `offset` of shape (3,), got {off.shape}")
        return np.broadcast_to(pos + quat.rotate(quat.normalize(rq), off), (n_frames, 3)).copy()


@dataclasses.dataclass(frozen=True, eq=False)
class EndEffector:
    """Put a joint on a target at a frame or over frames.

    Parameters
    ----------
    joint : str
        The end effector (e.g. ``"RightHand"``).
    frames : int, (start, stop) tuple, range, or sequence of ints
        A single frame, a half-open interval (a *tuple* of two ints), or a
        list/array of frames.
    target : array_like (3,) or (F, 3), RelativeTo, or ObjectFrame
        World position(s), a joint (of this or another character), or a
        point in an object's frame.
    character : int
        Which character in :func:`refine_scene` (0 for :func:`refine`).
    chain : sequence of str, optional
        Solve with damped least squares over these joints (e.g. the spine
        and the arm) instead of the two-bone limb ending at ``joint``.
    blend : float, optional
        Blending window in seconds (default: that of the refine call).

    Raises
    ------
    ValueError
        For a world target that is not of shape (3,) or (F, 3).

    Examples
    --------
    >>> EndEffector("RightHand", (10, 20), [0.2, 1.3, 0.0]).intervals(30)
    [(10, 20)]
    >>> EndEffector("RightHand", [3, 4, 5, 9], [0.2, 1.3, 0.0]).intervals(30)
    [(3, 6), (9, 10)]
    """

    joint: str
    frames: int | tuple[int, int] | Sequence[int] | range
    target: object
    character: int = 0
    chain: tuple[str, ...] | None = None
    blend: float | None = None

    def __post_init__(self) -> None:
        if self.chain is not None:
            object.__setattr__(self, "chain", tuple(self.chain))
        if not isinstance(self.target, (RelativeTo, ObjectFrame)):
            t = np.array(self.target, dtype=float)
            if t.ndim not in (1, 2) or t.shape[-1] != 3:
                raise ValueError(f"Expected EndEffector `target` of shape (3,) or (F, 3), got {t.shape}")
            object.__setattr__(self, "target", readonly(t))

    def check(self, motion: Motion, *, label: str | None = None) -> None:
        """Raise ValueError, naming this constraint, if it cannot apply to ``motion``.

        Checks that the joint (and any ``chain`` joint and :class:`RelativeTo`
        joint of the same character) is in the skeleton, that the frames lie
        within the clip and that a per-frame target has one row per frame.
        ``label`` names the constraint in the message (default its joint and
        frames).
        """
        what = label if label is not None else f"EndEffector({self.joint!r}, frames={self.frames!r})"
        names = motion.skeleton.names
        missing = [j for j in (self.joint, *(self.chain or ())) if j not in names]
        if isinstance(self.target, RelativeTo) and self.target.character in (None, self.character):
            missing += [self.target.joint] if self.target.joint not in names else []
        if missing:
            raise ValueError(
                f"{what}: joint(s) {missing} not in the skeleton of {motion.n_frames} frames; "
                f"expected one of {list(names)}"
            )
        try:
            ivs = self.intervals(motion.n_frames)
        except ValueError as err:
            raise ValueError(f"{what}: {err} (the clip has frames 0..{motion.n_frames - 1})") from None
        t = self.target
        if isinstance(t, np.ndarray) and t.ndim == 2 and t.shape[0] != motion.n_frames:
            raise ValueError(
                f"{what}: expected a target of shape (3,) or ({motion.n_frames}, 3) (one row per frame), got {t.shape}"
            )
        if not ivs:
            raise ValueError(f"{what}: no frame constrained")

    def intervals(self, n_frames: int) -> list[tuple[int, int]]:
        """The constrained frames as half-open intervals."""
        f = self.frames
        if isinstance(f, (int, np.integer)):
            ivs = [(int(f), int(f) + 1)]
        elif isinstance(f, tuple) and len(f) == 2:
            ivs = [(int(f[0]), int(f[1]))]
        else:
            arr = np.unique(np.asarray(list(f), dtype=np.int64))
            if arr.size == 0:
                raise ValueError(f"Expected at least one frame in EndEffector `frames` for {self.joint!r}")
            if arr[0] < 0 or arr[-1] >= n_frames:
                raise ValueError(f"Expected EndEffector frames in [0, {n_frames}), got {arr[0]}..{arr[-1]}")
            mask = np.zeros(n_frames, dtype=bool)
            mask[arr] = True
            ivs = intervals_from_mask(mask)
        return _check_intervals(ivs, n_frames)


def world_targets(ee: EndEffector, motions: Sequence[Motion]) -> Array:
    """World positions of an end effector's target on every frame.

    Parameters
    ----------
    ee : EndEffector
    motions : sequence of Motion
        The scene: ``motions[ee.character]`` is the constrained character,
        and a :class:`RelativeTo` target with ``character=k`` follows
        ``motions[k]``'s joint (``None``: the constrained character's own).

    Returns
    -------
    ndarray, shape (F, 3)
        A new array.

    Raises
    ------
    ValueError
        For characters of different frame counts or a target of the wrong shape.

    Examples
    --------
    >>> import numpy as np
    >>> from mocaplab.motion import Motion, Skeleton
    >>> sk = Skeleton(["hip", "knee", "ankle"], [-1, 0, 1], [[0, 1, 0], [0, -0.45, 0], [0, -0.45, 0]])
    >>> leg = Motion(sk, np.tile([0.0, 0, 0, 1], (30, 3, 1)), np.zeros((30, 3)), fps=30)
    >>> above_knee = EndEffector("ankle", 5, RelativeTo("knee", offset=(0, 0.1, 0)))
    >>> world_targets(above_knee, [leg])[5].round(3).tolist()
    [0.0, -0.35, 0.0]
    """
    me = motions[ee.character]
    n = me.n_frames
    t = ee.target
    if isinstance(t, RelativeTo):
        other = me if t.character is None else motions[t.character]
        if other.n_frames != n:
            raise ValueError(f"Expected characters with equal frame counts, got {n} and {other.n_frames}")
        return other.global_positions()[:, other.skeleton.index(t.joint)] + np.asarray(t.offset)
    if isinstance(t, ObjectFrame):
        return t.world(n)
    arr = np.asarray(t, dtype=float)
    if arr.shape == (3,):
        return np.broadcast_to(arr, (n, 3)).copy()
    if arr.shape != (n, 3):
        raise ValueError(f"Expected EndEffector target for {ee.joint!r} of shape (3,) or ({n}, 3), got {arr.shape}")
    return np.array(arr)


def effector_goals(
    motion: Motion,
    end_effectors: Sequence[EndEffector],
    targets: Sequence[Array],
    *,
    blend: float = 0.1,
) -> list[Goal]:
    """Goals from end effectors whose world targets ``(F, 3)`` are resolved.

    In the blending windows the joint follows its own motion plus a fading
    correction (see ``_window_targets`` in the source for the formula).

    Parameters
    ----------
    motion : Motion
        The constrained character.
    end_effectors : sequence of EndEffector
    targets : sequence of ndarray, shape (F, 3)
        Each end effector's world targets (:func:`world_targets`), in order.
    blend : float
        Blending window on each side, seconds, for end effectors without
        their own ``blend`` (default 0.1 s).

    Returns
    -------
    list of Goal
        One ``"limb"`` goal per end effector.

    Examples
    --------
    >>> import numpy as np
    >>> from mocaplab.motion import Motion, Skeleton
    >>> sk = Skeleton(["hip", "knee", "ankle"], [-1, 0, 1], [[0, 1, 0], [0, -0.45, 0], [0, -0.45, 0]])
    >>> leg = Motion(sk, np.tile([0.0, 0, 0, 1], (30, 3, 1)), np.zeros((30, 3)), fps=30)
    >>> ee = EndEffector("ankle", (10, 20), [0.2, 0.3, 0.0])
    >>> goal, = effector_goals(leg, [ee], [world_targets(ee, [leg])], blend=0.1)
    >>> goal.weights[6:11].round(2).tolist(), goal.targets[15].tolist()
    ([0.0, 0.1, 0.5, 0.9, 1.0], [0.2, 0.3, 0.0])
    """
    out = []
    n = motion.n_frames
    for ee, tgt in zip(end_effectors, targets, strict=True):
        ivs = ee.intervals(n)
        window = _frames(ee.blend if ee.blend is not None else blend, motion.fps, "blend")
        mask = np.zeros(n, dtype=bool)
        for a, b in ivs:
            mask[a:b] = True
        weights = blend_weights(n, ivs, window_frames=window)
        pos = motion.global_positions()[:, motion.skeleton.index(ee.joint)]
        out.append(Goal(ee.joint, _window_targets(pos, np.asarray(tgt, dtype=float), mask, weights), weights, chain=ee.chain))
    return out
