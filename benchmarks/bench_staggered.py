"""Staggered poses (Coleman et al. 2008): extraction and re-evaluation speed.

Targets (issue 7): extracting CMU 49_03 (1504 frames, 31 joints) in under
2 s, and a dense re-evaluation after an edit in under 50 ms so sliders feel
live.  Prints medians of repeats (wall clock and process CPU time: the
machine may be shared) and the ratio to each target.

Run: ``python benchmarks/bench_staggered.py`` (needs ``MOCAPLAB_DATA_DIR``).
"""

from __future__ import annotations

import os
import statistics
import time
import warnings
from collections.abc import Callable
from pathlib import Path

import numpy as np

from mocaplab import data, quat
from mocaplab.motion import Motion, Skeleton
from mocaplab.staggered import StaggeredTimingWarning, extract

EXTRACT_TARGET = 2.0
EVAL_TARGET = 0.050


def timed(fn: Callable[[], object], repeats: int) -> tuple[float, float, object]:
    walls, cpus = [], []
    out = None
    for _ in range(repeats):
        w, c = time.perf_counter(), time.process_time()
        out = fn()
        walls.append(time.perf_counter() - w)
        cpus.append(time.process_time() - c)
    return statistics.median(walls), statistics.median(cpus), out


def report(label: str, wall: float, cpu: float, target: float) -> None:
    print(
        f"{label:58s} {wall * 1e3:8.1f} ms wall {cpu * 1e3:8.1f} ms cpu   "
        f"{wall / target:5.2f} x target (wall) {cpu / target:5.2f} x target (cpu)"
    )


def main() -> None:
    if "MOCAPLAB_DATA_DIR" not in os.environ:
        default = Path(__file__).resolve().parents[2] / "shared" / "mocap"
        if default.is_dir():
            os.environ["MOCAPLAB_DATA_DIR"] = str(default)
    warnings.simplefilter("ignore", StaggeredTimingWarning)
    warnings.filterwarnings("ignore", "The motion path follows joint")
    clip = data.cmu("49_03")
    print(f"clip 49_03: {clip.n_frames} frames, {clip.n_joints} joints, {clip.fps:g} fps")
    extract(clip, optimize=False)  # warm caches (imports, FK)
    print(f"\nextraction (target {EXTRACT_TARGET:.1f} s)")
    wall, cpu, sm = timed(lambda: extract(clip), 3)
    report("extract (default: tangent start + Nelder-Mead polish)", wall, cpu, EXTRACT_TARGET)
    wall0, cpu0, _ = timed(lambda: extract(clip, optimize=False), 3)
    report("extract, tangent start only (optimize=False)", wall0, cpu0, EXTRACT_TARGET)
    out = sm.evaluate()  # type: ignore[union-attr]
    err_r = float(quat.angle(quat.mul(quat.inv(out.rotations), clip.rotations)).max())
    err_p = float(np.abs(out.root_positions - clip.root_positions).max())
    print(f"  {sm}\n  reconstruction: max {err_r:.1e} rad, {err_p:.1e} m")

    print(f"\ndense re-evaluation after an edit (target {EVAL_TARGET * 1e3:.0f} ms)")
    sm.evaluate()  # type: ignore[union-attr]
    roles = clip.skeleton.roles  # joints by role, never by name
    shoulders = [roles["left_shoulder"], roles["right_shoulder"]]
    arms = [roles["left_shoulder"], roles["left_elbow"], roles["right_shoulder"], roles["right_elbow"]]
    cases = {
        "succession s=0.01, l=2 on the whole body + evaluate": lambda: sm.succession(0.01, 2.0).evaluate(),
        "succession s=0.03, l=2 below the left shoulder + evaluate": lambda: sm.succession(
            0.03, 2.0, joint=roles["left_shoulder"]
        ).evaluate(),
        "random tau=0.03 s on every joint + evaluate": lambda: sm.randomize(0.03, seed=1).evaluate(),
        "exaggerate arms of one pose (w_r=0.5) + evaluate": lambda: sm.exaggerate(
            0.5, poses=[10], joints=shoulders
        ).evaluate(),
        "exaggerate arms of every pose (w_r=0.5) + evaluate": lambda: sm.exaggerate(0.5, joints=arms).evaluate(),
        "non-staggered playback (refinements zeroed), evaluate": lambda: sm.evaluate(staggered=False),
    }
    for label, fn in cases.items():
        wall, cpu, _ = timed(fn, 7)
        report(label, wall, cpu, EVAL_TARGET)

    # the same clip below a static joint 0, the pelvis travelling in translation channels on every joint
    static = static_root(clip)
    print(f"\nthe clip below a static joint 0, 6 channels per joint ({static.n_joints} joints)")
    wall, cpu, sm_b = timed(lambda: extract(static), 3)
    report("extract (default)", wall, cpu, EXTRACT_TARGET)
    out_b = sm_b.evaluate()  # type: ignore[union-attr]
    err_b = float(np.abs(out_b.global_positions() - static.global_positions()).max())
    print(f"  {sm_b}\n  reconstruction: max {err_b:.1e} m (joint positions)")
    wall, cpu, _ = timed(lambda: sm_b.succession(0.01, 2.0).evaluate(), 7)  # type: ignore[union-attr]
    report("succession s=0.01, l=2 on the whole body + evaluate", wall, cpu, EVAL_TARGET)


def static_root(clip: Motion) -> Motion:
    """``clip`` below a static joint 0 at the origin; the pelvis travel in ``translations``."""
    sk = clip.skeleton
    parents = np.concatenate([[-1], sk.parents + 1])
    parents[1] = 0
    offsets = np.concatenate([np.zeros((1, 3)), sk.offsets])
    six = ("Xposition", "Yposition", "Zposition", "Zrotation", "Yrotation", "Xrotation")
    new = Skeleton(
        ("Root",) + sk.names, parents, offsets, channels=(six,) * (sk.n_joints + 1),
        end_site_parents=sk.end_site_parents + 1, end_site_offsets=sk.end_site_offsets,
    )
    rot = np.concatenate([np.tile([0.0, 0.0, 0.0, 1.0], (clip.n_frames, 1, 1)), clip.rotations], axis=1)
    tr = np.array(np.broadcast_to(offsets, (clip.n_frames, sk.n_joints + 1, 3)))
    tr[:, 1] = clip.root_positions
    return Motion(new, rot, np.zeros((clip.n_frames, 3)), clip.fps, translations=tr, name=clip.name)


if __name__ == "__main__":
    main()
