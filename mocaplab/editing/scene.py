"""Edit a scene of characters: :func:`edit` and the interactive :class:`SceneEditor`.

``edit(motions, constraints)`` deforms every character's root path
(:mod:`~mocaplab.editing.laplacian`) and time warp
(:mod:`~mocaplab.editing.timewarp`) under the given constraints and returns an
:class:`EditResult`.  :class:`SceneEditor` keeps the factorised systems
between calls: dragging a constraint's target only changes right-hand sides,
so an update costs a few back-substitutions.  ``edit`` is a one-shot
``SceneEditor(...).result``; tests check that both agree.

Back to full-body motion (``EditResult.motions``, computed on first access):
each frame of each character is moved by one rigid ground motion
(:func:`~mocaplab.editing.paths.apply_path`): it turns by the change of the
path's tangent direction (so the heading relative to the path is kept) and
translates so that the path joint (the pelvis role,
:attr:`~mocaplab.motion.Motion.path_joint`) lands on its edited ground
position, height kept; then the clip is resampled (slerp for rotations,
linear for positions and per-joint translations) on one shared reference
clock from its time warp, so all characters play synchronised:
``motions[k]`` has one frame per clock tick ``clock[n]``, holding the first /
last pose outside the character's own time span (``active[k]`` marks the
ticks inside it).

Options (keyword-only, for both :func:`edit` and :class:`SceneEditor`)
----------------------------------------------------------------------
Every option is checked when the editor is built, before any path,
contact or solve (``_checked_options``: a TypeError for the wrong kind, a
ValueError for NaN, infinity or a value out of range, each naming the
option); ``constraints`` is a list or tuple, ``[]`` for none (``None`` is
refused, not read as none).

scale_compensation : bool, default True
    Run phase 2 (equation 7) after the shape-preserving phase.
stationary : "auto", "speed", None, or per-character lists of (start, stop)
    Stationary sub-paths made rigid (section 4.2).  "auto": root slower than
    ``stationary_speed`` or both feet planted
    (:func:`mocaplab.contacts.foot_contacts`) for at least
    ``stationary_min_duration`` s; "speed": speed only; None: none.
stationary_speed : float, default 0.15 (m/s)
stationary_min_duration : float, default 0.3 (s)
min_speed : float, default 0.1 (m/s)
    Tangent degeneracy threshold (:class:`~mocaplab.editing.paths.MotionPath`).
min_step, max_step : float, default 0.25 and 4.0
    Time-step bounds as ratios of each clip's frame time (section 4.4).
flip_rate : float or None, default 900.0 (degrees per second)
    Tangent-flip detection rate (section 4.2; the paper's 30 degrees per
    frame at 30 fps): a jump of the deformed tangent's angle to the
    undeformed one between two frames larger than ``flip_rate / fps`` is a
    flip, and the repaired heading turns at most this much faster than the
    input did, at any frame rate
    (:func:`~mocaplab.editing.flips.detect_tangent_flips`).  ``None``
    switches the repair off.
flip_window : float, default 1.0
    Seconds: the longest reversed stretch between two paired jumps that is
    repaired as one fold; from 0 to 10 times the scene's duration.
relative_tolerance : float, default 1e-3
    Metres: relative constraints are re-solved until their metric
    corrections change by less than this (see
    :mod:`~mocaplab.editing.laplacian`, "Relative constraints in metres").
relative_iterations : int, default 20
    Most solves per update for that (>= 1).
relative_drag_iterations : int, default 2
    Most solves a :meth:`SceneEditor.drag` makes for that (>= 1):
    a drag warm-starts from the previous update and may stop before the
    targets settle (``EditResult.settled`` False); when the gesture ends the
    editor solves them as :func:`edit` does, up to ``relative_iterations``
    solves (:meth:`SceneEditor.settle`, called by ``checkpoint()``, which
    the widgets call on mouse release), so the settled edit does not depend
    on the drags that led to it (``benchmarks/bench_laplacian.py``: a
    formation of 1000 tied walkers).
variational_step : int, default 10
    Sampling step of variational constraints (frames, >= 1).
start_times : sequence of float, optional
    Reference time of each character's frame 0 before editing (default 0),
    within :func:`~mocaplab.editing.timewarp.time_reach` of 0 (10 times the
    scene's duration), as are the time targets of the constraints (see
    :mod:`~mocaplab.editing.timewarp`, "How far times may reach").
clock_fps : float, optional
    Rate of the shared clock of ``motions`` (default: character 0's fps),
    from 0.1 to :data:`MAX_CLOCK_FPS` (1000) frames per second.  The clock
    may hold at most :data:`MAX_CLOCK_FRAMES` frames over all characters
    (a ``ValueError`` when ``motions`` are built, before any allocation).
refine : bool, default False
    ``motions`` are the full-body refined ones (:meth:`EditResult.refined`).
refine_tolerance : float, default 1e-3 (m)
    Incremental refinement: a character keeps the refined motion the editor
    last computed for it (the same object) while its path stays within this
    distance of the path that motion was refined on, its frame times within
    1 microsecond, its end effectors and the shared clock the same; only the
    others are refined again (see :class:`RefineCache`).  0 refines a
    character again whenever its path moved at all.
roles : mapping of role name to joint name, or one per character, optional
    Joint roles fixed by hand (:func:`mocaplab.roles.resolve_roles`), for
    skeletons whose roles cannot be inferred: the characters' skeletons get
    them (:func:`~mocaplab.editing.paths.with_roles`), so the path joint
    (``pelvis``) and the feet follow them.  ``EditResult.characters`` and
    the edited motions carry them.
joints : sequence of str, or one per character, optional
    The joints whose foot contacts are detected and kept: the "both feet
    planted" test of ``stationary="auto"`` and the plants of full-body
    refinement (``refine``, :meth:`EditResult.refined`).  Default: the
    ankle and toe of each foot of the roles
    (:func:`~mocaplab.editing.paths.contact_joints`).

Longer than 800 lines because the scene editor, its result and its incremental refinement cache share the editor's state (factorisations, clocks, per-character caches) and are tested together against the one-shot :func:`edit`.
"""

from __future__ import annotations

import copy
import dataclasses
import math
from collections import OrderedDict
from collections.abc import Iterator, Mapping, Sequence
from functools import cached_property
from types import MappingProxyType
from typing import Any

import numpy as np
from numpy.typing import NDArray

from .._checks import integer, real
from .._warnings import warn
from ..contacts import foot_contacts
from ..goals import EndEffector
from ..motion import FPS_RANGE, Motion
from ..undo import Undoable, UndoStack
from ._threads import single_blas_thread
from .constraints import (
    SPATIAL,
    TEMPORAL,
    ConstraintError,
    EndEffectorConstraint,
    PinPosition,
    Relative,
    effector_frames,
)
from .energy import Energies
from .flips import flip_step, heading_changes
from .laplacian import spatial_rows
from .lsq import Rows
from .paths import MotionPath, apply_path, contact_joints, laplacian_coordinates, stationary_segments, with_roles
from .refinement import refine_scene
from .spatial import SpatialFactors, SpatialSolution, SpatialSolver
from .timewarp import TIME_REACH, TimeFactors, TimeSolver, temporal_rows, time_reach

__all__ = [
    "edit",
    "SceneEditor",
    "EditResult",
    "RefineCache",
    "PathJumpWarning",
    "PinPlacementWarning",
    "RelativeConflictWarning",
    "MAX_CLOCK_FPS",
    "MAX_CLOCK_FRAMES",
]

Array = NDArray[np.float64]

#: Highest ``clock_fps``: ten times any capture rate the lessons use, and a bound on the work of resampling.
MAX_CLOCK_FPS = 1000.0
#: Most frames the edited motions on the shared clock may hold, summed over the characters (about 2.3 hours
#: of one character at 120 fps), checked before they are built.
MAX_CLOCK_FRAMES = 1_000_000

_OPTIONS: Mapping[str, Any] = MappingProxyType(
    {
        "scale_compensation": True,
        "stationary": "auto",
        "stationary_speed": 0.15,
        "stationary_min_duration": 0.3,
        "min_speed": 0.1,
        "min_step": 0.25,
        "max_step": 4.0,
        "flip_rate": 900.0,
        "flip_window": 1.0,
        "relative_tolerance": 1e-3,
        "relative_iterations": 20,
        "relative_drag_iterations": 2,
        "variational_step": 10,
        "start_times": None,
        "clock_fps": None,
        "refine": False,
        "refine_tolerance": 1e-3,
        "roles": None,
        "joints": None,
    }
)

_UNDO_LIMIT = 200  # undo steps kept (each holds a result)
_WARM_RESULTS = 4  # results of the most recently current undo states that keep their built motions


