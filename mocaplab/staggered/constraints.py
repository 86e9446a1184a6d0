"""The contact constraint layer of staggered poses (Coleman et al. 2008, section 3, section 4.1.2).

Section 3 ends the evaluation of a staggered-pose motion with one more
displacement layer: an inverse-kinematics solution that holds labelled end
effectors where the environment constrains them, nonzero only while a
constraint is active and attenuated smoothly over a short window on each side.
Section 4.1.2 and Appendix B find those constraints (joints that stay still
for a while); here they come from :func:`mocaplab.staggered.features.analyze`,
which uses the package's contact detection (:mod:`mocaplab.contacts`).

:class:`ConstraintLayer` is that layer: on contact intervals (mapped through
the pose timing) the feet (and any other constrained end effector) are brought
back to their original positions by the package's one goal solver,
:func:`mocaplab.goals.solve_goals`, with :class:`~mocaplab.goals.Goal` weights
blended in and out by :func:`mocaplab.goals.blend_weights`.
:func:`constraint_joints` says which joints of a skeleton it can hold, and how,
from the joint roles (:mod:`mocaplab.roles`).  Targets out of reach are
reported with :class:`mocaplab.ik.UnreachableTargetWarning`, the warning every
goal in the package raises for them.

Neighbours: the layer reads the pose timing of
:mod:`~mocaplab.staggered.representation` (which stores the layer and calls
:meth:`ConstraintLayer.apply` at the end of
:meth:`~mocaplab.staggered.StaggeredMotion.evaluate`, without importing this
module); :func:`mocaplab.staggered.extract` (:mod:`~mocaplab.staggered.fit`)
builds it from the clip's contacts; the edits of
:mod:`~mocaplab.staggered.edit` carry it along when poses are inserted or
deleted.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping, Sequence
from typing import Any, Literal

import numpy as np
from numpy.typing import NDArray

from .. import kinematics
from .._warnings import warn
from ..contacts import intervals_from_mask
from ..goals import Goal, _smooth_kinks, blend_weights, solve_goals
from ..ik import UnreachableTargetWarning, hinge_axes, limb_joints, reach_residual
from ..motion import Motion, Skeleton
from ..roles import resolve_roles
from .representation import StaggeredMotion, pose_time, pose_u

__all__ = ["ConstraintLayer", "constraint_joints"]

Array = NDArray[np.float64]
GoalKind = Literal["foot", "toe", "limb"]


def constraint_joints(
    skeleton: Skeleton, candidates: Sequence[str], *, roles: Mapping[str, Any] | None = None
) -> tuple[tuple[str, ...], tuple[GoalKind, ...]]:
    """The joints of ``candidates`` the constraint layer can hold, and how.

    From the joint roles (:func:`mocaplab.roles.resolve_roles`): an ankle
    is a ``"foot"`` goal (the leg's two-bone IK), a toe whose parent is an
    ankle a ``"toe"`` goal (the foot turns about the ankle), a wrist a
    ``"limb"`` goal (the arm's two-bone IK); other joints are left out.

    Parameters
    ----------
    skeleton : Skeleton
    candidates : sequence of str
        Joint names to consider (usually the contact joints).
    roles : mapping, optional
        Joint-role overrides (:func:`mocaplab.roles.resolve_roles`).

    Returns
    -------
    joints : tuple of str
        The kept joint names, in the order of ``candidates``.
    kinds : tuple of str
        Their kinds of :class:`~mocaplab.goals.Goal` (``"foot"``, ``"toe"`` or ``"limb"``).

    Examples
    --------
    >>> import mocaplab as ml
    >>> sk = ml.cmu("16_15").skeleton
    >>> ml.staggered.constraint_joints(sk, ["LeftFoot", "LeftToeBase", "RightHand", "Head"])
    (('LeftFoot', 'LeftToeBase', 'RightHand'), ('foot', 'toe', 'limb'))
    """
    r = resolve_roles(skeleton, roles)
    ankles = {r[f"{s}_ankle"] for s in ("left", "right") if f"{s}_ankle" in r}
    toes = {r[f"{s}_toe"] for s in ("left", "right") if f"{s}_toe" in r}
    wrists = {r[f"{s}_wrist"] for s in ("left", "right") if f"{s}_wrist" in r}
    names: list[str] = []
    kinds: list[GoalKind] = []
    for name in candidates:
        j = skeleton.index(name)
        parent = skeleton.names[int(skeleton.parents[j])] if j > 0 else None
        if name in ankles:
            kind: GoalKind | None = "foot"
        elif name in toes:
            kind = "toe" if parent in ankles else None
        elif name in wrists:
            kind = "limb"
        else:
            kind = None
        if kind is not None:
            names.append(name)
            kinds.append(kind)
    return tuple(names), tuple(kinds)


#: Seconds on each side over which the constraint layer's root lowering is
#: smoothed (``drop_window`` of :func:`mocaplab.goals.solve_goals`).
_DROP_WINDOW = 0.15
#: Fraction of a leg's length the layer's root lowering keeps a held leg
#: within (``reach`` of :func:`mocaplab.goals.solve_goals`).  Near full
#: extension the knee angle is very sensitive to the hip: at 0.99 the broad
#: jump 16_05 under a succession of 0.02 s snaps its knee to 167 degrees and
#: back at take-off (1,048 rad/s^2, the input 198); at 0.96, 529.
_REACH = 0.96
#: The straightest a held leg may stay (``max_reach`` of :func:`mocaplab.goals.solve_goals`): the
#: walk 16_15 with its legs exaggerated by 0.5 straightens a knee to 4 degrees where the toe still holds,
#: and a target brushing past that makes the held knee dip and return within 5 frames (peak knee
#: acceleration 779 rad/s^2 uncapped, 436 at 0.997, 345 at 0.995; the edit alone 230).  Lower caps
#: lower the root more often: the salsa 60_10 exaggerated by 0.3 goes from 1,970 to 2,122 (0.997) and
#: 2,251 (0.995).
_MAX_REACH = 0.997


#: How fast the layer's correction of a joint may grow or fall, as a multiple of the joint's largest speed in
#: the input (see "Pull-in" in ConstraintLayer's notes).  On animation.bvh (below) 0.5x leaves the edit's own
#: LeftToeBase at 1.50x the input's one-frame move, 1x at 1.47x; the CMU clips never reach it.
_PULL_IN_SPEED = 1.0
#: The slowest pull-in, m/s, for a joint (nearly) still throughout the input.
_PULL_IN_FLOOR = 0.5


def _pull_in_limited(w: Array, dist: Array, t: Array, speed: Array) -> Array:
    """Weights ``w`` (F, E) lowered so each correction changes size by at most ``speed`` (E,) m/s.

    ``dist`` (F, E) is each joint's distance to its target without the
    layer, so ``w * dist`` is the size of its correction, ``t`` the times
    (s).  A forward pass bounds the correction's growth (a pull-in, or a
    plant the edited joint runs away from), a backward pass its fall (a
    release, or a plant the edited joint sweeps through).
    """
    out = np.array(w, dtype=float, copy=True)
    step = speed[None, :] * np.diff(t)[:, None]  # (F - 1, E)
    safe = np.where(dist > 0, dist, 1.0)
    F = out.shape[0]
    for f, g in [(f, f - 1) for f in range(1, F)] + [(f, f + 1) for f in range(F - 2, -1, -1)]:
        cap = out[g] * dist[g] + step[min(f, g)]
        out[f] = np.where(out[f] * dist[f] > cap, cap / safe[f], out[f])
    return out


def _frames_of(seconds: float, fps: float) -> int:
    """Whole frames covering ``seconds`` at ``fps`` (at least 1)."""
    return max(int(np.ceil(seconds * fps - 1e-9)), 1)


@dataclasses.dataclass(frozen=True, eq=False)
class ConstraintLayer:
    """Contact constraints as the last displacement layer (section 3).

    On the frames of a contact each constrained joint is held at its
    original world position by the one goal solver of the package,
    :func:`mocaplab.goals.solve_goals` (ankles by the leg's two-bone
    IK, toes by turning the foot about the ankle, wrists by the arm's
    two-bone IK), with weights that are 1 inside the contact and fall to 0
    over ``window`` seconds on each side
    (:func:`mocaplab.goals.blend_weights`).  The motion's translation
    channels take part in the forward kinematics and are passed through.

    * **Timing.**  A contact and its targets are laid on the original
      frames, which follow the pose timing (``pose_u``): retimed poses carry
      their contacts.  ``timing`` can instead make a joint's contacts follow
      the knots of a control variable, for instance its own rotation (the
      foot's own refinements, ``timing=layer.joints``), through the
      representation's displacement-sample positions
      (:attr:`StaggeredMotion.sample_u`).  Measured on the walk 16_15 under
      whole-body succession (``s`` = 0.01 and 0.02 s, ``l = 1``), following
      the feet's refinements made the solver change the motion *more*
      (mean 0.82 against 0.35 degrees, peak knee acceleration 609 against
      275 rad/s^2, the edit without the layer 178): the root is not
      delayed with the legs, so a delayed leg cannot hold a plant at any
      shifted time, and a later plant only adds to the correction.  Pose
      timing is the default.
    * **Bending direction.**  Every two-bone limb bends about the hinge its
      middle joint had in the *input* clip (``hinges``,
      :func:`mocaplab.ik.hinge_axes` on the source motion), so a knee never
      changes its bending direction relative to the input, however straight
      an edit makes it.
    * **Continuity.**  The per-frame solution changes its velocity in one
      frame wherever a contact's weight starts or ends, the root lowering
      levels off or a near-straight knee's target turns back, so the legs'
      corrections are smoothed over about 0.1 s where no goal holds fully,
      the frames a goal holds fully kept exactly (the goal solver's kink
      smoother, ``pin=True``).  Measured under a succession of 0.02 s: the
      broad jump 16_05's take-off knee 656 -> 218 rad/s^2 (input 198), the
      landing toe of 49_03 47.9 -> 33.5 mm in a frame (input 27.6), pymo's
      walk AV_8Walk 1,207 -> 686 rad/s^2 (input 344); the plants still
      hold to 0.1 mm.
    * **Pull-in.**  A correction grows and falls no faster than its
      joint's largest speed in the input (``speeds``; at least 0.5 m/s):
      where an edit leaves a joint far from its plant, or sweeps it past
      the plant, the weight ramps in or out slower than ``window`` says and
      the plant is held only once the correction has caught up.  The
      motionmachine file animation.bvh (30 fps, a succession of 0.02 s),
      whose delayed toe sweeps 33 cm past a 0.3 s toe plant: RightLeg
      124.8 -> 97.4 mm/frame (input 67.8), the worst joint 1.84x -> 1.48x
      the input's (LeftFoot), the largest skate 127 -> 82 mm; the CMU clips
      of tests/test_staggered_quality.py are unchanged.
    * **Reach.**  Where a leg cannot reach, the solver lowers the root,
      smoothly and by at most 15 cm (``adjust_root``, on by default, as in
      Kovar et al. 2002's footskate cleanup): without it a leg snaps
      straight and back (the walk with its legs exaggerated by 0.5: peak
      knee acceleration 750 against 563 rad/s^2; whole-body succession
      ``s = 0.01``: 2,580 against 275, the edit alone 178).  Where a joint
      still misses its target (a held joint by more than
      ``reach_tolerance``, or a two-bone goal beyond the limb's reach), an
      :class:`~mocaplab.ik.UnreachableTargetWarning` names the frames.

    Parameters
    ----------
    joints : tuple of str
        Constrained joints (see :func:`constraint_joints`).
    pose_u : ndarray, shape (N,)
        Position of each original frame in *pose-index units*
        (:func:`~mocaplab.staggered.representation.pose_u` of the pose times),
        so contacts and targets follow the poses when they are retimed
        (inserting or deleting a pose updates it).
    masks : ndarray of bool, shape (N, E)
        Contact state of each joint on the original frames.
    targets : ndarray, shape (N, E, 3)
        Original world positions of the joints (the targets kept).
    speeds : ndarray, shape (N, E), optional
        Original world speeds of the joints (m/s); a goal's stiffness is
        ``1 / (speed + 0.05 m/s)`` as in :func:`mocaplab.goals.foot_goals`,
        so where an ankle and its toe cannot both hold (one of them blending
        in or out) the foot rolls about the stiller one.  Default zeros.
    window : float
        Seconds over which the solution is blended in and out.
    tolerance : float
        Frames where every constrained joint is within this distance of its
        target (metres) are left alone, so the layer is the identity on the
        unedited motion and outside the edited stretch (a contact with any
        such frame is solved whole).
    kinds : tuple of str, optional
        The :class:`~mocaplab.goals.Goal` kind of each joint
        (``"foot"``, ``"toe"`` or ``"limb"``); default from the joint roles
        (:func:`constraint_joints`).
    adjust_root : bool
        Let the solver lower the root where a leg cannot reach its target
        (:func:`~mocaplab.goals.solve_goals`); on by default (see
        "Reach").
    timing : tuple of (str or None), optional
        For each joint, the control variable whose knots its contacts
        follow, or None for the pose timing; default all None.
    hinges : ndarray, shape (E, 3), optional
        The hinge of each joint's limb (for a toe, its ankle's leg) in the
        middle joint's local frame; default estimated on the motion solved.
    reach_tolerance : float
        Metres; see "Reach" above.

    Examples
    --------
    :func:`~mocaplab.staggered.extract` builds the layer from the clip's foot contacts:

    >>> import mocaplab as ml
    >>> sm = ml.staggered.extract(ml.cmu("16_15").resample(30)[:60], constraints=True)
    >>> sm.constraints.joints, sm.constraints.masks.shape, sm.constraints.window
    (('LeftFoot', 'LeftToeBase', 'RightFoot', 'RightToeBase'), (60, 4), 0.1)
    """

    joints: tuple[str, ...]
    pose_u: Array
    masks: NDArray[np.bool_]
    targets: Array
    speeds: Array = None  # type: ignore[assignment]  # None: zeros
    window: float = 0.1
    tolerance: float = 1e-6
    kinds: tuple[GoalKind, ...] = ()
    adjust_root: bool = True
    timing: tuple[str | None, ...] = ()
    hinges: Array | None = None
    reach_tolerance: float = 0.005

    def __post_init__(self) -> None:
        joints = tuple(str(n) for n in self.joints)
        E = len(joints)
        pose_u = np.asarray(self.pose_u, dtype=float).reshape(-1)
        N = pose_u.size
        masks = np.asarray(self.masks, dtype=bool)
        if masks.shape != (N, E):
            raise ValueError(f"Expected `masks` of shape ({N}, {E}), got {masks.shape}")
        targets = np.asarray(self.targets, dtype=float)
        if targets.shape != (N, E, 3):
            raise ValueError(f"Expected `targets` of shape ({N}, {E}, 3), got {targets.shape}")
        speeds = np.zeros((N, E)) if self.speeds is None else np.asarray(self.speeds, dtype=float)
        if speeds.shape != (N, E) or not np.all(np.isfinite(speeds)) or np.any(speeds < 0):
            raise ValueError(f"Expected finite `speeds` >= 0 of shape ({N}, {E}), got shape {speeds.shape}")
        kinds = tuple(self.kinds)
        if kinds and (len(kinds) != E or any(k not in ("foot", "toe", "limb") for k in kinds)):
            raise ValueError(f"Expected `kinds` of 'foot', 'toe' or 'limb', one per joint {joints}, got {kinds}")
        timing = tuple(None if v is None else str(v) for v in self.timing) or (None,) * E
        if len(timing) != E:
            raise ValueError(f"Expected `timing` with one variable name per joint {joints}, got {timing}")
        if not (np.isfinite(self.window) and self.window >= 0):
            raise ValueError(f"Expected `window` >= 0 seconds, got {self.window!r}")
        if not (np.isfinite(self.reach_tolerance) and self.reach_tolerance > 0):
            raise ValueError(f"Expected `reach_tolerance` > 0 metres, got {self.reach_tolerance!r}")
        for name, value in (("pose_u", pose_u), ("masks", masks), ("targets", targets), ("speeds", speeds)):
            value.flags.writeable = False
            object.__setattr__(self, name, value)
        if self.hinges is not None:
            hinges = np.array(self.hinges, dtype=float)
            if hinges.shape != (E, 3) or not np.all(np.isfinite(hinges)):
                raise ValueError(f"Expected finite `hinges` of shape ({E}, 3), got shape {hinges.shape}")
            hinges.flags.writeable = False
            object.__setattr__(self, "hinges", hinges)
        object.__setattr__(self, "joints", joints)
        object.__setattr__(self, "kinds", kinds)
        object.__setattr__(self, "timing", timing)
        object.__setattr__(self, "window", float(self.window))

    @classmethod
    def from_contacts(
        cls,
        motion: Motion,
        contacts: Any,
        times: Array,
        *,
        joints: Sequence[str] | None = None,
        window: float = 0.1,
        roles: Mapping[str, Any] | None = None,
        adjust_root: bool = True,
    ) -> ConstraintLayer:
        """Build the layer from a clip, its Contacts and the pose times (seconds).

        Default joints: the contact joints that are feet (ankles, toes) or
        wrists in the joint roles (:func:`constraint_joints`, ``roles``
        overriding); for CMU feet: LeftFoot, LeftToeBase, RightFoot,
        RightToeBase.  Given ``joints`` must be among them.  The hinges of
        their limbs are measured on ``motion`` (:func:`mocaplab.ik.hinge_axes`).
        """
        sk = motion.skeleton
        if contacts.n_frames != motion.n_frames:
            raise ValueError(
                f"Expected contacts over the motion's {motion.n_frames} frames, got {contacts.n_frames}"
            )
        names, kinds = constraint_joints(sk, tuple(contacts.joints) if joints is None else tuple(joints), roles=roles)
        if joints is not None and len(names) != len(tuple(joints)):
            bad = [n for n in joints if n not in names]
            raise ValueError(
                f"Expected `joints` that are ankles, toes (below an ankle) or wrists in the joint roles, got {bad}; "
                "name the roles with roles={...} or skeleton.with_roles(...)"
            )
        idx = [sk.index(n) for n in names]
        masks = np.stack([contacts.of(n) for n in names], axis=1) if names else np.zeros((motion.n_frames, 0), bool)
        grot, gpos = motion.global_rotations(), motion.global_positions()
        targets = np.array(gpos[:, idx])
        # the limb each goal bends: a toe's is its ankle's leg
        ends = [int(sk.parents[j]) if kind == "toe" else j for j, kind in zip(idx, kinds, strict=True)]
        limbs = [limb_joints(sk, e) for e in ends]
        return cls(
            joints=names,
            pose_u=pose_u(np.asarray(times, dtype=float), motion.times),
            masks=masks,
            targets=targets,
            speeds=np.linalg.norm(kinematics.velocities(targets, motion.fps), axis=-1),
            window=float(window),
            kinds=kinds,
            adjust_root=adjust_root,
            hinges=hinge_axes(grot, gpos, limbs) if limbs else np.zeros((0, 3)),
        )

    def frame_times(self, sm: StaggeredMotion, *, staggered: bool = True) -> Array:
        """Current time of every original frame for each joint, seconds, shape (N, E).

        Pose timing (``timing`` None): original frame ``n`` sits at
        ``pose_u[n]`` between ``sm``'s pose times.  A variable ``i``:
        frame ``n`` sits at ``sm.sample_u[n, i]`` along that variable's
        knots, and its time is found on ``sm``'s knots of it (pose times only
        with ``staggered=False``).
        """
        N = self.masks.shape[0]
        out = np.empty((N, len(self.joints)))
        on_poses = pose_time(sm.times, self.pose_u)
        for e, name in enumerate(self.timing):
            if name is None:
                out[:, e] = on_poses
                continue
            if sm.sample_u.shape[0] != N:
                raise ValueError(
                    f"The constraint layer covers {N} original frames, the representation's displacement maps "
                    f"{sm.sample_u.shape[0]}: build the layer from the clip the representation was extracted from"
                )
            i = sm.variable_index(name)
            act = np.flatnonzero(sm.active[:, i])
            T = sm.times[act] + (sm.refinements[act, i] if staggered else 0.0)
            u = sm.sample_u[:, i]
            s = np.clip(np.searchsorted(act, u, side="right") - 1, 0, act.size - 2)
            tn = (u - act[s]) / (act[s + 1] - act[s])
            out[:, e] = T[s] + tn * (T[s + 1] - T[s])
        return out

    def weights_and_targets(
        self, sm: StaggeredMotion, t: Array, *, staggered: bool = True, motion: Motion | None = None
    ) -> tuple[Array, Array]:
        """Blend weights (F, E) and targets (F, E, 3) at times ``t`` for ``sm``'s timing.

        The contact intervals, mapped onto ``sm``'s frames through each
        joint's timing (:meth:`frame_times`), are blended by
        :func:`mocaplab.goals.blend_weights` (weights between frames are
        interpolated); targets are interpolated between original frames.
        Given ``motion``, ``sm`` evaluated at ``t`` without the layer, the
        weights are those :meth:`apply` uses: lowered where the correction
        would grow or fall faster than the joint's largest input speed (see
        "Pull-in" in the class notes).
        """
        t = np.asarray(t, dtype=float).reshape(-1)
        grid = np.arange(sm.n_frames) / sm.fps
        E = len(self.joints)
        window = int(round(self.window * sm.fps))
        w = np.zeros((t.size, E))
        tg = np.zeros((t.size, E, 3))
        n = np.arange(self.masks.shape[0], dtype=float)
        same = t.shape == grid.shape and np.array_equal(t, grid)
        for e, tau in enumerate(self.frame_times(sm, staggered=staggered).T):
            inside = np.interp(np.interp(grid, tau, n), n, self.masks[:, e].astype(float)) >= 0.5
            w_grid = blend_weights(grid.size, intervals_from_mask(inside), window_frames=window)
            w[:, e] = w_grid if same else np.interp(t, grid, w_grid)
            at = np.interp(t, tau, n)
            tg[:, e] = np.stack([np.interp(at, n, self.targets[:, e, c]) for c in range(3)], axis=-1)
        if motion is not None and E and t.size > 1:
            if motion.n_frames != t.size:
                raise ValueError(f"Expected `motion` with one frame per time ({t.size}), got {motion.n_frames}")
            pos = motion.global_positions()[:, [motion.skeleton.index(name) for name in self.joints]]
            speed = np.maximum(_PULL_IN_SPEED * self.speeds.max(axis=0), _PULL_IN_FLOOR)
            w = _pull_in_limited(w, np.linalg.norm(pos - tg, axis=-1), t, speed)
        return w, tg

    def _speeds_at(self, sm: StaggeredMotion, t: Array, staggered: bool) -> Array:
        n = np.arange(self.masks.shape[0], dtype=float)
        tau = self.frame_times(sm, staggered=staggered)
        return np.stack(
            [np.interp(np.interp(t, tau[:, e], n), n, self.speeds[:, e]) for e in range(len(self.joints))], axis=-1
        ).reshape(t.size, len(self.joints))

    def apply(self, sm: StaggeredMotion, motion: Motion, t: Array, *, staggered: bool = True) -> Motion:
        """Hold the constrained joints on their targets (:func:`mocaplab.goals.solve_goals`).

        Warns (:class:`~mocaplab.ik.UnreachableTargetWarning`) naming the frames where,
        by more than ``reach_tolerance``, a fully held joint misses its
        target or a two-bone goal's blended target lies beyond its limb's
        reach (:func:`mocaplab.ik.reach_residual`).
        """
        if not self.joints:
            return motion
        w, tg = self.weights_and_targets(sm, t, staggered=staggered, motion=motion)
        sk = motion.skeleton
        idx = [sk.index(n) for n in self.joints]
        pos = motion.global_positions()[:, idx]
        err = np.linalg.norm(pos - tg, axis=-1)
        need = np.any((w > 0) & (err > self.tolerance), axis=1)
        if not need.any():
            return motion
        # solve whole contacts (runs of positive weight), so the solver sees them without gaps, and
        # the frames around them the root lowering spreads over (a smooth lower envelope of its need,
        # which reaches zero within twice its half-width of the last frame a goal holds): cut short
        # at a contact's end, the pelvis would jump back up in one frame
        pad = 2 * _frames_of(_DROP_WINDOW, motion.fps) + 2 if self.adjust_root else 0
        on = np.zeros(w.shape[0], dtype=bool)
        for a, b in intervals_from_mask(np.any(w > 0, axis=1)):
            if need[a:b].any():
                on[max(a - pad, 0) : b + pad] = True
        frames = np.flatnonzero(on)
        kinds = self.kinds or constraint_joints(sk, self.joints)[1]
        if len(kinds) != len(self.joints):
            raise ValueError(f"Joints {self.joints} have no goal kind on this skeleton: pass `kinds`")
        tr = motion.translations
        sub = motion.replace(
            rotations=motion.rotations[frames],
            root_positions=motion.root_positions[frames],
            translations=None if tr is None else tr[frames],
        )
        stiffness = 1.0 / (self._speeds_at(sm, t[frames], staggered) + 0.05)
        goals = [
            Goal(name, tg[frames, e], w[frames, e], kind=kinds[e], stiffness=stiffness[:, e])
            for e, name in enumerate(self.joints)
        ]
        hinges: dict[str | int, Array] | None = None
        if self.hinges is not None:
            hinges = {}
            for e, (j, kind) in enumerate(zip(idx, kinds, strict=True)):
                end = int(sk.parents[j]) if kind == "toe" else j
                hinges.setdefault(end, self.hinges[e])
        solved = solve_goals(
            sub, goals, adjust_root=self.adjust_root, hinges=hinges, drop_window=_DROP_WINDOW, reach=_REACH,
            max_reach=_MAX_REACH,
        )
        # the per-frame solution changes its velocity in a frame wherever a goal starts or ends, the root
        # lowering levels off or a near-straight knee's target turns back: the legs' corrections are smoothed
        # where no goal holds fully, as after the goal solver's exact pass (enforce_goals), the frames a goal
        # holds fully kept exactly
        solved = _smooth_kinks(sub, solved, goals, pin=True)
        # out of reach: a fully held joint misses its target, or a two-bone
        # goal's blended target lies beyond its limb (the limb went straight)
        spos = solved.global_positions()
        wf = w[frames]
        miss = np.where(wf >= 1.0 - 1e-9, np.linalg.norm(spos[:, idx] - tg[frames], axis=-1), 0.0)  # (n, E)
        for e, (j, kind) in enumerate(zip(idx, kinds, strict=True)):
            if kind != "toe":
                u_, m_, _ = limb_joints(sk, j)
                want = pos[frames, e] + wf[:, e, None] * (tg[frames, e] - pos[frames, e])
                gap = reach_residual(spos[:, u_], spos[:, m_], spos[:, j], want)
                miss[:, e] = np.maximum(miss[:, e], np.where(wf[:, e] > 0, gap, 0.0))
        bad = miss > self.reach_tolerance
        if bad.any():
            rows = np.zeros(w.shape[0], dtype=bool)
            rows[frames[bad.any(axis=1)]] = True
            spans = ", ".join(f"{a}-{b - 1}" if b - a > 1 else f"{a}" for a, b in intervals_from_mask(rows))
            worst = np.unravel_index(int(np.argmax(miss)), miss.shape)
            warn(
                f"Constraint layer: targets out of reach on frames {spans} "
                f"({self.joints[worst[1]]!r} misses by up to {1000 * miss[worst]:.0f} mm): an edit moved the "
                "limb too far from where it was planted; undo part of the edit"
                + ("" if self.adjust_root else ", or let the solver lower the root (adjust_root=True)"),
                UnreachableTargetWarning,
            )
        rot = np.array(motion.rotations, copy=True)
        rot[frames] = solved.rotations
        if not self.adjust_root:
            return motion.replace(rotations=rot)
        root = np.array(motion.root_positions, copy=True)
        root[frames] = solved.root_positions
        if tr is None:
            return motion.replace(rotations=rot, root_positions=root)
        # the root lowering may sit on the pelvis's translation (below a static reference root)
        trans = np.array(tr, copy=True)
        trans[frames] = solved.translations
        return motion.replace(rotations=rot, root_positions=root, translations=trans)
