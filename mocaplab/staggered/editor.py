"""The undoable staggered-pose editor behind the explorer widget (Coleman et al. 2008, section 5).

:class:`StaggeredEditor` is the thin stateful layer on top of the pure edit
functions of :mod:`~mocaplab.staggered.edit`: it holds a clip, its pose
analysis (:func:`~mocaplab.staggered.features.analyze`, computed once), the
representation fitted per pose count (:func:`~mocaplab.staggered.extract`)
and one immutable :class:`EditorParams` record of timing and geometric edit
parameters, pushed on a :class:`mocaplab.undo.UndoStack` at every accepted
change.  The current representation is always recomputed from the fitted
base by the same functions a script would call (exaggerate, then
succession, then randomize), so the editor and the functions agree.  The
widget (:class:`mocaplab.widgets.StaggeredExplorer`) forwards every control
to this class in one line.

Neighbours: this is the top of the staggered package; it imports
:mod:`~mocaplab.staggered.edit`, :mod:`~mocaplab.staggered.fit`,
:mod:`~mocaplab.staggered.features` and
:mod:`~mocaplab.staggered.representation`, and nothing there imports it.
"""

from __future__ import annotations

import dataclasses
import warnings
from collections.abc import Mapping, Sequence
from typing import Any, Literal

import numpy as np
from numpy.typing import NDArray

from .. import quat
from .._checks import integer
from ..motion import Motion
from ..roles import resolve_roles
from ..undo import Undoable, UndoStack
from .edit import check_tau, default_joint, exaggerate, randomize, succession
from .features import analyze
from .fit import extract
from .representation import StaggeredMotion, StaggeredTimingWarning

__all__ = ["EditorParams", "StaggeredEditor"]

Array = NDArray[np.float64]


@dataclasses.dataclass(frozen=True)
class EditorParams:
    """Everything a :class:`StaggeredEditor` edit sets: one immutable record per undo state.

    :attr:`StaggeredEditor.current` is a function of this record (and the
    clip): the base representation culled to ``max_poses`` poses, then
    ``exaggerate(w_r, joints=exaggerate_joints)``,
    ``succession(s, l, joint=joint)`` and
    ``randomize(tau, seed=seed, by=random_by)``, each skipped when neutral;
    ``staggered`` chooses the playback, ``constraints`` whether the contact
    constraint layer holds the feet where they were planted, and
    ``selected`` the pose overlaid.

    Parameters
    ----------
    max_poses : int or None
        Pose count of the culled base representation (None: every candidate).
    s, l : float
        Succession offset per depth level (seconds) and nonlinearity
        (:func:`~mocaplab.staggered.succession`).
    joint : str
        Joint the succession depth is measured from.
    tau : float
        Random timing bound, seconds (:func:`~mocaplab.staggered.randomize`).
    seed : int
        Seed of the random timing.
    random_by : {"variable", "limb"}
        One random offset per variable or per limb.
    w_r : float
        Exaggeration degree (:func:`~mocaplab.staggered.exaggerate`).
    exaggerate_joints : tuple of str, optional
        Variables exaggerated (None: every joint rotation).
    staggered : bool
        Play the staggered motion (True) or the non-staggered one.
    constraints : bool
        Apply the contact constraint layer.
    selected : int
        Index of the overlaid pose.

    Examples
    --------
    >>> import dataclasses
    >>> from mocaplab.staggered import EditorParams
    >>> p = EditorParams(max_poses=8)
    >>> dataclasses.replace(p, s=0.02).s, p.s
    (0.02, 0.0)
    """

    max_poses: int | None
    s: float = 0.0
    l: float = 1.0
    joint: str = ""
    tau: float = 0.0
    seed: int = 0
    random_by: Literal["variable", "limb"] = "variable"
    w_r: float = 0.0
    exaggerate_joints: tuple[str, ...] | None = None
    staggered: bool = True
    constraints: bool = True
    selected: int = 0