class WarmResults:
    """The few most recently current results keep their lazily built motions; older ones release them.

    An undo state holds its :class:`EditResult`; the full-body motions it
    built on demand (and their cached global positions) are megabytes per
    step for a crowd.  An editor calls :meth:`touch` with its current result
    after every recorded edit, undo, redo and reset; the result that falls
    out of the ``size`` most recent ones drops those caches
    (:meth:`EditResult.release`), so the history holds paths, times and
    solver state only and rebuilds the motions, bitwise the same, when the
    state is current again.
    """

    def __init__(self, size: int = _WARM_RESULTS) -> None:
        self._size = int(size)
        self._results: list[EditResult] = []

    def touch(self, result: EditResult, *, replaces: bool = False) -> None:
        """``result`` is current; ``replaces``: its state took the place of the newest one (a merged drag)."""
        rest = self._results[1:] if replaces else self._results
        self._results = [result] + [r for r in rest if r is not result]
        for old in self._results[self._size :]:
            old.release()
        del self._results[self._size :]


_TIME_TOLERANCE = 1e-6  # seconds: frame times closer than this count as unchanged for refinement


class RefineCache:
    """Refined motions per character, kept between edits so only what changed is refined again.

    Full-body refinement (:func:`mocaplab.editing.refinement.refine_scene`) costs
    tens of milliseconds per character; a drag usually moves one character
    (and, through soft relative constraints, its neighbours a little).  Each
    entry remembers what a character was refined from: the shared clock
    (first tick, rate, length), the character's edited path and frame
    times, and its end-effector constraints (by identity).  A later result
    reuses the refined motion itself when the clock and the end effectors
    are the same, the frame times within :data:`_TIME_TOLERANCE` and the
    path within ``tolerance`` metres; characters tied by end effectors
    relative to one another (:class:`~mocaplab.goals.RelativeTo` of
    another character) are refined, or reused, together.

    The time-warped input clips and their foot contacts (the references of
    refinement) depend on the frame times only and are kept the same way.

    Parameters
    ----------
    tolerance : float
        Metres a path may move and still keep its refined motion.
    """

    def __init__(self, tolerance: float) -> None:
        tolerance = float(tolerance)
        if not (math.isfinite(tolerance) and tolerance >= 0.0):
            raise ValueError(f"Expected `refine_tolerance` >= 0 metres, got {tolerance!r}")
        self.tolerance = tolerance
        self._motions: dict[int, tuple[tuple[float, float, int], Array, Array, tuple[Any, ...], Motion]] = {}
        self._references: dict[int, tuple[tuple[float, float, int], Array, Any]] = {}
        #: How many characters were refined (not reused) so far.
        self.refined = 0

    def motion(self, k: int, clock: tuple[float, float, int], path: Array, times: Array, ees: tuple[Any, ...]) -> Any:
        """Character ``k``'s refined motion if its inputs are those it was refined from (within tolerance), else None."""
        entry = self._motions.get(k)
        if entry is None:
            return None
        c, p, t, e, motion = entry
        if c != clock or len(e) != len(ees) or any(a is not b for a, b in zip(e, ees, strict=True)):
            return None
        if p.shape != path.shape or t.shape != times.shape:
            return None
        if np.max(np.abs(t - times), initial=0.0) > _TIME_TOLERANCE:
            return None
        if np.max(np.linalg.norm(p - path, axis=-1), initial=0.0) > self.tolerance:
            return None
        return motion

    def store(
        self, k: int, clock: tuple[float, float, int], path: Array, times: Array, ees: tuple[Any, ...], motion: Motion
    ) -> None:
        """Remember ``motion`` as character ``k``'s refinement of these inputs."""
        self._motions[k] = (clock, np.array(path, dtype=float), np.array(times, dtype=float), tuple(ees), motion)
        self.refined += 1

    def reference(self, k: int, clock: tuple[float, float, int], times: Array, make: Any) -> Any:
        """``make()`` (the warped input and its contacts), or what it returned for the same clock and times."""
        entry = self._references.get(k)
        if entry is not None and entry[0] == clock and entry[1].shape == times.shape:
            if np.max(np.abs(entry[1] - times), initial=0.0) <= _TIME_TOLERANCE:
                return entry[2]
        value = make()
        self._references[k] = (clock, np.array(times, dtype=float), value)
        return value


def _renumbered(ee: EndEffector, local: Mapping[int, int]) -> EndEffector:
    """``ee`` with its character (and a RelativeTo's other character) numbered within its group."""
    target = ee.target
    other = getattr(target, "character", None)
    if other is not None:
        target = dataclasses.replace(target, character=local[int(other)])  # type: ignore[type-var]
    return dataclasses.replace(ee, character=local[ee.character], target=target)


def _effector_groups(end_effectors: Sequence[Sequence[EndEffector]]) -> list[list[int]]:
    """Characters tied by end effectors relative to another character's joint, as sorted groups (union-find)."""
    K = len(end_effectors)
    root = list(range(K))

    def find(a: int) -> int:
        while root[a] != a:
            root[a] = root[root[a]]
            a = root[a]
        return a

    for k, per in enumerate(end_effectors):
        for ee in per:
            other = getattr(ee.target, "character", None)
            if other is not None and 0 <= int(other) < K:
                root[find(k)] = find(int(other))
    groups: dict[int, list[int]] = {}
    for k in range(K):
        groups.setdefault(find(k), []).append(k)
    return list(groups.values())


def _effectors(constraints: Sequence[Any], K: int) -> tuple[tuple[EndEffector, ...], ...]:
    """End-effector constraints per character (as :class:`mocaplab.goals.EndEffector`)."""
    ee: list[list[EndEffector]] = [[] for _ in range(K)]
    for c in constraints:
        if isinstance(c, EndEffectorConstraint):
            ee[c.character].append(c.constraint)
        elif isinstance(c, EndEffector):
            ee[c.character].append(c)
    return tuple(tuple(x) for x in ee)


def _per_character(value: Any, K: int, name: str, single: Any) -> list[Any]:
    """An option given once for every character (``single(value)`` is true) or as one entry per character."""
    if value is None or single(value):
        return [value] * K
    try:
        items = list(value)
    except TypeError:
        raise TypeError(f"Expected `{name}` for every character or one per character, got {value!r}") from None
    if len(items) != K:
        raise ValueError(f"Expected `{name}` for every character or one entry per character ({K}), got {len(items)}")
    return items


def _is_names(value: Any) -> bool:
    return isinstance(value, str) or (
        isinstance(value, Sequence) and len(value) > 0 and all(isinstance(v, str) for v in value)
    )


def _constraint_list(constraints: Any) -> tuple[Any, ...]:
    """``constraints`` as a tuple: a list or tuple of them (each checked later, by index).

    ``None`` is refused rather than read as "no constraints": no constraint
    is written ``[]`` (the default), and a None usually stands for a list
    that was never built.  A single constraint must be put in a list.
    """
    if constraints is None:
        raise TypeError(
            "Expected `constraints` to be a sequence of constraints, got None: for no constraint give [] "
            "(or leave `constraints` out)"
        )
    if isinstance(constraints, (str, bytes, Mapping)) or not isinstance(constraints, Sequence):
        hint = "; put a single constraint in a list: [c]" if type(constraints).__module__.startswith("mocaplab") else ""
        raise TypeError(
            f"Expected `constraints` to be a sequence (list or tuple) of constraints, got "
            f"{type(constraints).__name__}{hint}"
        )
    return tuple(constraints)


def _checked_options(opts: dict[str, Any], chars: Sequence[Motion]) -> dict[str, Any]:
    """Every option of :class:`SceneEditor` checked (TypeError/ValueError naming it), numbers made plain.

    The one validator of the editing entry points (:func:`edit`,
    :class:`SceneEditor`, :func:`~mocaplab.editing.make_editor` and the
    discrete editor, which builds a SceneEditor): run before any path,
    contact or solve.  Time options are bounded by the scene
    (:func:`~mocaplab.editing.timewarp.time_reach`).
    """
    out = dict(opts)
    reach = time_reach([m.n_frames for m in chars], [m.dt for m in chars])
    flip_step(out["flip_rate"], 1.0, name="flip_rate")  # a bad rate fails here, not when a heading is first asked for
    _check_clock_fps(out["clock_fps"])
    for name, unit in (
        ("stationary_speed", "m/s"), ("stationary_min_duration", "seconds"), ("min_speed", "m/s"),
        ("relative_tolerance", "metres"), ("refine_tolerance", "metres"),
    ):
        out[name] = real(out[name], name, low=0.0, unit=unit)
    out["min_step"] = real(out["min_step"], "min_step", low=0.0, high=1.0, low_open=True, high_open=True,
                           unit="of the frame time")
    out["max_step"] = real(out["max_step"], "max_step", low=1.0, low_open=True, unit="of the frame time")
    out["flip_window"] = real(
        out["flip_window"], "flip_window", low=0.0, high=reach,
        unit=f"seconds (at most {TIME_REACH:g} times the scene's duration)",
    )
    out["relative_iterations"] = integer(out["relative_iterations"], "relative_iterations", low=1,
                                         why="most solves per update")
    out["relative_drag_iterations"] = integer(out["relative_drag_iterations"], "relative_drag_iterations", low=1,
                                              why="most solves per drag")
    out["variational_step"] = integer(out["variational_step"], "variational_step", low=1, why="frames")
    starts = out["start_times"]
    if starts is not None:
        if isinstance(starts, (str, bytes)) or not isinstance(starts, Sequence | np.ndarray):
            raise TypeError(f"Expected `start_times` to be a sequence of seconds, one per motion, got {starts!r:.80}")
        if len(starts) != len(chars):
            raise ValueError(f"Expected {len(chars)} `start_times` (one per motion), got {len(starts)}")
        out["start_times"] = tuple(real(t, f"start_times[{k}]", unit="seconds") for k, t in enumerate(starts))
    return out


