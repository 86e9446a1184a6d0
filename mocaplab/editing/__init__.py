"""Synchronized multi-character path editing and time warping (Kim et al. 2009).

Sections 3, 4.1, 4.2 and 4.4 of Kim, Hyun, Kim and Lee 2009,
"Synchronized multi-character motion editing": every character's root path is
deformed by Laplacian (as-rigid-as-possible) curve editing and its timing by a
1D Laplacian time warp, all characters in ONE sparse system, under soft
(weighted least squares) and hard (Lagrange multiplier) constraints.

API summary (names are stable; lessons and widgets code against them)
--------------------------------------------------------------------
Conventions: ground positions are ``(x, z)`` in metres, times in seconds on a
shared *reference clock*, frames are indices into each character's own clip,
characters are indices into the ``motions`` sequence.  Directions on the
ground are 2-vectors ``(x, z)`` or yaw angles in radians (``atan2(x, z)``, the
convention of :func:`mocaplab.quat.yaw`).  Local frames are ``(forward, left)``:
forward along the path tangent, left along the normal ``R t`` (tangent turned
+90 degrees about +Y).

Any skeleton
    The "root" of a path is the motion's path joint,
    :attr:`mocaplab.motion.Motion.path_joint` (the ``pelvis`` role of
    :mod:`mocaplab.roles`; joint 0 for CMU, the travelling pelvis below a
    static reference joint in other exports), and the feet are the roles'
    ankles and toes: no joint name is needed anywhere.  Every entry point
    takes ``roles=`` (role overrides, one mapping or one per character) for
    skeletons whose roles cannot be inferred.  Per-joint translations
    (``Motion.translations``) are carried through every operation.

Paths (:mod:`mocaplab.editing.paths`)
    ``MotionPath.from_motion(motion, *, min_speed=0.1, roles=None) -> MotionPath`` with
    ``.positions (F, 2)``, ``.tangents (F, 2)`` (central differences
    ``p[i+1] - p[i-1]``, degenerate ones interpolated), ``.normals (F, 2)``,
    ``.directions (F,)`` root heading relative to the tangent (radians),
    ``.headings (F,)``, ``.degenerate (F,) bool``, ``.fps``, ``.length``,
    ``.laplacian_coordinates() -> (F, 2)`` (eq. 3; NaN at the two ends),
    ``.local_offset(frame, point) -> (forward, left)``, ``.local_direction(frame,
    vector)``, ``.from_local(frame, offset) -> (2,)``, ``.with_positions(p)``,
    ``.tangent_operator() -> sparse (F, F)``.
    ``stationary_segments(motion, *, speed=0.15, min_duration=0.3, contacts=None,
    joints=None, roles=None) -> list[(start, stop)]`` (half-open; ``contacts="auto"``
    adds both-feet-planted, on ``joints`` or the roles' feet).
    ``apply_path(motion, positions (F, 2), heading_change (F,)) -> Motion`` (a
    per-frame rigid ground motion putting the path joint on the new path),
    ``contact_joints(motion, joints=None, *, roles=None)``, ``with_roles(motion, roles)``.

Constraints (:mod:`mocaplab.editing.constraints`), frozen dataclasses
    ``PinPosition(character, frame, position, *, hard=False, weight=1.0, frames=None)``
    ``PinDirection(character, frame, direction, *, hard=False, weight=1.0, frames=None)``
    ``Relative(character, frame, other, other_frame, offset, *, direction=None,
    hard=False, weight=1.0, frames=None, other_frames=None)`` (offset = (forward, left)
    metres in the tangent frame of ``other`` at ``other_frame``, on the edited
    path; ``direction`` a (forward, left) vector or an angle ``a``, ``(cos a,
    sin a)``; eqs. 1-2)
    ``AbsoluteTime(character, frame, time, *, hard=False, weight=1.0, frames=None)``
    ``Duration(character, frame, end_frame, duration, *, hard=False, weight=1.0)``
    ``Sync(character, frame, other, other_frame, *, offset=0.0, hard=False,
    weight=1.0, frames=None, other_frames=None)`` (``t[frame] = t_other[other_frame] + offset``)
    End effectors: ``EndEffectorConstraint(character, joint=..., frame=i or
    frames=(a, b), target=...)`` (or wrapping a :class:`mocaplab.goals.EndEffector`,
    which may also go straight into the list); path editing ignores them,
    ``EditResult.end_effectors[k]`` records them and ``EditResult.refined()``
    hands them to :func:`mocaplab.editing.refinement.refine_scene`.
    Variational form by keyword: ``PinPosition(0, position=p, frames=(30, 91))``,
    ``Relative(1, other=0, offset=(0.0, 0.6), frames=(30, 91))``; sampled every
    10th frame, the last one included.  Intervals ``frames=(start, stop)`` are
    half-open, as everywhere in mocaplab (``(30, 91)``: frames 30 to 90); both
    ends included is spelt ``frames_inclusive=(30, 90)``.  Every constraint has ``.target``,
    ``.with_target(new_target)``, ``.hard``, ``.weight``, ``.characters``.
    ``ConstraintError(ValueError)`` with ``.constraints`` (the offending ones)
    and ``.indices``: inconsistent hard constraints (redundant but consistent
    ones are accepted, their rows left out and checked: ``EditResult.notes``).

Editing (:mod:`mocaplab.editing.scene`)
    ``edit(motions, constraints, *, discrete=False, **options) -> EditResult``
    (``discrete``: see below), ``make_editor(motions, constraints, *,
    discrete=False, **options)`` (a SceneEditor, or a DiscreteEditor),
    ``SceneEditor(motions, constraints=(), **options)`` (continuous only) with
    ``.drag(constraint_index, new_target) -> EditResult``, ``.add(constraint) -> int``,
    ``.remove(index) -> EditResult``, ``.replace(index, constraint) -> EditResult``,
    ``.set_constraints(constraints) -> EditResult``, ``.evaluate(motions,
    constraints) -> EditResult`` (fresh, state untouched), ``.result``,
    ``.constraints``, ``.characters``, ``.paths`` (input MotionPaths),
    ``.segments`` (rigid stationary segments), ``.options``,
    ``.factorizations`` (how many factorisations so far; a target drag adds
    none), ``.contact_joints(k)`` (the joints whose foot contacts are kept),
    ``.snapshot()``/``.restore(state)``, and a history (:mod:`mocaplab.undo`):
    ``.undo()``, ``.redo()``, ``.reset()`` (undoable), ``.checkpoint()`` (end a
    gesture: drags of one constraint merge into one undo step until then;
    it settles relative constraints, ``.settle()``),
    ``.can_undo``, ``.can_redo``, ``.undo_stack``; a DiscreteEditor has the
    same (its steps include the transformations a drag applied).
    A failed update (ConstraintError) leaves the editor unchanged and records nothing.
    ``EditResult``: ``.paths[k] (F_k, 2)``, ``.times[k] (F_k,)``, ``.motions[k]``
    (lazy; all on one shared clock ``.clock (N,)``, pose held outside each
    character's own span, ``.active[k] (N,) bool``), ``.shape_paths[k]``
    (phase-1 result), ``.tangents[k]``, ``.heading_change[k] (F_k,)``,
    ``.flips[k] (F_k,) bool`` (repaired tangent flips), ``.stationary[k]``,
    ``.edited_motions[k]`` (edited, not time-warped), ``.residuals() -> {index: max |r|}``,
    ``.constraints``, ``.transformations`` (section 5 discrete edits, see below),
    ``.end_effectors[k]``, ``.refined()`` (full-body refined motions on the
    clock), ``.original_paths``, ``.report() -> dict`` and attributes
    ``hard_residual_space, hard_residual_time, soft_residual_space,
    soft_residual_time, shape_distortion, length_change (K,), min_time_step``,
    ``min_time_step_ratio``, ``.energies -> Energies(shape, scale, time)``,
    ``.notes``, ``.settled``, ``.with_transformations(ts)``; immutable.
    Options: ``scale_compensation=True, stationary="auto", min_step=0.25,
    max_step=4.0`` (ratios of the frame time), ``flip_rate=900`` (degrees
    per second), ``flip_window=1.0`` (s), ``relative_tolerance=1e-3`` (m),
    ``relative_iterations=20``, ``relative_drag_iterations=2`` (solves per drag;
    ``SceneEditor.settle()``, called by ``checkpoint()``, settles the rest),
    ``variational_step=10, clock_fps=None,
    start_times=None``, ``refine=False``,
    ``roles=None`` (role overrides), ``joints=None`` (contact joints for
    ``stationary="auto"`` and refinement; default the roles' feet).
    Modes no constraint determines (a character's placement, its time
    shift) keep their undeformed values exactly.

Energy (:mod:`mocaplab.editing.energy`)
    ``deformation_energy(result, *, cs=1.0, ct=1.0, reference=None) -> float`` (eq. 10).

Discrete editing (section 5; :mod:`mocaplab.editing.graph`, the package :mod:`mocaplab.editing.discrete`)
    ``build_graph(motions, *, weights=None, threshold=0.1, window=0.5, min_gap=0.3,
    chunk=1024, roles=None) -> MotionGraph`` (frame similarity of joint angles, root height and
    orientation, joint and root velocities; local minima below ``threshold`` kept,
    stored sparsely, built in row chunks), ``MotionGraph`` with ``.clips``,
    ``.offsets``, ``.pairs (M, 2)``, ``.costs (M,)``, ``.n_frames``,
    ``.transitions() -> (src, dst, cost)``, ``.clip_index(motion)``.
    ``DiscreteEditor(motions, constraints, discrete=True or DiscreteOptions(...),
    **options)`` (the SceneEditor interface) or ``edit(..., discrete=True)``
    runs the greedy Algorithm 1 after every constraint update: at most one
    transformation per update, the best of all pruned candidates by the
    equation-10 energy on subsampled paths; ``.tracks``, ``.applied``,
    ``.history`` (``Step`` records), ``.timings`` (``Timing`` records), ``.scene``
    (the continuous editor of the transformed scene).
    ``DiscreteOptions(*, graphs=None, locality=Locality(), min_duration=0.3,
    max_duration=2.0, cs=1.0, ct=1.0, subsample=25, blend=0.2, min_gain=0.1,
    max_initial=8, verify=3, verify_subsample=5, threshold=0.1, window=0.5,
    min_gap=0.3, weights=None)``;
    ``Locality(characters=None, types=TYPES, time_zones=None, regions=None)`` with
    regions ``Box(lo, hi)`` and ``Disk(center, radius)`` (ground ``(x, z)``);
    ``Transformation(character, kind, removed=(a, b), inserted=(s, e), fps, ...)``
    with ``kind`` in ``"deletion", "insertion", "duplication", "replacement"``,
    ``.frames``, ``.span``, ``.removed_duration``, ``.inserted_duration``,
    ``.length_change``, ``.energy``, ``.baseline``, ``.update``.
    With discrete editing on, ``EditResult.transformations`` lists every
    transformation applied so far (character, type, frame ranges), and
    ``EditResult.characters`` are the transformed clips (constraints follow
    their frames).  Lower-level pieces (``enumerate_transformations``,
    ``prune``, ``pruning_violations``, ``apply_transformation``, ``Track``,
    ``SubsampledScene``) are in :mod:`mocaplab.editing.discrete`.

The discrete names are imported on first use (``mocaplab.editing.DiscreteEditor``
loads :mod:`~mocaplab.editing.discrete`), so ``import mocaplab.editing`` does not
pay for them.
"""

