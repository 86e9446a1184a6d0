"""The discrete editor: Algorithm 1 of Kim et al. 2009 around a continuous editor (section 5.2).

:class:`DiscreteEditor` owns the discrete state (the characters' current
structure as :class:`~mocaplab.editing.discrete.transformations.Track`, the
transformations applied, the history) and a continuous
:class:`~mocaplab.editing.scene.SceneEditor` of the current, transformed
scene, which it replaces when a transformation is applied.  Its interface is
the scene editor's (``drag``, ``add``, ``remove``, ``replace``,
``set_constraints``, ``constraints``, ``result``), so the widgets drive either.

Greedy optimisation (Algorithm 1)
---------------------------------
On every constraint update, every surviving transformation of every
character (:func:`~mocaplab.editing.discrete.transformations.enumerate_transformations`,
pruned by :func:`~mocaplab.editing.discrete.pruning.prune`) is scored with
equation 10 on subsampled paths, all in one batch
(:class:`~mocaplab.editing.discrete.evaluation.SubsampledScene`).  The best
candidate is applied if it lowers ``E`` by more than ``min_gain``; at most one
transformation per update (section 5.2).  The first solve (and so
``edit(..., discrete=True)``) repeats the greedy step up to ``max_initial``
times (a jump from no constraints to the given ones is like a long drag);
those steps are one undo step, so reset returns to the untransformed clips.
Our addition (``DiscreteOptions.verify``): the few best candidates are
re-scored on paths subsampled 1 in 5, and the chosen one is kept only if the
full solve confirms the gain, because the 1/25 subsampling sometimes
misjudges strongly curved paths and the transformation would be undone at
the next update.  The transformed scene's continuous editor reuses the
stationary segments of the characters that did not change.

Constraints keep referring to the frames of the *input* clips; they are
mapped to the current frames of the transformed characters (a frame follows
its pose: :attr:`Track.origin`; constraints on removed frames, which the
pruning rules never allow for existing constraints, go to the nearest
surviving frame).  The returned :class:`~mocaplab.editing.scene.EditResult`
is that of the transformed scene: ``result.characters`` are the transformed
clips, ``result.constraints`` the mapped constraints (same order and
indices), ``result.transformations`` every transformation applied so far.
"""

from __future__ import annotations

import dataclasses
import math
import time
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np
from numpy.typing import NDArray

from ...undo import Undoable, UndoStack
from ..constraints import ConstraintError
from ..energy import deformation_energy
from ..graph import MotionGraph, SimilarityWeights, build_graph
from ..paths import stationary_segments
from ..scene import EditResult, SceneEditor, WarmResults
from .evaluation import SubsampledScene
from .pruning import Locality, protected_by_character, prune
from .transformations import (
    GraphArrays,
    Track,
    Transformation,
    apply_transformation,
    enumerate_transformations,
    map_constraint,
)

__all__ = ["DiscreteOptions", "DiscreteEditor", "Step", "Timing"]

Array = NDArray[np.float64]

_UNDO_LIMIT = 100  # undo steps kept (each holds a result and, after a transformation, its scene editor)