def _characters(motions: Any) -> tuple[Motion, ...]:
    if isinstance(motions, Motion):
        motions = (motions,)
    try:
        chars = tuple(motions)
    except TypeError:
        raise TypeError(f"Expected `motions` as a sequence of Motion, got {type(motions).__name__}") from None
    if not chars:
        raise ValueError("Expected at least one character in `motions`, got none")
    for k, m in enumerate(chars):
        if not isinstance(m, Motion):
            raise TypeError(f"Expected motions[{k}] to be a Motion, got {type(m).__name__}")
        if m.n_frames < 3:
            raise ValueError(f"Expected motions[{k}] to have at least 3 frames, got {m.n_frames}")
    return chars


class _Domain:
    """One linear system (space or time) with its factorisation cache."""

    def __init__(self, solver: Any, kind: str, make_rows: Any) -> None:
        self.solver = solver
        self.kind = kind
        self.make_rows = make_rows
        self.cache: OrderedDict[tuple[Any, ...], Any] = OrderedDict()
        self.key: tuple[Any, ...] | None = None
        self.factors: Any = None
        self.slices: dict[int, tuple[str, slice]] = {}
        self.bw = np.zeros(0)
        self.h = np.zeros(0)
        self.factorizations = 0

    def structure(self, items: Sequence[tuple[int, Any]]) -> tuple[Any, ...]:
        return tuple((i, c.structure()) for i, c in items)

    def set(self, items: Sequence[tuple[int, Any]]) -> None:
        """Compile and factorise (or fetch from the cache) for these constraints."""
        key = self.structure(items)
        if key in self.cache:
            self.cache.move_to_end(key)
            self.key, self.factors, self.slices, ns, nh = self.cache[key]
            bw, h = np.zeros(ns), np.zeros(nh)
            for i, c in items:
                self._write(bw, h, i, c)
            self.bw, self.h = bw, h
            return
        soft: list[Rows] = []
        weights: list[float] = []
        hard: list[Rows] = []
        labels: list[Any] = []
        slices: dict[int, tuple[str, slice]] = {}
        ns = nh = 0
        for i, c in items:
            rows = self.make_rows(c)
            if c.hard:
                hard.append(rows)
                labels.append((i, c))
                slices[i] = ("hard", slice(nh, nh + rows.n))
                nh += rows.n
            else:
                soft.append(rows)
                weights.append(c.weight)
                slices[i] = ("soft", slice(ns, ns + rows.n))
                ns += rows.n
        factors, bw, h = self.solver.factorize(soft, weights, hard, labels)
        self.factorizations += 1
        self.key, self.factors, self.slices, self.bw, self.h = key, factors, slices, bw, h
        self.cache[key] = (key, factors, slices, ns, nh)
        if len(self.cache) > 4:
            self.cache.popitem(last=False)

    def _write(self, bw: Array, h: Array, i: int, c: Any) -> None:
        which, sl = self.slices[i]
        rhs = self.make_rows(c).rhs
        if which == "soft":
            bw[sl] = rhs * math.sqrt(c.weight)
        else:
            h[sl] = rhs

    def snapshot(self) -> tuple[Any, ...]:
        return (self.key, self.factors, self.slices, self.bw, self.h)

    def restore(self, state: tuple[Any, ...]) -> None:
        self.key, self.factors, self.slices, self.bw, self.h = state

    def move(self, i: int, c: Any) -> None:
        """Update the right-hand sides for constraint ``i``'s new target (structure unchanged)."""
        bw, h = self.bw.copy(), self.h.copy()
        self._write(bw, h, i, c)
        self.bw, self.h = bw, h


