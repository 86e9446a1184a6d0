"""Benchmark: physical touch-up (Shin, Kovar and Gleicher 2003).

The paper touched up a 111-frame curved walk in 0.172 s (Section 4.3, a 2.0 GHz
Xeon).  Here:

1. the full default ground schedule (lower body, upper body, arms: one pass of
   three adjustments, footplants re-enforced after each) on 111 frames of a
   bent CMU walk at 30 fps; target at least 20x faster than the paper;
2. the paper's Figure 9 protocol on the same clip (5 lower-body, 5 upper-body
   and 2 arm adjustments: 12 steps), which is what the 0.172 s most likely
   covered;
3. one pass of the default ground schedule on a 1500-frame clip (CMU 02_06 at
   120 fps); target under 0.5 s;
4. for information, the full default schedule (ground and flight) on 1500
   frames of CMU 49_03 (jumps and hops).

Each is timed with the default footplant step (``"plant"``: the refinement
module's plant goals and IK layer) and with the analytic leg IK (``"ik"``,
closest to the paper's choice of Kovar et al. 2002).  Figures are medians of
repeats, wall-clock and CPU time of this process (they differ when the machine
is shared; the ratios use the wall-clock time); body, contacts and the bent
input are built outside the timed region.
Run: ``python benchmarks/bench_touchup.py``.
"""

from __future__ import annotations

import statistics
import time

import numpy as np

from mocaplab import data, quat
from mocaplab.contacts import foot_contacts
from mocaplab.physics import GROUND_SCHEDULE, Body, touch_up

PAPER_SECONDS = 0.172  # 111 frames, Shin et al. 2003, section 4.3


def bend(motion, radius):
    """Turn a straight walk into an arc (heading proportional to the distance walked)."""
    p = motion.root_positions
    s = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(p[:, [0, 2]], axis=0), axis=1))])
    q = quat.from_yaw(s / radius)
    new = np.array(p)
    new[1:, [0, 2]] = p[0, [0, 2]] + np.cumsum(quat.rotate(q[:-1], np.diff(p, axis=0) * [1, 0, 1])[:, [0, 2]], axis=0)
    return motion.with_root(root_positions=new, root_rotations=quat.mul(q, motion.rotations[:, 0]))


def median_time(fn, repeats):
    """Median wall-clock and CPU seconds of ``fn()`` (after one warm-up call)."""
    fn()  # warm-up (imports, caches)
    wall, cpu = [], []
    for _ in range(repeats):
        t, c = time.perf_counter(), time.process_time()
        fn()
        wall.append(time.perf_counter() - t)
        cpu.append(time.process_time() - c)
    return statistics.median(wall), statistics.median(cpu)


def main() -> None:
    walk = data.cmu("16_15").resample(30)[:111]
    bent = bend(walk, 2.0)
    body = Body.from_skeleton(walk)
    contacts = foot_contacts(walk)
    figure9 = (GROUND_SCHEDULE[0],) * 5 + (GROUND_SCHEDULE[1],) * 5 + (GROUND_SCHEDULE[2],) * 2

    long_ground = data.cmu("02_06")[:1500]
    long_body = Body.from_skeleton(long_ground)
    long_contacts = foot_contacts(long_ground)
    hops = data.cmu("49_03")[:1500]
    hop_contacts = foot_contacts(hops)

    import os

    print(f"physical touch-up; paper: {PAPER_SECONDS * 1000:.0f} ms for 111 frames; load average {os.getloadavg()[0]:.1f}")
    print(f"{'case':58s} {'footplants':>10s} {'wall':>9s} {'cpu':>9s}  ratio (wall)")
    rows = []
    for fp in ("plant", "ik"):
        t1 = median_time(lambda fp=fp: touch_up(bent, body=body, contacts=contacts, schedule="ground", iterations=1, footplants=fp), 21)
        rows.append(("default ground schedule, 111 frames (3 steps)", fp, t1, f"{PAPER_SECONDS / t1[0]:5.1f}x faster than the paper (target >= 20x)"))
        t2 = median_time(lambda fp=fp: touch_up(bent, body=body, contacts=contacts, schedule=figure9, iterations=1, footplants=fp), 9)
        rows.append(("Figure 9 protocol, 111 frames (12 steps)", fp, t2, f"{PAPER_SECONDS / t2[0]:5.1f}x faster than the paper"))
        t3 = median_time(
            lambda fp=fp: touch_up(long_ground, body=long_body, contacts=long_contacts, schedule="ground", iterations=1, footplants=fp), 5
        )
        rows.append((f"default ground schedule, {long_ground.n_frames} frames at 120 fps (02_06)", fp, t3, f"{t3[0] / 0.5:5.2f} of the 0.5 s budget"))
        t4 = median_time(lambda fp=fp: touch_up(hops, body=long_body, contacts=hop_contacts, iterations=1, footplants=fp), 3)
        rows.append((f"ground + flight schedule, {hops.n_frames} frames (49_03 hops)", fp, t4, f"{t4[0] / 0.5:5.2f} of 0.5 s"))
    for name, fp, (wall, cpu), ratio in rows:
        print(f"{name:58s} {fp:>10s} {1000 * wall:6.1f} ms {1000 * cpu:6.1f} ms  {ratio}")


if __name__ == "__main__":
    main()
