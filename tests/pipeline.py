"""The whole mocaplab pipeline on one clip, judged by :mod:`mocaplab.quality` (test and benchmark helper).

:func:`run` takes a loaded clip through what a user does with it: a bend and
a squeeze of its path (Kim et al. 2009 §4.1) each followed by refinement
(§4.3), refinement of the unedited clip, the physical touch-up (Shin et al.
2003) of the clip and of the refined bend, staggered-pose extraction
(Coleman et al. 2008) with an exaggeration and a succession of the arms, and
a BVH export read back.  Each step's output is compared with its input by
:func:`mocaplab.quality.compare`, and timed.

``tests/test_quality_pipeline.py`` asserts the factors; ``benchmarks/
bench_quality.py`` prints the table over every clip of the data mirror.
"""

from __future__ import annotations

import dataclasses
import tempfile
import time
import warnings
from collections.abc import Callable, Iterator
from pathlib import Path

import numpy as np

import mocaplab as ml
from mocaplab import Motion, quality
from mocaplab.contacts import foot_contacts
from mocaplab.editing import PinPosition
from mocaplab.ik import UnreachableTargetWarning

#: Clips are trimmed to this many seconds (the corpus must run in minutes).
MAX_SECONDS = 20.0

#: The steps, in order: ``(name, input step)``; the input of each is the
#: named earlier output ("input" is the loaded clip).
STEPS: tuple[tuple[str, str], ...] = (
    ("bend", "input"),
    ("bend+refine", "input"),
    ("squeeze", "input"),
    ("squeeze+refine", "input"),
    ("refine", "input"),
    ("touch_up", "input"),
    ("bend+refine+touch_up", "bend+refine"),
    ("staggered", "input"),
    ("export", "input"),
)


@dataclasses.dataclass(frozen=True)
class StepResult:
    """One step of the pipeline on one clip."""

    clip: str
    step: str
    seconds: float
    report: quality.Comparison | None
    error: str = ""
    #: The step's :class:`~mocaplab.ik.UnreachableTargetWarning` messages: what the method said it could not do.
    unreachable: tuple[str, ...] = ()


def trimmed(motion: Motion, seconds: float = MAX_SECONDS) -> Motion:
    """The first ``seconds`` of a clip (the clip itself when shorter)."""
    n = int(round(seconds * motion.fps)) + 1
    return motion if motion.n_frames <= n else motion.sample(np.arange(n) / motion.fps)


def _pins(motion: Motion, *, bend: float, squeeze: float) -> list[PinPosition]:
    """Pins a user would set: a bend drags the middle of the path sideways, a squeeze pulls the end in.

    ``bend`` moves the middle frame sideways by that fraction of the chord (at
    least 0.3 m, so a clip on the spot is bent too); ``squeeze`` pulls the
    last frame towards the first by that fraction of the chord.  The first
    frame is pinned hard, the dragged ones soft: a clip that stands still
    for a while has rigid stationary segments (Kim et al. §4.1), in which two
    hard pins that disagree conflict, and the diagnosis of such a conflict
    is slow on long segments.
    """
    p = motion.pelvis_positions[:, [0, 2]]
    n = len(p)
    chord = p[-1] - p[0]
    length = float(np.linalg.norm(chord))
    if squeeze:
        return [PinPosition(0, 0, p[0], hard=True), PinPosition(0, n - 1, p[-1] - squeeze * chord, hard=False)]
    along = chord / length if length > 1e-6 else np.array([1.0, 0.0])
    side = np.array([-along[1], along[0]])
    return [
        PinPosition(0, 0, p[0], hard=True),
        PinPosition(0, n // 2, p[n // 2] + side * max(bend * length, 0.3), hard=False),
        PinPosition(0, n - 1, p[-1], hard=False),
    ]


def _edit(motion: Motion, *, bend: float = 0.0, squeeze: float = 0.0) -> Motion:
    return ml.edit([motion], _pins(motion, bend=bend, squeeze=squeeze)).motions[0]


def _refine(motion: Motion, reference: Motion) -> Motion:
    return ml.refine(motion, contacts=foot_contacts(reference), reference=reference)


def _arms(motion: Motion) -> list[str]:
    roles = motion.skeleton.roles
    return [roles[f"{side}_{part}"] for side in ("left", "right") for part in ("shoulder", "elbow")
            if f"{side}_{part}" in roles]


def _staggered(motion: Motion) -> Motion:
    arms = _arms(motion)
    sm = ml.extract(motion)
    styled = ml.staggered.exaggerate(sm, 0.5, joints=arms, reference="average")
    return ml.staggered.succession(styled, 0.02, 2.0, joint=arms[::2]).evaluate()


def _export(motion: Motion) -> Motion:
    with tempfile.TemporaryDirectory(prefix="mocaplab_pipeline_") as folder:
        path = Path(folder) / "clip.bvh"
        ml.save_bvh(motion, path, scale=0.01)  # centimetres, read back as such
        return ml.load(path, scale=0.01)


def step_functions(motion: Motion) -> dict[str, Callable[[Motion], Motion]]:
    """Each step as a function of its input motion."""
    bend_chord, squeeze_chord = 0.25, 0.4
    return {
        "bend": lambda m: _edit(m, bend=bend_chord),
        "bend+refine": lambda m: _refine(_edit(m, bend=bend_chord), m),
        "squeeze": lambda m: _edit(m, squeeze=squeeze_chord),
        "squeeze+refine": lambda m: _refine(_edit(m, squeeze=squeeze_chord), m),
        "refine": lambda m: _refine(m, m),
        "touch_up": lambda m: ml.touch_up(m).motion,
        "bend+refine+touch_up": lambda m: ml.touch_up(m).motion,
        "staggered": _staggered,
        "export": _export,
    }


def run(motion: Motion, *, steps: tuple[str, ...] | None = None) -> Iterator[StepResult]:
    """Each step of :data:`STEPS` (or those named) on ``motion``: its comparison with its input and its time.

    A step that raises is reported with its error (the corpus benchmark
    must see every clip through); the steps that build on it are skipped.
    """
    wanted = [s for s, _ in STEPS] if steps is None else list(steps)
    functions = step_functions(motion)
    outputs: dict[str, Motion] = {"input": motion}
    needed = set(wanted)
    for name, source in reversed(STEPS):
        if name in needed:
            needed.add(source)
    for name, source in STEPS:
        if name not in needed:
            continue
        if source not in outputs:
            yield StepResult(motion.name, name, 0.0, None, f"skipped: {source} failed")
            continue
        start = time.perf_counter()
        try:
            with warnings.catch_warnings(record=True) as said:
                warnings.simplefilter("always")
                out = functions[name](outputs[source])
        except Exception as exc:  # noqa: BLE001 - the corpus reports every failure and goes on
            yield StepResult(motion.name, name, time.perf_counter() - start, None, f"{type(exc).__name__}: {exc}")
            continue
        seconds = time.perf_counter() - start
        outputs[name] = out
        unreachable = tuple(str(w.message) for w in said if issubclass(w.category, UnreachableTargetWarning))
        if name in wanted:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                report = quality.compare(outputs[source], out)
            yield StepResult(motion.name, name, seconds, report, unreachable=unreachable)