class SceneEditor(Undoable):
    """An interactive editing session over a scene of characters.

    Parameters
    ----------
    motions : Motion or sequence of Motion
        The input clips (never modified).
    constraints : sequence of constraints
        :mod:`~mocaplab.editing.constraints` objects.
    **options
        See the module docstring.

    Notes
    -----
    Factorisations are cached per constraint *structure* (which constraints,
    on which frames, hard or soft, weights, relative offsets).  :meth:`drag`
    keeps the structure, so it costs two back-substitutions for space
    (phases 1 and 2) or one per monotonicity round for time.  The space
    system is not re-solved when only temporal constraints change, and vice
    versa.

    History (:attr:`undo_stack`, a :class:`mocaplab.undo.UndoStack` of
    :meth:`snapshot` states): every successful :meth:`drag`, :meth:`add`,
    :meth:`remove`, :meth:`replace` and :meth:`set_constraints` records the
    new state; a failed one records nothing and leaves the editor as it was.
    One undo step is one gesture: consecutive :meth:`drag` calls on the same
    constraint, and an :meth:`add` followed by drags of the constraint it
    added (a press that pins a point, then drags it), merge into one step
    until :meth:`checkpoint` (the widgets call it when the mouse is
    released).  :meth:`undo` and :meth:`redo` restore a recorded state
    exactly (the same constraints and the very same :class:`EditResult`);
    :meth:`reset` returns to the constraints the editor was created with,
    as one more (undoable) step.  Memory: only the results of the few most
    recently current states keep the full-body motions they built
    (:class:`WarmResults`); older states rebuild them, bitwise the same, on
    first access after an undo.

    Examples
    --------
    Pin a walk's first frame, drag a soft pin on its last frame half a
    metre along x, then undo the drag:

    >>> import numpy as np
    >>> from mocaplab.data import cmu
    >>> from mocaplab.editing import PinPosition
    >>> walk = cmu("16_15")
    >>> ends = walk.root_positions[[0, -1]][:, [0, 2]]
    >>> ed = SceneEditor([walk], [PinPosition(0, 0, ends[0], hard=True), PinPosition(0, 470, ends[1])])
    >>> before = ed.result
    >>> res = ed.drag(1, ends[1] + (0.5, 0.0))
    >>> (np.round(res.paths[0][-1] - ends[1], 3) + 0.0).tolist()
    [0.5, 0.0]
    >>> ed.checkpoint(); ed.undo() is before
    True
    """

    def __init__(self, motions: Any, constraints: Sequence[Any] = (), **options: Any) -> None:
        if options.get("discrete"):
            raise TypeError(
                "SceneEditor is continuous-only: for discrete editing (section 5) use "
                "mocaplab.editing.DiscreteEditor(characters, constraints, discrete=..., **options), "
                "or mocaplab.editing.make_editor(..., discrete=...)"
            )
        options = {k: v for k, v in options.items() if k != "discrete"}
        unknown = sorted(set(options) - set(_OPTIONS))
        if unknown:
            raise TypeError(f"Unknown option(s) {unknown}; valid options are {sorted(_OPTIONS)}")
        opts = dict(_OPTIONS)
        opts.update(options)
        chars = _characters(motions)
        constraints = _constraint_list(constraints)
        opts = _checked_options(opts, chars)  # every option, before any path, contact or solve
        self.options = opts
        K = len(chars)
        roles = _per_character(opts["roles"], K, "roles", lambda v: isinstance(v, Mapping))
        self.characters = tuple(with_roles(m, r) for m, r in zip(chars, roles, strict=True))
        joints = _per_character(opts["joints"], K, "joints", _is_names)
        for k, (m, j) in enumerate(zip(self.characters, joints, strict=True)):
            if j is not None:
                try:
                    contact_joints(m, j)
                except ValueError as exc:
                    raise ValueError(f"character {k}: {exc}") from None
        self._joints = joints
        self._refine_cache = RefineCache(opts["refine_tolerance"])
        self.paths = tuple(MotionPath.from_motion(m, min_speed=opts["min_speed"]) for m in self.characters)
        self.segments = self._stationary(opts["stationary"])
        step = opts["variational_step"]
        starts = [0.0] * K if opts["start_times"] is None else list(opts["start_times"])
        self._space = SpatialSolver(
            self.paths,
            self.segments,
            scale_compensation=opts["scale_compensation"],
            metric_tolerance=opts["relative_tolerance"],
            metric_iterations=opts["relative_iterations"],
        )
        self._time = TimeSolver(
            [m.n_frames for m in self.characters],
            [m.dt for m in self.characters],
            starts,
            min_step=opts["min_step"],
            max_step=opts["max_step"],
        )
        layout = self._space.layout
        tangents = self._space.tangent_rows
        self._sd = _Domain(self._space, "space", lambda c: spatial_rows(c, self.paths, layout, tangents, step))
        self._td = _Domain(self._time, "time", lambda c: temporal_rows(c, layout, self._time.dts, step))
        self._constraints: tuple[Any, ...] = ()
        self._effectors: tuple[tuple[Any, ...], ...] = ()
        self._space_sol: SpatialSolution | None = None
        self._time_sol: tuple[Array, tuple[int, ...]] | None = None
        self._result: EditResult | None = None
        self._set(tuple(constraints), changed=None)
        self.undo_stack: UndoStack[tuple[Any, ...]] = UndoStack(self.snapshot(), limit=_UNDO_LIMIT)
        self._warm = WarmResults()
        self._warm.touch(self.result)
        self._merging: Any = None  # merge key of the last recorded edit, until a checkpoint

    # ------------------------------------------------------------ set-up
    def _stationary(self, spec: Any) -> list[list[tuple[int, int]]]:
        K = len(self.characters)
        o = self.options
        if spec is None or spec is False:
            return [[] for _ in range(K)]
        if isinstance(spec, str):
            if spec not in ("auto", "speed"):
                raise ValueError(f"Expected `stationary` 'auto', 'speed', None or per-character segments, got {spec!r}")
            return [
                stationary_segments(
                    m,
                    speed=o["stationary_speed"],
                    min_duration=o["stationary_min_duration"],
                    contacts="auto" if spec == "auto" else None,
                    joints=j,
                )
                for m, j in zip(self.characters, self._joints, strict=True)
            ]
        segs = list(spec)
        if len(segs) != K:
            raise ValueError(f"Expected `stationary` segments for {K} characters, got {len(segs)}")
        out = []
        for k, s in enumerate(segs):
            cur = []
            for a, b in s:
                if not 0 <= a < b <= self.characters[k].n_frames:
                    raise ValueError(f"Stationary segment ({a}, {b}) out of range for character {k}")
                cur.append((int(a), int(b)))
            out.append(cur)
        return out

    def _warn_pin_on_static_root(self, i: int, pin: PinPosition) -> None:
        """Warn when a hard pin sits on a static root joint, far from the path: built from the wrong joint."""
        m = self.characters[pin.character]
        if m.path_joint == 0:
            return
        f = int(pin.frame)  # type: ignore[arg-type]
        target = np.asarray(pin.position, dtype=float)
        off_path = float(np.linalg.norm(target - self.paths[pin.character].positions[f]))
        on_root = float(np.linalg.norm(target - m.root_positions[f, [0, 2]]))
        if off_path > PIN_FAR and on_root < PIN_ON_ROOT:
            names = m.skeleton.names
            warn(
                f"constraint #{i} (hard pin at frame {f} of character {pin.character}) lies on the static root joint "
                f"{names[0]!r}, {off_path:.2f} m from the path there: pins are ground positions of the path joint "
                f"{names[m.path_joint]!r}; build them from motion.pelvis_positions (or the result's paths), "
                "not motion.root_positions",
                PinPlacementWarning,
            )

    def _validate(self, constraints: Sequence[Any], offset: int = 0) -> None:
        K = len(self.characters)
        for i, c in enumerate(constraints, start=offset):
            if not isinstance(c, SPATIAL + TEMPORAL + (EndEffectorConstraint, EndEffector)):
                raise TypeError(f"constraint #{i}: expected a mocaplab.editing constraint, got {type(c).__name__}")
            if isinstance(c, (EndEffector, EndEffectorConstraint)):
                if not 0 <= c.character < K:
                    raise ValueError(
                        f"constraint #{i} {c!r}: unknown character {c.character} (the scene has {K} characters)"
                    )
                ee = c.constraint if isinstance(c, EndEffectorConstraint) else c
                ee.check(self.characters[c.character], label=f"constraint #{i} {c!r}")
                continue
            for k in c.characters:
                if not 0 <= k < K:
                    raise ValueError(
                        f"constraint #{i} {c!r}: unknown character {k} (the scene has {K} characters: 0..{K - 1})"
                    )
            for k, f in c.frame_refs():
                n = self.characters[k].n_frames
                if not 0 <= f < n:
                    raise ValueError(
                        f"constraint #{i} {c!r}: frame {f} out of range for character {k} ({n} frames: 0..{n - 1})"
                    )
            if isinstance(c, SPATIAL[0]) and c.hard and c.frame is not None:
                self._warn_pin_on_static_root(i, c)
            if isinstance(c, TEMPORAL):
                problem = self._time.target_problem(c)
                if problem is not None:
                    raise ConstraintError(f"constraint #{i} {c!r}: {problem}", [c], [i])
            if isinstance(c, SPATIAL) and not isinstance(c, SPATIAL[0]):
                needs = (
                    [c.character]
                    if not hasattr(c, "other")
                    else [c.other] + ([c.character] if c.direction is not None else [])
                )
                for k in needs:
                    if not self.paths[k].has_tangents:
                        raise ConstraintError(
                            f"constraint #{i} {c!r}: character {k} never moves, so its path has no tangent frame "
                            "to measure directions or relative offsets in",
                            [c],
                            [i],
                        )

    def snapshot(self) -> tuple[Any, ...]:
        """The editor's state (constraints, factorisations in use, solutions), for :meth:`restore`."""
        return (
            self._sd.snapshot(),
            self._td.snapshot(),
            self._space_sol,
            self._time_sol,
            self._effectors,
            self._constraints,
            self._result,
        )

    def restore(self, state: tuple[Any, ...]) -> None:
        """Go back to a :meth:`snapshot` (the factorisation caches keep what they hold)."""
        self._sd.restore(state[0])
        self._td.restore(state[1])
        self._space_sol, self._time_sol, self._effectors, self._constraints, self._result = state[2:]

    def _set(self, constraints: tuple[Any, ...], changed: int | None, iterations: int | None = None) -> EditResult:
        """Install constraints; ``changed`` = index whose target alone may have moved (fast path).

        ``iterations``: most solves for the relative constraints' metric targets
        (default ``relative_iterations``).  On any error the editor keeps its previous state.
        """
        saved = self.snapshot()
        try:
            with single_blas_thread():  # small systems: one BLAS thread, the caller's setting restored
                return self._install(constraints, changed, iterations)
        except ConstraintError as exc:
            self.restore(saved)
            current = _naming_current(exc, constraints)
            if current is exc:
                raise
            raise current from None
        except Exception:
            self.restore(saved)
            raise

    def _install(self, constraints: tuple[Any, ...], changed: int | None, iterations: int | None) -> EditResult:
        old = self._constraints
        fast = (
            changed is not None
            and len(old) == len(constraints)
            and self._space_sol is not None
            and type(old[changed]) is type(constraints[changed])
        )
        if fast:
            assert changed is not None
            previous_factors = self._sd.factors
            c = constraints[changed]
            self._validate([c], offset=changed)
            dom = self._sd if isinstance(c, SPATIAL) else self._td if isinstance(c, TEMPORAL) else None
            if dom is None:
                self._effectors = _effectors(constraints, len(self.characters))
            if dom is not None:
                if old[changed].structure() == c.structure():
                    dom.move(changed, c)
                else:
                    dom.set(
                        [
                            (i, x)
                            for i, x in enumerate(constraints)
                            if isinstance(x, SPATIAL if dom is self._sd else TEMPORAL)
                        ]
                    )
                if dom is self._sd:
                    same = dom.factors is previous_factors
                    self._space_sol = self._space.solve(
                        self._sd.factors,
                        self._sd.bw,
                        self._sd.h,
                        previous=self._space_sol if same else None,
                        iterations=iterations,
                    )
                else:
                    self._time_sol = self._time.solve(self._td.factors, self._td.bw, self._td.h)
        else:
            self._validate(constraints)
            self._effectors = _effectors(constraints, len(self.characters))
            self._sd.set([(i, c) for i, c in enumerate(constraints) if isinstance(c, SPATIAL)])
            self._td.set([(i, c) for i, c in enumerate(constraints) if isinstance(c, TEMPORAL)])
            self._space_sol = self._space.solve(self._sd.factors, self._sd.bw, self._sd.h)
            self._time_sol = self._time.solve(self._td.factors, self._td.bw, self._td.h)
        self._constraints = constraints
        self._result = EditResult(self, constraints)
        return self._result

    # -------------------------------------------------------- public API
    @property
    def constraints(self) -> tuple[Any, ...]:
        return self._constraints

    @property
    def result(self) -> EditResult:
        """The current edit."""
        assert self._result is not None
        return self._result

    def contact_joints(self, character: int) -> tuple[str, ...]:
        """The joints whose foot contacts character ``character`` keeps (the ``joints`` option or the roles' feet)."""
        return contact_joints(self.characters[character], self._joints[character])

    @property
    def factorizations(self) -> int:
        """How many factorisations (space + time structures) were computed so far."""
        return self._sd.factorizations + self._td.factorizations

    def drag(self, constraint_index: int, new_target: Any) -> EditResult:
        """Move constraint ``constraint_index``'s target (see :attr:`Constraint.target`) and re-solve.

        Consecutive drags of one constraint are one undo step (until :meth:`checkpoint`).
        """
        i = self._check_index(constraint_index)
        c = self._constraints[i]
        if not hasattr(c, "with_target"):
            raise TypeError(f"constraint #{i} {c!r} has no draggable target")
        new = list(self._constraints)
        new[i] = c.with_target(new_target)
        budget = self.options["relative_drag_iterations"]
        return self._record(self._set(tuple(new), changed=i, iterations=budget), merge=("edit", i))

    def settle(self) -> EditResult:
        """Solve the relative constraints' metric targets from the constraints alone, after drags.

        A drag starts the metric-target iterations from the previous update
        and makes at most ``relative_drag_iterations`` solves, so
        while the mouse moves a large formation of tied characters can trail
        its targets, and where more than one arrangement meets them (a long
        chain of tied characters turned far) the drags can lead to either.
        Settling solves them again as :func:`edit` does (from the linear
        rows, up to ``relative_iterations`` solves): the result is
        then the one ``edit(characters, constraints)`` gives, whatever the
        drags that led there.  It replaces the current undo state (the same
        edit, settled) and returns the current result; it does nothing when
        the current solution was not warm-started.  :meth:`checkpoint` calls
        it (the widgets call that on mouse release).

        Examples
        --------
        >>> import numpy as np
        >>> from mocaplab.data import cmu
        >>> from mocaplab.editing import PinPosition, Relative
        >>> walk = cmu("16_15")
        >>> p = walk.root_positions[:, [0, 2]]
        >>> side = walk.transformed(translation=[0.0, 0.0, 0.8])
        >>> cons = [PinPosition(0, 0, p[0], hard=True), PinPosition(0, 470, p[-1]),
        ...         PinPosition(1, 0, p[0] + (0.0, 0.8), hard=True), Relative(1, 400, 0, 400, (0.0, 0.8))]
        >>> ed = SceneEditor([walk, side], cons, relative_drag_iterations=1)
        >>> for x in np.linspace(0.1, 0.8, 8):
        ...     res = ed.drag(1, p[-1] + (-x, x))
        >>> settled = ed.settle()
        >>> once = edit([walk, side], ed.constraints)
        >>> settled.settled, bool(np.array_equal(settled.paths[1], once.paths[1]))
        (True, True)
        """
        sol = self._space_sol
        if sol is None or not sol.warm:
            return self.result
        saved = self.snapshot()
        try:
            with single_blas_thread():
                self._space_sol = self._space.solve(self._sd.factors, self._sd.bw, self._sd.h)
                self._result = EditResult(self, self._constraints)
        except Exception:
            self.restore(saved)
            raise
        self.undo_stack.amend(self.snapshot())
        self._warm.touch(self._result, replaces=True)
        return self._result

    def add(self, constraint: Any) -> int:
        """Append a constraint and re-solve; returns its index.

        Drags of the new constraint that follow merge into this undo step (until :meth:`checkpoint`).
        """
        index = len(self._constraints)
        self._record(self._set(self._constraints + (constraint,), changed=None), merge=("edit", index))
        return index

    def remove(self, index: int) -> EditResult:
        """Remove constraint ``index`` (later indices shift down by one) and re-solve (one undo step)."""
        i = self._check_index(index)
        return self._record(self._set(self._constraints[:i] + self._constraints[i + 1 :], changed=None))

    def replace(self, index: int, constraint: Any) -> EditResult:
        """Put ``constraint`` in place of constraint ``index`` and re-solve (one undo step)."""
        i = self._check_index(index)
        new = list(self._constraints)
        new[i] = constraint
        same = type(constraint) is type(self._constraints[i])
        return self._record(self._set(tuple(new), changed=i if same else None))

    def set_constraints(self, constraints: Sequence[Any]) -> EditResult:
        """Replace every constraint and re-solve (one undo step); ``[]`` removes them all (None is refused)."""
        return self._record(self._set(_constraint_list(constraints), changed=None))

    # ----------------------------------------------------------- history
    def _record(self, result: EditResult, merge: Any = None) -> EditResult:
        replaces = merge is not None and merge == self._merging  # the stack merges this push into the newest
        self.undo_stack.push(self.snapshot(), merge=merge)
        self._merging = merge
        self._warm.touch(result, replaces=replaces)
        return result

    def _go(self, state: tuple[Any, ...]) -> EditResult:
        """Make an undo state current (undo, redo, reset)."""
        self.restore(state)
        self._merging = None
        self._warm.touch(self.result)
        return self.result

    def _here(self) -> EditResult:
        return self.result

    def _gesture_ended(self) -> None:
        self._merging = None
        self.settle()

    def trim(self) -> None:
        """Drop the factorisations cached for other constraint structures than the one in use.

        Also the time solver's systems for monotonicity active sets.  They
        are rebuilt when needed; the discrete editor calls this on the
        continuous editor of a scene it leaves (kept for undo).
        """
        for dom in (self._sd, self._td):
            for key in [k for k in dom.cache if k != dom.key]:
                del dom.cache[key]
        self._td.factors.cache.clear()

    @property
    def tangent_rows(self) -> Any:
        """The tangent-operator rows of the input paths (``row(k, i) -> (columns, weights)``), cached."""
        return self._space.tangent_rows

    def evaluate(self, motions: Any, constraints: Sequence[Any]) -> EditResult:
        """A fresh continuous edit of other characters/constraints with this editor's options (state untouched)."""
        return SceneEditor(motions, constraints, **self.options).result

    def _check_index(self, index: Any) -> int:
        n = len(self._constraints)
        if isinstance(index, bool) or not isinstance(index, (int, np.integer)) or not -n <= index < n:
            raise IndexError(f"Expected a constraint index in 0..{n - 1}, got {index!r}")
        return int(index) % n