from __future__ import annotations

from collections.abc import Sequence
from types import MappingProxyType
from typing import TYPE_CHECKING, Any

from .constraints import (
    AbsoluteTime,
    Constraint,
    ConstraintError,
    Duration,
    EndEffectorConstraint,
    PinDirection,
    PinPosition,
    Relative,
    Sync,
)
from .energy import Energies, deformation_energy
from .paths import MotionPath, stationary_segments
from .scene import EditResult, PathJumpWarning, RelativeConflictWarning, SceneEditor
from .scene import edit as _continuous_edit

if TYPE_CHECKING:
    from .discrete import Box, DiscreteEditor, DiscreteOptions, Disk, Locality, Transformation
    from .graph import MotionGraph, build_graph

_LAZY = MappingProxyType({
    "Box": "discrete",
    "DiscreteEditor": "discrete",
    "DiscreteOptions": "discrete",
    "Disk": "discrete",
    "Locality": "discrete",
    "Transformation": "discrete",
    "MotionGraph": "graph",
    "build_graph": "graph",
})

__all__ = [
    "AbsoluteTime",
    "Box",
    "Constraint",
    "ConstraintError",
    "PathJumpWarning",
    "RelativeConflictWarning",
    "DiscreteEditor",
    "DiscreteOptions",
    "Disk",
    "Duration",
    "EditResult",
    "EndEffectorConstraint",
    "Energies",
    "Locality",
    "MotionGraph",
    "MotionPath",
    "PinDirection",
    "PinPosition",
    "Relative",
    "SceneEditor",
    "Sync",
    "Transformation",
    "build_graph",
    "deformation_energy",
    "edit",
    "make_editor",
    "stationary_segments",
]


