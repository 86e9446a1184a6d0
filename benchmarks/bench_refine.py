"""Benchmark: full-body refinement of a 500-frame 120 fps CMU walk.

The walk 16_11 (first 500 frames) has its path bent by a progressive 90-degree
heading rotation, then :func:`mocaplab.editing.refinement.refine` plants both feet
through the contacts detected on the unbent clip.  Target (issue 4): under
100 ms.  Prints the median of repeats, the split between the IK layer and
the displacement map, and the quality figures.

Run: ``python benchmarks/bench_refine.py``
"""

from __future__ import annotations

import os
import time

import numpy as np

import mocaplab
from mocaplab import quat
from mocaplab.contacts import foot_contacts
from mocaplab.displacement import DisplacementMap, displacement_between
from mocaplab.editing.refinement import foot_skate, max_joint_angle_jump, refine
from mocaplab.goals import foot_goals, solve_goals

TARGET_MS = 100.0
REPEATS = 5 if os.environ.get("MOCAPLAB_FAST") == "1" else 15


def bend(motion, total_yaw):
    theta = np.linspace(0.0, total_yaw, motion.n_frames)
    step = quat.rotate(quat.from_yaw(theta[:-1]), np.diff(motion.root_positions, axis=0))
    root = np.concatenate([motion.root_positions[:1], motion.root_positions[:1] + np.cumsum(step, axis=0)])
    return motion.with_root(root_positions=root, root_rotations=quat.mul(quat.from_yaw(theta), motion.rotations[:, 0]))


def median_ms(fn, repeats=REPEATS, clock=time.perf_counter):
    fn()  # warm up
    times = []
    for _ in range(repeats):
        t0 = clock()
        fn()
        times.append(clock() - t0)
    return 1000.0 * float(np.median(times))


def main() -> None:
    clip = mocaplab.cmu("16_11")[:500]
    bent = bend(clip, np.pi / 2)
    contacts = foot_contacts(clip)
    print(f"clip 16_11[:500]: {clip.n_frames} frames at {clip.fps:g} fps, contacts {contacts}")

    t_refine = median_ms(lambda: refine(bent, contacts=contacts, reference=clip))
    # CPU time of this process: the wall time is inflated when the machine is shared
    t_cpu = median_ms(lambda: refine(bent, contacts=contacts, reference=clip), clock=time.process_time)
    t_detect = median_ms(lambda: refine(bent, reference=clip))
    goals = foot_goals(bent, contacts, reference=clip)
    t_goals = median_ms(lambda: foot_goals(bent, contacts, reference=clip))
    t_ik = median_ms(lambda: solve_goals(bent, goals))
    solved = solve_goals(bent, goals)
    d_root, d_rot = displacement_between(bent, solved)
    t_map = median_ms(lambda: DisplacementMap.fit(d_root, d_rot, spacing=30, levels=3).apply(bent))

    out = refine(bent, contacts=contacts, reference=clip)
    before = np.nanmean(foot_skate(bent, contacts))
    after = np.nanmean(foot_skate(out, contacts))
    print(f"refine (given contacts)      median {t_refine:7.1f} ms   target {TARGET_MS:.0f} ms   ratio {t_refine / TARGET_MS:.2f}")
    print(f"refine (given contacts), CPU median {t_cpu:7.1f} ms   ratio {t_cpu / TARGET_MS:.2f}")
    print(f"refine (contacts detected)   median {t_detect:7.1f} ms   ratio {t_detect / TARGET_MS:.2f}")
    print(f"  foot goals                 median {t_goals:7.1f} ms")
    print(f"  one IK pass                median {t_ik:7.1f} ms  (refine runs two)")
    print(f"  displacement map fit+apply median {t_map:7.1f} ms")
    print(f"skate per planted frame: {before:.2f} mm before, {after:.3f} mm after (ratio {after / before:.3f})")
    print(f"largest joint-angle jump introduced: {max_joint_angle_jump(bent, out):.2f} deg (limit 5)")


if __name__ == "__main__":
    main()