def _naming_current(exc: ConstraintError, constraints: tuple[Any, ...]) -> ConstraintError:
    """``exc`` naming the constraints as they are now.

    A drag that keeps a constraint's structure reuses the factorisation,
    whose row labels hold the constraint as it was when it was factorised
    (its first target): name the dragged one instead.
    """
    if not exc.indices:
        return exc
    named = list(exc.constraints)
    message = str(exc)
    user = iter(exc.indices)
    for k, c in enumerate(named):
        if isinstance(c, str):
            continue  # automatic rows (rigid segments, step bounds) carry no index
        i = next(user, None)
        if i is None or not 0 <= i < len(constraints):
            break
        now = constraints[i]
        if now is not c:
            message = message.replace(f"#{i} {c!r}", f"#{i} {now!r}")
            named[k] = now
    if message == str(exc) and named == list(exc.constraints):
        return exc
    return ConstraintError(message, named, exc.indices)


def _check_clock_fps(fps: Any) -> None:
    """``clock_fps`` is None or a rate from 0.1 to :data:`MAX_CLOCK_FPS` (ValueError naming the limit)."""
    if fps is None:
        return
    try:
        value = float(fps)
    except (TypeError, ValueError):
        raise ValueError(f"Expected `clock_fps` to be None or a number of frames per second, got {fps!r}") from None
    if not FPS_RANGE[0] <= value <= MAX_CLOCK_FPS:  # NaN fails too
        raise ValueError(
            f"Expected `clock_fps` from {FPS_RANGE[0]:g} to MAX_CLOCK_FPS = {MAX_CLOCK_FPS:g} frames per second, "
            f"got {fps!r}"
        )


#: A hard pin further than this (metres) from the path point of its frame, and within :data:`PIN_ON_ROOT` of
#: a static root joint above the path joint, was built from the wrong joint (:class:`PinPlacementWarning`).
PIN_FAR = 1.0
PIN_ON_ROOT = 0.05


class PinPlacementWarning(UserWarning):
    """A hard pin lies on a static root joint, far from the path: it was built from the wrong joint.

    Files with a static reference joint above a travelling pelvis (a common
    export layout) keep ``motion.root_positions`` at one place; the path is
    the path joint's (``motion.pelvis_positions``).  A pin taken from the
    former lands metres from the walk and silently bends it there.

    Parameters
    ----------
    *args
        The message.

    Examples
    --------
    >>> import warnings
    >>> import numpy as np
    >>> from mocaplab import Motion, Skeleton
    >>> from mocaplab.editing import PinPosition, edit
    >>> sk = Skeleton(["Root", "Hips"], [-1, 0], [[0, 0, 0], [0, 1, 0]], channels=(("Xposition", "Yposition", "Zposition"), ("Xposition", "Yposition", "Zposition")))
    >>> walk = np.column_stack([np.linspace(0, 3, 60), np.zeros(60), np.zeros(60)])
    >>> trans = np.zeros((60, 2, 3)); trans[:, 1] = walk + [0, 1, 0]
    >>> m = Motion(sk, np.tile([0, 0, 0, 1.0], (60, 2, 1)), np.zeros((60, 3)), 30, translations=trans)
    >>> with warnings.catch_warnings(record=True) as caught:
    ...     warnings.simplefilter("always")
    ...     res = edit([m], [PinPosition(0, 59, m.root_positions[59, [0, 2]], hard=True)], stationary="speed")
    >>> [w.category.__name__ for w in caught if w.category is not UserWarning]  # (the other: the path joint is 'Hips')
    ['PinPlacementWarning']
    """


class PathJumpWarning(UserWarning):
    """A path edit moves a character's path joint much further in one frame than the input ever did.

    It happens where the constraints force it: a rigid stationary segment
    dragged away from a hard pin a few frames before it (or two rigid
    segments pulled apart across a short gap).  The message names the
    frames, the jump and what holds them.

    Examples
    --------
    A character stands still for a second, then walks 1 m; its standing
    segment is dragged 1 m back while frame 31 is held hard:

    >>> import warnings
    >>> import numpy as np
    >>> from mocaplab import Motion, Skeleton
    >>> from mocaplab.editing import PinPosition
    >>> x = np.concatenate([np.zeros(30), np.linspace(0, 1, 31)[1:]])
    >>> root = np.column_stack([x, np.ones(60), np.zeros(60)])
    >>> m = Motion(Skeleton(["hips"], [-1], [[0, 0, 0]]), np.tile([0, 0, 0, 1.0], (60, 1, 1)), root, 30)
    >>> pins = [PinPosition(0, 31, (x[31], 0.0), hard=True), PinPosition(0, 0, (-1.0, 0.0), hard=True)]
    >>> with warnings.catch_warnings(record=True) as caught:
    ...     warnings.simplefilter("always")
    ...     res = edit([m], pins, stationary="speed")
    >>> [w.category.__name__ for w in caught], res.stationary
    (['PathJumpWarning'], (((0, 28),),))
    """