def make_editor(motions: Any, constraints: Sequence[Any] = (), *, discrete: Any = False, **options: Any) -> Any:
    """An interactive editor: a :class:`SceneEditor`, or a :class:`~mocaplab.editing.discrete.DiscreteEditor`.

    Parameters
    ----------
    motions : Motion or sequence of Motion
    constraints : sequence of constraints
    discrete : bool or DiscreteOptions
        False: continuous editing only; True or a
        :class:`~mocaplab.editing.discrete.DiscreteOptions`: section 5 too.
    **options
        Options of :class:`SceneEditor` (:mod:`mocaplab.editing.scene`).

    Returns
    -------
    SceneEditor or DiscreteEditor

    Examples
    --------
    >>> from mocaplab.data import cmu
    >>> walk = cmu("16_15")
    >>> pin = PinPosition(0, 0, walk.root_positions[0, [0, 2]], hard=True)
    >>> type(make_editor([walk], [pin])).__name__, type(make_editor([walk], [pin], discrete=True)).__name__
    ('SceneEditor', 'DiscreteEditor')
    """
    if discrete is False or discrete is None:
        return SceneEditor(motions, constraints, **options)
    from .discrete import DiscreteEditor

    return DiscreteEditor(motions, constraints, discrete=discrete, **options)