@dataclasses.dataclass(frozen=True)
class DiscreteOptions:
    """Options of discrete editing (``DiscreteEditor(..., discrete=DiscreteOptions(...))``; ``True`` = defaults).

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
    threshold, window, min_gap : float
        Parameters of the default graphs (:func:`~mocaplab.editing.graph.build_graph`):
        frame distance, and seconds.
    weights : SimilarityWeights, optional
        Weights of the default graphs' frame distance.

    Raises
    ------
    ValueError
        For durations out of order, negative weights or gains, or counts below their minimum.
    TypeError
        For a ``locality`` that is neither a Locality nor a mapping of them.

    Examples
    --------
    >>> opts = DiscreteOptions(subsample=10, max_initial=2)
    >>> opts.subsample, opts.max_duration, opts.locality_of(0) == opts.locality
    (10, 2.0, True)
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


@dataclasses.dataclass(frozen=True)
class Step:
    """One applied transformation and what it was chosen from.

    Attributes
    ----------
    transformation : Transformation
    candidates : tuple of Transformation
        The pruned candidates of that greedy step.
    energies : tuple of float
        Their subsampled equation-10 energies (same order).
    baseline : float
        The energy without a transformation.
    constraints : tuple
        The constraints mapped to the frames before the transformation.
    times, positions : ndarray
        The transformed character's edited frame times (F,) and ground
        positions (F, 2) before it (for locality checks).
    """

    transformation: Transformation
    candidates: tuple[Transformation, ...]
    energies: tuple[float, ...]
    baseline: float
    constraints: tuple[Any, ...]
    times: Array
    positions: Array


@dataclasses.dataclass(frozen=True)
class Timing:
    """Seconds spent by one greedy step: enumerate + prune, evaluate, verify; CPU seconds; candidates."""

    enumerate: float
    evaluate: float
    verify: float
    cpu: float
    candidates: int


def _update(scene: SceneEditor, constraints: tuple[Any, ...]) -> None:
    """Give ``scene`` these constraints: a target drag (right-hand sides only) when one constraint moved.

    The inner scene keeps no history of its own (the discrete editor's
    :attr:`DiscreteEditor.undo_stack` holds its snapshots), so its private
    solve is called rather than its recording ``replace``.
    """
    old = scene.constraints
    if old == constraints:
        return
    diff = [i for i, (x, y) in enumerate(zip(old, constraints, strict=False)) if x != y]
    if len(old) == len(constraints) and len(diff) == 1 and type(old[diff[0]]) is type(constraints[diff[0]]):
        scene._set(constraints, changed=diff[0])
    else:
        scene._set(constraints, changed=None)


def _options(discrete: Any) -> DiscreteOptions:
    if discrete is True:
        return DiscreteOptions()
    if isinstance(discrete, DiscreteOptions):
        return discrete
    raise TypeError(f"Expected `discrete` as True or a DiscreteOptions, got {type(discrete).__name__} {discrete!r}")


class DiscreteEditor(Undoable):
    """Interactive editing with discrete transformations (section 5; see the module docstring).

    Parameters
    ----------
    motions : Motion or sequence of Motion
        The input clips (never modified).
    constraints : sequence of constraints
        On the input clips' frames.
    discrete : True or DiscreteOptions
        The discrete-editing options (``True``: the defaults).
    **options
        Options of the continuous :class:`~mocaplab.editing.scene.SceneEditor`.

    Attributes
    ----------
    characters : tuple of Motion
        The input clips (with the ``roles`` option applied).
    tracks : tuple of Track
        Current structure of each character.
    applied : tuple of Transformation
    history : tuple of Step
    timings : tuple of Timing
        One per greedy step.
    updates : int
        Constraint updates so far.
    undo_stack : mocaplab.undo.UndoStack
        The edit history (not to be confused with :attr:`history`, the
        record of applied transformations), behind ``undo``/``redo``/``reset``
        (:class:`mocaplab.undo.Undoable`). Its initial state is the input
        before the constructor's greedy steps (``max_initial``), which are an
        undo step of their own: ``reset()`` returns to the untransformed clips.

    Notes
    -----
    Undo, redo and reset work as for
    :class:`~mocaplab.editing.scene.SceneEditor`, and one undo step is the
    same: one constraint update, consecutive drags of one constraint (and
    an :meth:`add` followed by drags of its constraint) merged until
    :meth:`checkpoint`.  A state (:meth:`snapshot`) is the whole discrete
    state: the constraints, the tracks (the current transformed motions),
    the transformations applied (:attr:`applied`, :attr:`history`), the
    continuous editor of the transformed scene and its own state, and the
    result; so undoing a drag that inserted steps removes them.  The
    initial state is the input (the untransformed clips under the given
    constraints): the greedy steps of the first update (``max_initial``)
    are the first undo step.  As in the scene editor, only the few most
    recently current results keep their built motions
    (:class:`~mocaplab.editing.scene.WarmResults`).
    :attr:`timings`, :attr:`updates` and :attr:`factorizations` count the
    work done and are not undone.

    Examples
    --------
    Pull the end of a 30 fps walk half as far again: the editor adds a
    gait cycle instead of stretching the steps.

    >>> from mocaplab.data import cmu
    >>> from mocaplab.editing import PinPosition
    >>> walk = cmu("16_15").resample(30)
    >>> p = walk.root_positions[:, [0, 2]]
    >>> ed = DiscreteEditor([walk], [PinPosition(0, 0, p[0], hard=True), PinPosition(0, len(p) - 1, p[-1], hard=True)])
    >>> res = ed.drag(1, p[0] + 1.5 * (p[-1] - p[0]))
    >>> [str(t) for t in res.transformations]
    ['character 0: duplicate frames 65..100 (1.20 s)']
    """

    def __init__(
        self, motions: Any, constraints: Sequence[Any] = (), *, discrete: Any = True, **options: Any
    ) -> None:
        self.discrete_options = _options(discrete)
        o = self.discrete_options
        scene = SceneEditor(motions, constraints, **options)
        self.characters = scene.characters
        self.options = dict(scene.options)
        graphs: dict[int, MotionGraph] = {}
        built: dict[int, MotionGraph] = {}
        given = dict(o.graphs or {})
        for k, m in enumerate(self.characters):
            if k in given:
                g = given[k]
                if not isinstance(g, MotionGraph):
                    raise TypeError(f"Expected graphs[{k}] to be a MotionGraph, got {type(g).__name__}")
            elif id(m) in built:
                g = built[id(m)]
            else:
                g = build_graph([m], weights=o.weights, threshold=o.threshold, window=o.window, min_gap=o.min_gap)
                built[id(m)] = g
            graphs[k] = g
        self.graphs = graphs
        arrays: dict[int, GraphArrays] = {}
        tracks = []
        for k, m in enumerate(self.characters):
            g = graphs[k]
            if id(g) not in arrays:
                arrays[id(g)] = GraphArrays(g)
            tracks.append(Track.from_motion(m, g, arrays[id(g)]))
        self.tracks: tuple[Track, ...] = tuple(tracks)
        self._nodes0 = [t.nodes for t in self.tracks]
        self.applied: tuple[Transformation, ...] = ()
        self.history: tuple[Step, ...] = ()
        self.timings: tuple[Timing, ...] = ()
        self.updates = 0
        self._scene = scene
        self._retired_factorizations = 0
        self._constraints: tuple[Any, ...] = ()
        # the initial undo state is the input: the untransformed clips under the given constraints;
        # the first update's greedy steps (up to max_initial) are the first undoable step
        self._constraints = scene.constraints
        self._result = scene.result.with_transformations(())
        self.undo_stack: UndoStack[tuple[Any, ...]] = UndoStack(self.snapshot(), limit=_UNDO_LIMIT)
        self._warm = WarmResults()
        self._merging: Any = None  # merge key of the last recorded edit, until a checkpoint
        result = self._set(scene.constraints)
        if self.applied:
            self._warm.touch(self.undo_stack.initial[-1])
            self._record(result)
        else:  # nothing applied: the input is the current state
            self.undo_stack = UndoStack(self.snapshot(), limit=_UNDO_LIMIT)
            self._warm.touch(result)

    # ------------------------------------------------------------ public
    @property
    def constraints(self) -> tuple[Any, ...]:
        """The constraints, on the input clips' frames."""
        return self._constraints

    @property
    def result(self) -> EditResult:
        """The current edit (of the transformed scene)."""
        assert self._result is not None
        return self._result

    @property
    def scene(self) -> SceneEditor:
        """The continuous editor of the current, transformed scene."""
        return self._scene

    @property
    def factorizations(self) -> int:
        """Factorisations so far, over every continuous editor this one has used."""
        return self._retired_factorizations + self._scene.factorizations

    def contact_joints(self, character: int) -> tuple[str, ...]:
        return self._scene.contact_joints(character)

    def drag(self, constraint_index: int, new_target: Any) -> EditResult:
        """Move constraint ``constraint_index``'s target and run one update of Algorithm 1.

        Consecutive drags of one constraint are one undo step (until :meth:`checkpoint`).
        """
        i = self._check_index(constraint_index)
        c = self._constraints[i]
        if not hasattr(c, "with_target"):
            raise TypeError(f"constraint #{i} {c!r} has no draggable target")
        new = list(self._constraints)
        new[i] = c.with_target(new_target)
        return self._record(self._set(tuple(new)), merge=("edit", i))

    def add(self, constraint: Any) -> int:
        """Append a constraint (update); returns its index.  Drags of it that follow merge into this undo step."""
        index = len(self._constraints)
        self._record(self._set(self._constraints + (constraint,)), merge=("edit", index))
        return index

    def remove(self, index: int) -> EditResult:
        """Remove constraint ``index`` (update; one undo step)."""
        i = self._check_index(index)
        return self._record(self._set(self._constraints[:i] + self._constraints[i + 1 :]))

    def replace(self, index: int, constraint: Any) -> EditResult:
        """Put ``constraint`` in place of constraint ``index`` (update; one undo step)."""
        i = self._check_index(index)
        new = list(self._constraints)
        new[i] = constraint
        return self._record(self._set(tuple(new)))

    def set_constraints(self, constraints: Sequence[Any]) -> EditResult:
        """Replace every constraint (update; one undo step)."""
        return self._record(self._set(tuple(constraints)))

    # ----------------------------------------------------------- history
    def snapshot(self) -> tuple[Any, ...]:
        """The whole discrete state (see the class notes), for :meth:`restore`."""
        return (
            self._constraints,
            self.tracks,
            self.applied,
            self.history,
            self._scene,
            self._scene.snapshot(),
            self._result,
        )

    def restore(self, state: tuple[Any, ...]) -> None:
        """Go back to a :meth:`snapshot` (the history of edits is not touched; see :meth:`undo`)."""
        constraints, tracks, applied, history, scene, scene_state, result = state
        if scene is not self._scene:  # keep `factorizations` counting the work done
            self._retired_factorizations += self._scene.factorizations - scene.factorizations
        scene.restore(scene_state)
        self._constraints, self.tracks, self.applied, self.history = constraints, tracks, applied, history
        self._scene, self._result = scene, result

    def _record(self, result: EditResult, merge: Any = None) -> EditResult:
        replaces = merge is not None and merge == self._merging  # the stack merges this push into the newest
        self.undo_stack.push(self.snapshot(), merge=merge)
        self._merging = merge
        self._warm.touch(result, replaces=replaces)
        return result

    def _go(self, state: tuple[Any, ...]) -> EditResult:
        """Make an undo state current (undo, redo, reset)."""
        left = self._scene
        self.restore(state)
        if self._scene is not left:
            left.trim()
        self._merging = None
        self._warm.touch(self.result)
        return self.result

    def _here(self) -> EditResult:
        return self.result

    def _gesture_ended(self) -> None:
        self._merging = None

    def _check_index(self, index: Any) -> int:
        n = len(self._constraints)
        if isinstance(index, bool) or not isinstance(index, (int, np.integer)) or not -n <= index < n:
            raise IndexError(f"Expected a constraint index in 0..{n - 1}, got {index!r}")
        return int(index) % n

    # ----------------------------------------------------------- mapping
    def _changed(self, tracks: Sequence[Track]) -> list[bool]:
        return [t.nodes is not self._nodes0[k] for k, t in enumerate(tracks)]

    def map_constraints(self, constraints: Sequence[Any], tracks: Sequence[Track] | None = None) -> tuple[Any, ...]:
        """``constraints`` (input-clip frames) on the current frames of ``tracks`` (default: the editor's)."""
        tracks = self.tracks if tracks is None else tracks
        ch = self._changed(tracks)
        if not any(ch):
            return tuple(constraints)
        return tuple(map_constraint(c, tracks, ch) for c in constraints)

    def _scene_options(self, tracks: Sequence[Track], base: SceneEditor, k: int) -> dict[str, Any]:
        """Options of a continuous editor for ``tracks`` where only character ``k`` differs from ``base``.

        The stationary segments of the other characters are reused; ``k``'s
        are detected again on its new motion (or mapped, if they were given).
        """
        opts = dict(self.options)
        st = self.options["stationary"]
        segs = [list(s) for s in base.segments]
        if st is None or st is False:
            return opts
        if isinstance(st, str):
            segs[k] = stationary_segments(
                tracks[k].motion,
                speed=opts["stationary_speed"],
                min_duration=opts["stationary_min_duration"],
                contacts="auto" if st == "auto" else None,
                joints=base.contact_joints(k),
            )
        else:
            out = []
            for a, b in st[k]:
                a2, b2 = tracks[k].frame_of(a), tracks[k].frame_of(b - 1) + 1
                if b2 - a2 >= 3:
                    out.append((a2, b2))
            segs[k] = out
        opts["stationary"] = segs
        return opts

    # ------------------------------------------------------------ greedy
    def _scored(
        self, tracks: Sequence[Track], scene: SceneEditor, mapped: tuple[Any, ...], subsample: int
    ) -> SubsampledScene:
        o = self.discrete_options
        result = scene.result
        starts = self.options.get("start_times") or [0.0] * len(tracks)
        return SubsampledScene(
            tracks,
            scene.paths,
            mapped,
            scene.segments,
            starts,
            subsample=subsample,
            cs=o.cs,
            ct=o.ct,
            step=int(self.options["variational_step"]),
            tangents=scene.tangent_rows,
            deformed=result.paths,
        )

    def _best(
        self, tracks: Sequence[Track], scene: SceneEditor, mapped: tuple[Any, ...]
    ) -> tuple[list[Transformation], dict[str, Any], Timing]:
        o = self.discrete_options
        result = scene.result
        t0 = time.perf_counter()
        c0 = time.process_time()
        cands: list[Transformation] = []
        protected = protected_by_character(mapped)
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
                protected=protected,
            )
        t1 = time.perf_counter()
        if not cands:
            return [], {}, Timing(t1 - t0, 0.0, 0.0, time.process_time() - c0, 0)
        scored = self._scored(tracks, scene, mapped, int(o.subsample))
        energies = scored.energies(cands)
        base = scored.baseline
        t2 = time.perf_counter()
        timing = Timing(t1 - t0, t2 - t1, 0.0, time.process_time() - c0, len(cands))
        order = [int(i) for i in np.argsort(energies, kind="stable") if energies[i] < base - o.min_gain]
        best = [
            dataclasses.replace(cands[i], energy=float(energies[i]), baseline=float(base), update=self.updates)
            for i in order
        ]
        info = {"candidates": tuple(cands), "energies": tuple(float(e) for e in energies), "baseline": float(base)}
        return best, info, timing

    def _refine_ranking(
        self, ranked: list[Transformation], tracks: Sequence[Track], scene: SceneEditor, mapped: tuple[Any, ...]
    ) -> list[Transformation]:
        """Re-score the best ``verify`` candidates on paths subsampled ``verify_subsample``; keep those that still gain."""
        o = self.discrete_options
        top = ranked[: int(o.verify)]
        if int(o.verify_subsample) == int(o.subsample):
            return top
        scored = self._scored(tracks, scene, mapped, int(o.verify_subsample))
        fine = scored.energies(top)
        base = scored.baseline
        keep = [(float(e), i) for i, e in enumerate(fine) if e < base - o.min_gain]
        return [top[i] for _, i in sorted(keep)]

    def _set(self, constraints: tuple[Any, ...]) -> EditResult:
        """Algorithm 1 for one constraint update; on any error the editor keeps its state."""
        o = self.discrete_options
        steps = int(o.max_initial) if self.updates == 0 else 1
        tracks = list(self.tracks)
        applied = list(self.applied)
        history: list[Step] = []
        timings: list[Timing] = []
        retired = 0
        mapped = self.map_constraints(constraints, tracks)
        scene = self._scene
        snapshot = scene.snapshot()
        try:
            _update(scene, mapped)
            result = scene.result
            for _ in range(steps):
                ranked, info, timing = self._best(tracks, scene, mapped)
                if not ranked:
                    timings.append(timing)
                    break
                t0 = time.perf_counter()
                if o.verify:
                    ranked = self._refine_ranking(ranked, tracks, scene, mapped)
                current = deformation_energy(result, cs=o.cs, ct=o.ct) if o.verify else math.nan
                accepted = None
                for best in ranked[:1] if o.verify else ranked:
                    k = best.character
                    trial = list(tracks)
                    trial[k] = apply_transformation(tracks[k], best, blend=o.blend)
                    trial_mapped = self.map_constraints(constraints, trial)
                    try:
                        t_scene = SceneEditor(
                            [t.motion for t in trial], trial_mapped, **self._scene_options(trial, scene, k)
                        )
                    except ConstraintError:
                        continue  # the transformed scene cannot be edited under these constraints
                    t_result = t_scene.result
                    if o.verify:
                        full = deformation_energy(t_result, cs=o.cs, ct=o.ct)
                        if not full < current - o.min_gain:
                            continue
                        best = dataclasses.replace(best, full_energy=float(full), full_baseline=float(current))
                    accepted = (best, trial, trial_mapped, t_scene, t_result)
                    break
                timings.append(dataclasses.replace(timing, verify=time.perf_counter() - t0))
                if accepted is None:
                    break
                best, new_tracks, new_mapped, new_scene, new_result = accepted
                k = best.character
                history.append(
                    Step(
                        best,
                        info["candidates"],
                        info["energies"],
                        info["baseline"],
                        mapped,
                        result.times[k],
                        result.paths[k],
                    )
                )
                applied.append(best)
                if new_scene is not scene:
                    retired += scene.factorizations
                tracks, mapped, scene, result = new_tracks, new_mapped, new_scene, new_result
        except Exception:
            self._scene.restore(snapshot)
            raise
        self._retired_factorizations += retired
        if scene is not self._scene:
            self._scene.trim()  # the scene left is kept for undo only
        self.tracks = tuple(tracks)
        self.applied = tuple(applied)
        self.history += tuple(history)
        self.timings += tuple(timings)
        self._scene = scene
        self._constraints = constraints
        self.updates += 1
        self._result = result.with_transformations(self.applied)
        return self._result