#: A path step is a jump when longer than this factor of the input's longest step plus :data:`_JUMP_SLACK` m.
_JUMP_FACTOR = 1.5
_JUMP_SLACK = 0.002


class RelativeConflictWarning(UserWarning):
    """A soft relative constraint fights hard constraints: the edit is their least-squares compromise.

    The hard constraints fix (part of) what the relative asks for, e.g. hard
    pins on both characters at the related frames 3 m apart and an offset
    of 0.8 m; the relative is then missed by about 2.2 m.  A hard relative
    in that place raises :class:`~mocaplab.editing.constraints.ConstraintError`
    naming it and the pins.

    Examples
    --------
    That case, on two copies of a walk:

    >>> import warnings
    >>> from mocaplab.data import cmu
    >>> from mocaplab.editing import PinPosition, Relative
    >>> walk = cmu("16_15")
    >>> p = walk.root_positions[100, [0, 2]]
    >>> pins = [PinPosition(0, 100, p, hard=True), PinPosition(1, 100, p + (3.0, 0.0), hard=True)]
    >>> with warnings.catch_warnings(record=True) as caught:
    ...     warnings.simplefilter("always")
    ...     res = edit([walk, walk], [*pins, Relative(1, 100, 0, 100, (0.0, 0.8))])
    >>> print(caught[0].message)
    soft relative constraint #2 is missed by 2.21 m: hard constraints #0, #1 fix what it asks for, ...
    """


def _path_jumps(result: EditResult) -> list[str]:
    """Messages for each character whose edited path makes a one-frame jump (see :class:`PathJumpWarning`)."""
    out = []
    for k, (before, after) in enumerate(zip(result.original_paths, result.paths, strict=True)):
        old = np.linalg.norm(np.diff(before.positions, axis=0), axis=1)
        new = np.linalg.norm(np.diff(after, axis=0), axis=1)
        limit = _JUMP_FACTOR * float(old.max(initial=0.0)) + _JUMP_SLACK
        if not len(new) or float(new.max()) <= limit:
            continue
        i = int(np.argmax(new))
        near = range(i - 3, i + 5)
        segs = [f"frames {a}-{b - 1} are a rigid stationary segment" for a, b in result.stationary[k]
                if a in near or b in near]
        pins = [f"#{n} holds frame {f} hard" for n, c in enumerate(result.constraints)
                if getattr(c, "hard", False) and hasattr(c, "frame_refs")
                for kk, f in c.frame_refs() if kk == k and f in near]
        cause = "; ".join(segs + pins) or "the constraints pull these frames apart"
        out.append(
            f"character {k}: the path edit moves the path joint {1000 * float(new[i]):.0f} mm between frames {i} and "
            f"{i + 1} (the input's longest one-frame step is {1000 * float(old.max()):.0f} mm): {cause}. The body "
            "pops there; make the pin soft (hard=False), move the targets closer, or let the segment deform "
            "(stationary=None or shorter segments)."
        )
    return out


def edit(motions: Any, constraints: Sequence[Any] = (), **options: Any) -> EditResult:
    """Edit the paths and timing of the characters ``motions`` under ``constraints``.

    Parameters
    ----------
    motions : Motion or sequence of Motion
    constraints : sequence of constraints
        A list or tuple; ``[]`` (the default) edits with none.  ``None`` is
        a TypeError saying so (it is not read as "no constraints").
    **options
        See :mod:`mocaplab.editing.scene`; each is checked before any work
        (a TypeError or ValueError naming the option and what it takes).

    Returns
    -------
    EditResult

    Examples
    --------
    Pin a walk's first frame and move its last frame 1 m along x:

    >>> import numpy as np
    >>> from mocaplab.data import cmu
    >>> from mocaplab.editing import PinPosition
    >>> walk = cmu("16_15")
    >>> ends = walk.root_positions[[0, -1]][:, [0, 2]]
    >>> res = edit([walk], [PinPosition(0, 0, ends[0], hard=True), PinPosition(0, 470, ends[1] + (1.0, 0.0))])
    >>> res.paths[0].shape, (np.round(res.paths[0][-1] - ends[1], 3) + 0.0).tolist(), res.motions[0].n_frames
    ((471, 2), [1.0, 0.0], 471)

    Warns
    -----
    PathJumpWarning
        Where the constraints force a one-frame jump of a path (a rigid
        segment dragged from a hard pin next to it), naming the frames.
    RelativeConflictWarning
        Where a soft :class:`~mocaplab.editing.constraints.Relative` asks
        for what hard constraints fix (:attr:`EditResult.conflicts`).
    """
    result = SceneEditor(motions, constraints, **options).result
    for message in _path_jumps(result):
        warn(message, PathJumpWarning)
    for note in result.notes:
        if note.startswith("soft relative constraint #"):
            warn(note, RelativeConflictWarning)
    return result


class _Lazy(Sequence):
    """A read-only sequence whose items are computed on first access."""

    def __init__(self, n: int, make: Any) -> None:
        self._n = n
        self._make = make
        self._items: dict[int, Any] = {}

    def __len__(self) -> int:
        return self._n

    def __getitem__(self, k: Any) -> Any:
        if isinstance(k, slice):
            return [self[i] for i in range(*k.indices(self._n))]
        if not -self._n <= k < self._n:
            raise IndexError(f"character index {k} out of range for {self._n} characters")
        k = int(k) % self._n
        if k not in self._items:
            self._items[k] = self._make(k)
        return self._items[k]

    def __iter__(self) -> Iterator[Any]:
        return (self[k] for k in range(self._n))

    def clear(self) -> None:
        """Forget the items computed so far (they are computed again on access)."""
        self._items.clear()

    def __repr__(self) -> str:
        return f"<{self._n} lazily computed items>"


def _lerp(x: Array, u: Array) -> Array:
    """Rows of ``x`` (F, ...) linearly interpolated at fractional frames ``u`` (clamped to the clip)."""
    u = np.clip(u, 0.0, len(x) - 1)
    i0 = np.floor(u).astype(np.int64)
    i1 = np.minimum(i0 + 1, len(x) - 1)
    a = (u - i0).reshape((-1,) + (1,) * (x.ndim - 1))
    return (1 - a) * x[i0] + a * x[i1]


def _ro(a: NDArray[Any]) -> NDArray[Any]:
    a.flags.writeable = False
    return a