class StaggeredEditor(Undoable):
    """Stateful core of the staggered-pose explorer (the widget forwards to it).

    Holds a clip, its :class:`~mocaplab.staggered.features.PoseAnalysis`
    (computed once), the culled base representation and the current
    timing and geometric edit parameters (an :class:`EditorParams`
    record).  Every setter recomputes :attr:`current` from :attr:`base`, so
    edits never accumulate drift: :func:`~mocaplab.staggered.exaggerate`
    ``(base, w_r, joints=...)`` (against the average pose), then
    :func:`~mocaplab.staggered.succession` ``(s, l, joint=...)``, then
    :func:`~mocaplab.staggered.randomize` ``(tau, seed=...)``, each skipped
    when neutral.  A rejected
    edit changes nothing (parameters, :attr:`current`, history) and
    explains why in :attr:`message`, as do timing warnings.

    History: every accepted change of the record is pushed on a
    :class:`mocaplab.undo.UndoStack`; :meth:`undo`, :meth:`redo` and
    :meth:`reset` (undoable) restore a record, and :attr:`current` is
    recomputed from the same base, so it is restored exactly (the base of a
    pose count is fitted once and kept).  Consecutive changes of one
    parameter (a slider dragged) merge into one undo step until
    :meth:`checkpoint`; a change that leaves the record as it was pushes
    nothing.

    Parameters
    ----------
    motion : Motion
    max_poses : int, optional
        Initial pose count (culling); default every candidate.
    joint : str, optional
        Joint the succession depth is measured from (default the pelvis,
        :func:`default_joint`).
    random_joints : sequence of str, optional
        Joints affected by random timing (default every joint).
    random_by : {"variable", "limb"}
        One random offset per variable (default) or per limb
        (:func:`randomize`).
    curve_joint : str, optional
        Variable whose curves :meth:`curves` returns (default the pelvis;
        a view setting, not part of the history).
    roles : mapping, optional
        Joint-role overrides (:func:`mocaplab.roles.resolve_roles`) for the
        defaults: the pelvis, the contact joints, the constraint layer.
    constraints : bool
        Play the contact constraint layer (feet held where the clip planted
        them; :class:`ConstraintLayer`): on by default, and
        :meth:`set_constraints` turns it off and on (an undoable edit).  The
        layer is built whenever the clip has contacts (``contacts`` of
        ``extract_options``, default ``"auto"``), so turning it on later
        costs nothing.
    **extract_options
        Passed to :func:`~mocaplab.staggered.extract`.

    Examples
    --------
    >>> import mocaplab as ml
    >>> ed = ml.staggered.StaggeredEditor(ml.cmu("16_15").resample(30)[:60], max_poses=4)
    >>> ed.set_succession(s=0.02); ed.set_succession(s=0.04); ed.checkpoint()
    >>> ed.s
    0.04
    >>> ed.undo()                                   # both slider moves were one edit
    EditorParams(max_poses=4, s=0.0, ...)
    >>> ed.s
    0.0
    """

    #: Bases (one per pose count) kept for undo without refitting.
    BASE_CACHE = 8

    def __init__(
        self,
        motion: Motion,
        *,
        max_poses: int | None = None,
        joint: str | None = None,
        random_joints: Sequence[str] | None = None,
        random_by: Literal["variable", "limb"] = "variable",
        curve_joint: str | None = None,
        roles: Mapping[str, Any] | None = None,
        constraints: bool = True,
        **extract_options: Any,
    ) -> None:
        if not isinstance(motion, Motion):
            raise TypeError(f"Expected `motion` to be a Motion, got {type(motion).__name__}")
        if roles is not None:
            # pinned on the skeleton: analysis, extraction and edits all see them
            motion = motion.replace(skeleton=motion.skeleton.with_roles(**dict(resolve_roles(motion, roles))))
        self.motion = motion
        self._extract = extract
        self._options = dict(extract_options)
        contacts = self._options.pop("contacts", "auto")
        self.analysis = analyze(motion, contacts=contacts)
        # the layer is built once with every base (it needs contacts); `constraints` only chooses whether it plays
        # (analyze has already warned when the clip has no contact to hold)
        found = self.analysis.contacts
        self._options["constraints"] = found is not None and bool(np.any(found.mask))
        self.random_joints = None if random_joints is None else tuple(random_joints)
        if random_by not in ("variable", "limb"):
            raise ValueError(f"Expected `random_by` in ('variable', 'limb'), got {random_by!r}")
        joint = joint or default_joint(motion.skeleton)
        motion.skeleton.index(joint)
        self.curve_joint = curve_joint or default_joint(motion.skeleton)
        self._bases: dict[int | None, StaggeredMotion] = {}
        self.message = ""
        params = EditorParams(
            # as extract takes it (a count above the candidates keeps them all); set_pose_count is stricter
            max_poses=None if max_poses is None else integer(max_poses, "max_poses", low=2, high=motion.n_frames),
            joint=joint,
            random_by=random_by,
            constraints=bool(constraints),
        )
        self._params = params
        if not self._apply(params):
            raise ValueError(f"Expected a clip the editor can represent: {self.message}")
        self.undo_stack: UndoStack[EditorParams] = UndoStack(self._params)

    # ------------------------------------------------------------ the record
    @property
    def params(self) -> EditorParams:
        """The current edit parameters (an immutable record; the undo state)."""
        return self._params

    @property
    def max_poses(self) -> int | None:
        """Pose count (None: every candidate)."""
        return self._params.max_poses

    @property
    def s(self) -> float:
        """Succession offset per level of depth, seconds."""
        return self._params.s

    @property
    def l(self) -> float:  # noqa: E743 (the paper's name)
        """Succession exponent."""
        return self._params.l

    @property
    def joint(self) -> str:
        """Joint the succession depth is measured from."""
        return self._params.joint

    @property
    def tau(self) -> float:
        """Bound of the random timing offsets, seconds."""
        return self._params.tau

    @property
    def seed(self) -> int:
        """Seed of the random timing."""
        return self._params.seed

    @property
    def random_by(self) -> Literal["variable", "limb"]:
        """Random offsets per 'variable' or per 'limb'."""
        return self._params.random_by

    @property
    def w_r(self) -> float:
        """Relative exaggeration against the average pose."""
        return self._params.w_r

    @property
    def exaggerate_joints(self) -> tuple[str, ...] | None:
        """Joints exaggerated (None: all)."""
        return self._params.exaggerate_joints

    @property
    def staggered(self) -> bool:
        """Staggered (True) or non-staggered playback."""
        return self._params.staggered

    @property
    def constraints(self) -> bool:
        """The contact constraint layer plays (feet planted; on by default)."""
        return self._params.constraints

    @property
    def selected(self) -> int:
        """The pose overlaid in 3D."""
        return self._params.selected

    def _base(self, max_poses: int | None) -> StaggeredMotion:
        """The representation culled to ``max_poses`` poses, fitted once per count."""
        base = self._bases.get(max_poses)
        if base is None:
            base = self._extract(self.motion, max_poses=max_poses, analysis=self.analysis, **self._options)
            if len(self._bases) >= self.BASE_CACHE:
                self._bases.pop(next(k for k in self._bases if k != self._params.max_poses))
            self._bases[max_poses] = base
        return base

    def _apply(self, params: EditorParams) -> bool:
        """Make ``params`` current (recomputing from its base); False, with :attr:`message`, if rejected."""
        base = self._base(params.max_poses)
        params = dataclasses.replace(params, selected=min(params.selected, base.n_poses - 1))
        sm = base
        message = ""
        try:
            with warnings.catch_warnings(record=True) as caught:
                warnings.simplefilter("always", StaggeredTimingWarning)
                if params.w_r != 0.0:
                    sm = exaggerate(sm, params.w_r, joints=params.exaggerate_joints)
                if params.s != 0.0:
                    sm = succession(sm, params.s, params.l, joint=params.joint)
                if params.tau > 0.0:
                    sm = randomize(sm, params.tau, joints=self.random_joints, seed=params.seed, by=params.random_by)
            if caught:
                message = str(caught[-1].message)
        except ValueError as exc:
            self.message = f"edit rejected: {exc}"
            return False
        self._params, self.base, self.current, self.message = params, base, sm, message
        return True

    def _edit(self, merge: str, **changes: Any) -> None:
        """Apply a change of the record and push it (merged with the last push of the same ``merge`` key)."""
        new = dataclasses.replace(self._params, **changes)
        if new == self._params:
            return
        if self._apply(new):
            self.undo_stack.push(self._params, merge=merge)

    def _restore(self, params: EditorParams) -> None:
        if not self._apply(params):  # pragma: no cover - every state in the history was accepted once
            raise RuntimeError(f"Could not restore an earlier edit: {self.message}")

    # ------------------------------------------------------------- history
    def _go(self, params: EditorParams) -> EditorParams:
        self._restore(params)
        return self._params

    def _here(self) -> EditorParams:
        return self._params

    def _at_start(self) -> bool:
        return self._params == self.undo_stack.initial

    # ------------------------------------------------------------- setters
    @property
    def n_candidates(self) -> int:
        return int(self.analysis.candidates.size)

    def _pose_count(self, n: Any, name: str) -> int:
        """A pose count the clip holds: 2 (its first and last frames) to every candidate (TypeError/ValueError)."""
        return integer(
            n, name, low=2, high=self.n_candidates,
            why=f"the pose count `max_poses`: the clip's first and last frames and its {self.n_candidates - 2} "
            "candidate poses between",
        )

    def set_pose_count(self, n: int | None) -> None:
        """Cull to ``n`` poses (fits the representation once per count).

        ``n`` is an int from 2 to :attr:`n_candidates` (or None: every
        candidate); anything else raises before anything is fitted or recorded.
        """
        self._edit("max_poses", max_poses=None if n is None else self._pose_count(n, "n"))

    def set_succession(self, s: float | None = None, l: float | None = None, joint: str | None = None) -> None:
        """Set the succession offset ``s`` (seconds), exponent ``l`` and/or the depth joint."""
        changes: dict[str, Any] = {}
        if s is not None:
            changes["s"] = float(s)
        if l is not None:
            changes["l"] = float(l)
        if joint is not None:
            self.motion.skeleton.index(joint)
            changes["joint"] = joint
        self._edit("succession:" + ",".join(sorted(changes)), **changes)

    def set_random(
        self, tau: float | None = None, seed: int | None = None, by: Literal["variable", "limb"] | None = None
    ) -> None:
        """Set the random timing bound ``tau`` (seconds), the seed and/or per variable or per limb.

        ``tau`` from 0 to the clip's duration
        (:func:`~mocaplab.staggered.edit.check_tau`) and ``seed`` an integer
        >= 0: anything else raises TypeError/ValueError naming it, and
        nothing is recorded.
        """
        changes: dict[str, Any] = {}
        if tau is not None:
            changes["tau"] = check_tau(self.base, tau)  # a bad bound raises; nothing is recorded
        if seed is not None:
            changes["seed"] = integer(seed, "seed", low=0)
        if by is not None:
            if by not in ("variable", "limb"):
                raise ValueError(f"Expected `by` in ('variable', 'limb'), got {by!r}")
            changes["random_by"] = by
        self._edit("random:" + ",".join(sorted(changes)), **changes)

    def set_exaggeration(self, w_r: float, joints: Sequence[str] | None = None) -> None:
        """Relative exaggeration of every pose against the average pose."""
        changes: dict[str, Any] = {"w_r": float(w_r)}
        if joints is not None:
            changes["exaggerate_joints"] = tuple(joints)
        self._edit("exaggeration:" + ",".join(sorted(changes)), **changes)

    def set_staggered(self, on: bool) -> None:
        """Staggered (True) or non-staggered (refinements zeroed) playback."""
        self._edit("staggered", staggered=bool(on))

    def set_constraints(self, on: bool) -> None:
        """Play the contact constraint layer (True: feet held where the clip planted them) or not."""
        self._edit("constraints", constraints=bool(on))

    def select(self, k: int) -> None:
        """Select pose ``k`` (for the 3D overlay); successive selections are one undo step."""
        self._edit("select", selected=self.current._pose_index(int(k)))

    def set_curve_joint(self, name: str) -> None:
        """Choose the variable :meth:`curves` returns (a view setting: not recorded in the history)."""
        self.current.variable_index(name)
        self.curve_joint = name

    # ------------------------------------------------------------- outputs
    @property
    def playback(self) -> StaggeredMotion:
        """The representation played: current, or with refinements zeroed."""
        return self.current if self.staggered else self.current.zero_refinements()

    def evaluate(self) -> Motion:
        """The dense motion being played (with the constraint layer when :attr:`constraints`)."""
        return self.current.evaluate(staggered=self.staggered, constraints=self.constraints)

    def curves(self, name: str | None = None) -> dict[str, Any]:
        """Curves of one variable for plotting.

        Returns a dict with ``"t"`` (F,), ``"values"`` (F, 3) (a root
        position or joint translation in metres, or the rotation vector
        ``log(q)`` in radians), ``"kind"`` (``"translation"`` or
        ``"rotation"``), ``"pose_times"`` (K,), ``"knot_times"`` (K,) and
        ``"knot_values"`` (K, 3) of the refined knots as played, and
        ``"original"`` (F0, 3) with ``"t0"`` of the source clip.
        """
        name = name or self.curve_joint
        sm = self.playback
        i = sm.variable_index(name)
        motion = self.evaluate()
        J = sm.n_joints

        def series(m: Motion) -> Array:
            if i == 0:
                return np.asarray(m.root_positions)
            if i > J:  # a translation variable: the clip has translation channels
                return np.asarray(m.translations)[:, sm.translation_joints[i - J - 1]]
            return quat.log(quat.unroll(m.rotations[:, i - 1], axis=0))

        act = sm.active[:, i]
        knots = (sm.times + sm.refinements[:, i])[act]
        vals = series(motion)
        return {
            "t": motion.times,
            "values": vals,
            "kind": "translation" if sm.is_translation(i) else "rotation",
            "pose_times": np.asarray(sm.times),
            "knot_times": knots,
            "knot_values": np.stack([np.interp(knots, motion.times, vals[:, d]) for d in range(3)], axis=1),
            "t0": self.motion.times,
            "original": series(self.motion),
        }

    def pose_table(self) -> list[tuple[int, float, float, int]]:
        """Rows ``(k, t_k, priority w_k, number of refined knots)``."""
        sm = self.current
        ek = sm.editing_knots.sum(axis=1)
        return [(k, float(sm.times[k]), float(sm.priorities[k]), int(ek[k])) for k in range(sm.n_poses)]

    def overlay(self, k: int | None = None) -> tuple[Motion, Motion]:
        """(non-staggered pose, true pose at t_k) of the selected pose, one frame each (Figure 6)."""
        k = self.selected if k is None else int(k)
        return (self.current.pose_motion(k, which="non-staggered"), self.current.pose_motion(k, which="true"))