def edit(motions: Any, constraints: Sequence[Any] = (), *, discrete: Any = False, **options: Any) -> EditResult:
    """Edit the paths and timing of the characters ``motions`` under ``constraints`` (one shot).

    ``make_editor(motions, constraints, discrete=discrete, **options).result``:
    continuous Laplacian editing (:func:`mocaplab.editing.scene.edit`), and
    with ``discrete`` on, Algorithm 1 run to convergence (up to
    ``DiscreteOptions.max_initial`` transformations).

    Parameters
    ----------
    motions : Motion or sequence of Motion
        The characters (never modified).
    constraints : sequence of constraints
        :mod:`~mocaplab.editing.constraints` objects; ``[]`` edits with none.
    discrete : bool or DiscreteOptions
        False (default): continuous editing only; True or a
        :class:`~mocaplab.editing.discrete.DiscreteOptions`: section 5 too.
    **options
        Options of :class:`SceneEditor` (:mod:`mocaplab.editing.scene`),
        each checked before any work.

    Returns
    -------
    EditResult

    Examples
    --------
    Pin a walk's first frame and move its last frame 1 m along x:

    >>> import numpy as np
    >>> from mocaplab.data import cmu
    >>> walk = cmu("16_15")
    >>> ends = walk.root_positions[[0, -1]][:, [0, 2]]
    >>> res = edit([walk], [PinPosition(0, 0, ends[0], hard=True), PinPosition(0, 470, ends[1] + (1.0, 0.0))])
    >>> (np.round(res.paths[0][-1] - ends[1], 3) + 0.0).tolist(), res.transformations
    ([1.0, 0.0], ())
    """
    if discrete is False or discrete is None:
        return _continuous_edit(motions, constraints, **options)
    return make_editor(motions, constraints, discrete=discrete, **options).result


def __getattr__(name: str) -> Any:
    # the section-5 names load their modules on first use (import mocaplab.editing stays light)
    module = _LAZY.get(name)
    if module is None:
        raise AttributeError(f"module 'mocaplab.editing' has no attribute {name!r}")
    from importlib import import_module

    return getattr(import_module(f"{__name__}.{module}"), name)  # sys.modules caches the module


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(__all__))