class EditResult:
    """The outcome of an edit (immutable).

    Attributes
    ----------
    paths : sequence of ndarray, shape (F_k, 2)
        Edited ground positions ``(x, z)`` per character (after phase 2).
    times : sequence of ndarray, shape (F_k,)
        Reference time of each frame (the time warp), seconds.
    motions : sequence of Motion
        Full-body motions on the shared clock (lazy; see the module docstring).
    clock : ndarray, shape (N,)
        Reference times of the frames of ``motions``.
    active : sequence of ndarray of bool, shape (N,)
        Clock ticks within each character's own time span.
    shape_paths : sequence of ndarray, shape (F_k, 2)
        Phase-1 (shape-preserving) positions.
    edited_motions : sequence of Motion
        Full-body motions along the edited paths at their original frame
        timing (no time warp; lazy).
    tangents, heading_change, flips : per character, lazy
        Repaired unit tangents (F_k, 2), yaw change of the path direction
        (F_k,), and tangent-flip frames that were repaired (F_k,) bool.
    stationary : sequence of list of (start, stop)
        Rigid stationary segments per character.
    constraints : tuple
    end_effectors : sequence of tuple
        End-effector constraints per character (for full-body refinement).
    transformations : tuple
        Discrete transformations applied (section 5; empty but for the
        results of a :class:`~mocaplab.editing.discrete.DiscreteEditor`).
    notes : tuple of str
        What the solver did that the user may want to know: redundant hard
        constraints left out of the factorisation (and checked), relative
        constraints whose metric targets had not settled.
    relative_iterations : int
        Solves made for the relative constraints' metric targets (1 without any).
    settled : bool
        The relative constraints' metric targets were solved from the
        constraints alone and settled to ``relative_tolerance`` (True
        without relative constraints): the result :func:`edit` gives.
        False for a drag's warm-started update until
        :meth:`SceneEditor.settle` (on release).

    Attributes cannot be reassigned; :meth:`with_transformations` returns a copy.

    Parameters
    ----------
    editor : SceneEditor
        The editor whose current solution this is: results are made by the
        editors (:attr:`SceneEditor.result`, :func:`edit`), not by hand.
    constraints : tuple
        The constraints solved for.

    Examples
    --------
    >>> import numpy as np
    >>> from mocaplab.data import cmu
    >>> from mocaplab.editing import PinPosition
    >>> walk = cmu("16_15")
    >>> res = edit([walk], [PinPosition(0, 0, walk.root_positions[0, [0, 2]], hard=True)])
    >>> len(res.paths), res.times[0].shape, res.stationary, res.transformations
    (1, (471,), ((),), ())
    >>> res.paths = None
    Traceback (most recent call last):
    ...
    AttributeError: EditResult is immutable: cannot set 'paths'
    """

    _frozen = False

    def __setattr__(self, name: str, value: Any) -> None:
        if self._frozen:
            raise AttributeError(f"EditResult is immutable: cannot set {name!r}")
        object.__setattr__(self, name, value)

    def with_transformations(self, transformations: Sequence[Any]) -> EditResult:
        """A copy listing these discrete transformations (the edit itself is shared)."""
        out = copy.copy(self)
        object.__setattr__(out, "transformations", tuple(transformations))
        object.__setattr__(out, "_origin", self)
        return out

    _origin: EditResult | None = None

    def release(self) -> None:
        """Drop the motions built on demand (edited, time-warped, refined; headings); they rebuild on access.

        The result stays the same edit: paths, times and residuals are kept,
        and motions built again are bitwise those built before (the same
        deterministic computation on the same arrays).  The editors call this
        on the results of older undo states to bound the history's memory.
        """
        for lazy in (self._headings, self.edited_motions, self._plain, self._refined):
            lazy.clear()
        self.__dict__.pop("_refined_list", None)
        if self._origin is not None:
            self._origin.release()

    def spatial_rhs(self) -> dict[int, Array]:
        """Right-hand sides (unweighted) each spatial constraint's rows were solved for, by index.

        For a :class:`~mocaplab.editing.constraints.Relative` these are the
        metric corrections of its linear rows (see
        :mod:`~mocaplab.editing.laplacian`); for the others, their targets.
        """
        out = {}
        for i, (which, sl) in self._sslices.items():
            r = self._sbw[sl] / math.sqrt(self.constraints[i].weight) if which == "soft" else self._sh[sl]
            out[i] = _ro(np.array(r))
        return out

    def _relative_conflicts(
        self, editor: SceneEditor, sol: SpatialSolution
    ) -> tuple[tuple[int, float, tuple[int, ...]], ...]:
        """``(constraint, metric error, hard constraints)`` of each soft Relative that hard constraints defeat."""
        found = editor._space.soft_conflicts(self._sfac, sol)
        if not found:
            return ()
        owner = {}
        for i, (which, sl) in self._sslices.items():
            if which == "soft":
                owner[(sl.start, sl.stop)] = i
        worst: dict[int, tuple[float, set[int]]] = {}
        for row, err, labels in found:
            i = next(i for (a, b), i in owner.items() if a <= row < b)
            pins = {lab[0] for lab in labels if isinstance(lab, tuple)}
            e, p = worst.get(i, (0.0, set()))
            worst[i] = (max(e, err), p | pins)
        return tuple((i, e, tuple(sorted(p))) for i, (e, p) in sorted(worst.items()) if p)

    def __init__(self, editor: SceneEditor, constraints: tuple[Any, ...]) -> None:
        self._ed = editor
        self.constraints = constraints
        self.characters = editor.characters
        self.original_paths = editor.paths
        self.stationary = tuple(tuple(s) for s in editor.segments)
        self.transformations: tuple[Any, ...] = ()
        sp_, tm = editor._space_sol, editor._time_sol
        assert sp_ is not None and tm is not None
        self._pbar, self._phat = sp_.pbar, sp_.phat
        self._t, self.active_steps = tm
        self._sfac: SpatialFactors = editor._sd.factors
        # the right-hand sides solved for (relative rows corrected to metres)
        self._sbw, self._sh, self._sslices = sp_.bw, sp_.h, editor._sd.slices
        self.relative_iterations = sp_.iterations
        self.settled = bool(sp_.settled and not sp_.warm)
        notes = list(self._sfac.notes()) + list(editor._td.factors.notes())
        tol = float(editor.options["relative_tolerance"])
        out_of_solves = sp_.iterations >= editor.options["relative_iterations"]
        # a drag's preview may stop early without a note (settle() goes on); a full update that stops says so
        if self._sfac.metric is not None and sp_.change > tol and (out_of_solves or sp_.diverged or sp_.stalled):
            notes.append(
                f"relative constraints: metric targets still changing by {sp_.change:.2g} m after "
                f"{sp_.iterations} solves (relative_tolerance {tol:g} m); residuals() shows the metric errors"
            )
        self.conflicts: tuple[tuple[int, float, tuple[int, ...]], ...] = self._relative_conflicts(editor, sp_)
        for i, err, pins in self.conflicts:
            notes.append(
                f"soft relative constraint #{i} is missed by {err:.3g} m: hard constraints "
                + ", ".join(f"#{j}" for j in pins)
                + " fix what it asks for, so the result is a least-squares compromise (move them, or make them soft)"
            )
        self.notes: tuple[str, ...] = tuple(notes)
        self._tfac: TimeFactors = editor._td.factors
        self._tbw, self._th, self._tslices = editor._td.bw, editor._td.h, editor._td.slices
        off = editor._space.layout.offsets
        P = _ro(self._phat.reshape(-1, 2).copy())
        Pb = _ro(self._pbar.reshape(-1, 2).copy())
        T = _ro(self._t.copy())
        K = len(self.characters)
        self.paths = tuple(P[off[k] : off[k + 1]] for k in range(K))
        self.shape_paths = tuple(Pb[off[k] : off[k + 1]] for k in range(K))
        self.times = tuple(T[off[k] : off[k + 1]] for k in range(K))
        self.end_effectors = editor._effectors
        self._headings = _Lazy(K, self._heading)
        self.edited_motions = _Lazy(K, self._edited_motion)
        self._plain = _Lazy(K, self._motion)
        self._refined = _Lazy(K, lambda k: self._refine_all()[k])
        self.motions = self._refined if editor.options["refine"] else self._plain
        self._frozen = True

    def __repr__(self) -> str:
        return (
            f"<EditResult: {len(self.paths)} characters, {len(self.constraints)} constraints, "
            f"hard residual {self.hard_residual_space:.2g} m / {self.hard_residual_time:.2g} s>"
        )

    # ------------------------------------------------------- orientation
    def _heading(self, k: int) -> tuple[Array, NDArray[np.bool_], Array]:
        d, f, t = heading_changes(
            self.original_paths[k],
            self.paths[k],
            segments=self.stationary[k],
            flip_rate=self._ed.options["flip_rate"],
            flip_window=self._ed.options["flip_window"],
        )
        return _ro(d), _ro(f), _ro(t)

    @property
    def heading_change(self) -> Sequence[Array]:
        """Yaw change of the path direction per frame, (F_k,) per character."""
        return _Lazy(len(self.paths), lambda k: self._headings[k][0])

    @property
    def flips(self) -> Sequence[NDArray[np.bool_]]:
        """Frames whose tangent flipped and was repaired, (F_k,) bool per character."""
        return _Lazy(len(self.paths), lambda k: self._headings[k][1])

    @property
    def tangents(self) -> Sequence[Array]:
        """Repaired unit tangent directions, (F_k, 2) per character."""
        return _Lazy(len(self.paths), lambda k: self._headings[k][2])

    # ------------------------------------------------------------ motions
    def _edited_motion(self, k: int) -> Motion:
        return apply_path(self.characters[k], self.paths[k], self._headings[k][0])

    @cached_property
    def clock_fps(self) -> float:
        f = self._ed.options["clock_fps"]
        return float(f) if f is not None else float(self.characters[0].fps)

    @cached_property
    def clock(self) -> Array:
        """Shared reference clock of :attr:`motions`, shape (N,)."""
        t0 = min(float(t[0]) for t in self.times)
        t1 = max(float(t[-1]) for t in self.times)
        n = int(math.floor((t1 - t0) * self.clock_fps + 1e-6)) + 1  # the time solve's rounding is not a lost frame
        if n * len(self.times) > MAX_CLOCK_FRAMES:
            raise ValueError(
                f"The edited motions would hold {n} clock frames for each of {len(self.times)} characters "
                f"({t1 - t0:.6g} s at clock_fps={self.clock_fps:g}), more than MAX_CLOCK_FRAMES = {MAX_CLOCK_FRAMES} "
                "in all: lower `clock_fps`, or bring the characters' times closer (time targets that chain "
                "far apart)"
            )
        return _ro(t0 + np.arange(n) / self.clock_fps)

    @property
    def active(self) -> Sequence[NDArray[np.bool_]]:
        """Clock ticks inside each character's time span, (N,) bool per character."""
        tol = 1e-9
        return tuple(_ro((self.clock >= t[0] - tol) & (self.clock <= t[-1] + tol)) for t in self.times)

    def _warp(self, k: int, motion: Motion) -> Motion:
        t = self.times[k]
        u = np.interp(self.clock, t, np.arange(len(t)))
        out = motion.sample(u / motion.fps, fps=self.clock_fps)
        if motion.path_joint != 0:
            # sample() interpolates joint 0's per-frame ground motion and the path joint's own
            # translation separately, which bends the path joint's course between frames by the
            # lever arm of that translation (metres: the travel from the static joint 0); move the
            # whole body (Motion.transformed) so that the path joint is where interpolating its positions
            # puts it, as it is when the path joint is joint 0
            want = _lerp(motion.pelvis_positions, u)
            out = out.transformed(translation=want - out.pelvis_positions)
        return out.replace(name=motion.name)

    def _motion(self, k: int) -> Motion:
        return self._warp(k, self.edited_motions[k])

    def _tick(self, k: int, frame: int) -> int:
        """Clock tick nearest to character ``k``'s frame ``frame``."""
        return int(round((float(self.times[k][frame]) - float(self.clock[0])) * self.clock_fps))

    def _effector_on_clock(self, ee: EndEffector) -> EndEffector:
        """``ee`` with its frames (the character's own) moved to the nearest clock ticks."""
        k = ee.character
        n = len(self.clock)
        runs = effector_frames(ee, len(self.times[k]))
        if isinstance(ee.frames, (int, np.integer)):
            frames: Any = min(self._tick(k, int(ee.frames)), n - 1)
        elif len(runs) == 1:
            a, b = self._tick(k, runs[0][0]), self._tick(k, runs[0][1] - 1) + 1
            frames = (a, min(max(b, a + 1), n))
        else:
            frames = sorted({min(self._tick(k, i), n - 1) for a, b in runs for i in range(a, b)})
        return dataclasses.replace(ee, frames=frames)

    @cached_property
    def _refined_list(self) -> list[Motion]:

        cache: RefineCache = self._ed._refine_cache
        clock = (float(self.clock[0]), float(self.clock_fps), len(self.clock))
        out: list[Any] = [None] * len(self.characters)
        for group in _effector_groups(self.end_effectors):
            kept = [cache.motion(k, clock, self.paths[k], self.times[k], self.end_effectors[k]) for k in group]
            if all(m is not None for m in kept):
                for k, m in zip(group, kept, strict=True):
                    out[k] = m
                continue

            def reference(k: int) -> tuple[Motion, Any]:
                ref = self._warp(k, self.characters[k])
                # the input's contacts, on the clock, of the roles' feet (or the `joints` option)
                return ref, foot_contacts(ref, joints=self._ed.contact_joints(k))

            refs = [cache.reference(k, clock, self.times[k], lambda k=k: reference(k)) for k in group]
            local = {k: i for i, k in enumerate(group)}
            ees = [_renumbered(self._effector_on_clock(ee), local) for k in group for ee in self.end_effectors[k]]
            refined = refine_scene(
                [self._plain[k] for k in group],
                ees,
                references=[r for r, _ in refs],
                contacts=[c for _, c in refs],
            )
            for k, m in zip(group, refined, strict=True):
                cache.store(k, clock, self.paths[k], self.times[k], self.end_effectors[k], m)
                out[k] = m
        return out

    def _refine_all(self) -> list[Motion]:
        return self._refined_list

    def refined(self) -> Sequence[Motion]:
        """Full-body refined motions on the shared clock (section 4.3).

        The time-warped motions (:attr:`motions` without refinement) go through
        :func:`mocaplab.editing.refinement.refine_scene` with the input clips warped the
        same way as references (the foot contacts of their
        :meth:`SceneEditor.contact_joints`, detected on them, are planted) and the
        scene's end-effector constraints, whose frames (each character's own
        frames) are mapped to the nearest clock ticks, so interactions between
        characters happen at the synchronised instant.
        """
        return self._refined

    # ------------------------------------------------------------ quality
    def _hard_res(self, fac: Any, x: Array, h: Array, extra: int) -> float:
        H = fac.H if hasattr(fac, "H") else fac.Hu
        if H.shape[0] == 0:
            return 0.0
        full = np.concatenate([h, np.zeros(extra)])
        return float(np.max(np.abs(H @ x - full)))

    @cached_property
    def hard_residual_space(self) -> float:
        """Largest violation of a hard spatial constraint (incl. rigid segments), metres."""
        return self._hard_res(self._sfac, self._phat, self._sh, self._ed._space.R.shape[0])

    @cached_property
    def hard_residual_time(self) -> float:
        """Largest violation of a hard temporal constraint, seconds."""
        return self._hard_res(self._tfac, self._t, self._th, 0)

    def residuals(self) -> dict[int, float]:
        """Largest residual of each path constraint, by index.

        Metres for positions, seconds for times; for a :class:`~mocaplab.editing.constraints.Relative`
        the *metric* error on the edited paths: the distance from the
        character to where its offset (metres, in the other's edited tangent
        frame) puts it, and for its ``direction`` the chord between the unit
        directions (about the angle, radians).  Direction pins: the tangent's
        distance from its target (metres per two frames).
        """
        out: dict[int, float] = {}
        metric = self._sfac.metric
        pair_errors = None
        for fac, x, bw, h, slices in (
            (self._sfac, self._phat, self._sbw, self._sh, self._sslices),
            (self._tfac, self._t, self._tbw, self._th, self._tslices),
        ):
            H = fac.H if hasattr(fac, "H") else fac.Hu
            soft_values = fac.Bw @ x if fac.Bw.shape[0] else np.zeros(0)
            hard_values = H @ x if H.shape[0] else np.zeros(0)
            if fac is self._sfac and metric is not None:  # every pair at once (one pass, not one per constraint)
                pair_errors = metric.pair_errors(x, soft_values, hard_values)
            for i, (which, sl) in slices.items():
                c = self.constraints[i]
                if isinstance(c, Relative) and pair_errors is not None and metric is not None:
                    sel = (metric.soft == (which == "soft")) & (metric.index >= sl.start) & (metric.index < sl.stop)
                    out[i] = float(np.max(pair_errors[sel])) if sel.any() else 0.0
                    continue
                if which == "soft":
                    r = (soft_values[sl] - bw[sl]) / math.sqrt(c.weight)
                else:
                    r = hard_values[sl] - h[sl]
                out[i] = float(np.max(np.abs(r))) if len(r) else 0.0
        return dict(sorted(out.items()))

    def _soft_max(self, slices: dict[int, tuple[str, slice]]) -> float:
        res = self.residuals()
        vals = [res[i] for i, (w, _) in slices.items() if w == "soft"]
        return max(vals, default=0.0)

    @cached_property
    def soft_residual_space(self) -> float:
        """Largest residual of a soft spatial constraint, metres."""
        return self._soft_max(self._sslices)

    @cached_property
    def soft_residual_time(self) -> float:
        """Largest residual of a soft temporal constraint, seconds."""
        return self._soft_max(self._tslices)

    @cached_property
    def shape_distortion(self) -> float:
        """RMS change of the Laplacian coordinates (eq. 3) over interior moving frames (dimensionless)."""
        sq, n = 0.0, 0
        for path, new in zip(self.original_paths, self.paths, strict=True):
            a = path.laplacian_coordinates()[1:-1]
            b = laplacian_coordinates(new)[1:-1]
            ok = ~path.degenerate[1:-1]
            d = (a - b)[ok]
            sq += float(np.sum(d * d))
            n += int(ok.sum())
        return math.sqrt(sq / n) if n else 0.0

    @cached_property
    def length_change(self) -> Array:
        """Relative change of each path's arc length, shape (K,) (0 = unchanged)."""
        out = []
        for path, new in zip(self.original_paths, self.paths, strict=True):
            L = float(np.sum(np.linalg.norm(np.diff(new, axis=0), axis=1)))
            out.append(L / path.length - 1.0 if path.length > 0 else 0.0)
        return _ro(np.array(out))

    @cached_property
    def min_time_step(self) -> float:
        """Smallest ``t[i+1] - t[i]`` over all characters, seconds."""
        return float(min(np.min(np.diff(t)) for t in self.times))

    @cached_property
    def min_time_step_ratio(self) -> float:
        """Smallest ``(t[i+1] - t[i]) / h`` over all characters."""
        return float(min(np.min(np.diff(t)) * m.fps for t, m in zip(self.times, self.characters, strict=True)))

    @cached_property
    def energies(self) -> Energies:
        """The shape, scale and time energies of equation 10."""
        sp_ = self._ed._space
        shape = sp_.shape_energy(self._sfac, self._sbw, self._pbar)
        scale = sp_.scale_energy(self._sfac, self._sbw, self._pbar, self._phat) if self._sfac.scale else 0.0
        time = self._ed._time.energy(self._tfac, self._tbw, self._t)
        return Energies(shape, scale, time)

    def report(self) -> dict[str, Any]:
        """The quality figures as a dict."""
        return {
            "hard_residual_space": self.hard_residual_space,
            "hard_residual_time": self.hard_residual_time,
            "soft_residual_space": self.soft_residual_space,
            "soft_residual_time": self.soft_residual_time,
            "shape_distortion": self.shape_distortion,
            "length_change": self.length_change.tolist(),
            "min_time_step": self.min_time_step,
            "min_time_step_ratio": self.min_time_step_ratio,
            "flipped_frames": [int(f.sum()) for f in self.flips],
            "energies": {"shape": self.energies.shape, "scale": self.energies.scale, "time": self.energies.time},
        }
