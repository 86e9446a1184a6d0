"""No runaway: every option that sizes work is checked before anything is allocated (issue 27, item 2).

Each case runs in a child process limited to 500 MB of address space
(``RLIMIT_AS``) with 5 s to fail (``SIGALRM``, armed once the data is
loaded): it must end with the ValueError naming the option and its limit,
not a MemoryError, not a timeout.  Before the checks these cases took
minutes and gigabytes (a soft ``Sync`` offset of 10,000 s: 53 s and 8.7 GB;
``extract`` at 10,000 fps: more than 150 s; ``filter_sigma=1e9``: a 5 TiB
allocation).
"""

from __future__ import annotations

import os
import subprocess
import sys

import numpy as np
import pytest

posix_only = pytest.mark.skipif(os.name != "posix", reason="resource limits and alarms are POSIX")

LIMIT_MB = 500
SECONDS = 5

PRELUDE = f"""
import resource, signal, sys, time
resource.setrlimit(resource.RLIMIT_AS, ({LIMIT_MB} << 20, {LIMIT_MB} << 20))
import numpy as np
from mocaplab import data
from mocaplab.editing import AbsoluteTime, Duration, SceneEditor, Sync, edit
from mocaplab.staggered import extract
from mocaplab.staggered.features import analyze
from mocaplab.staggered.noise import orientation_filter
walk = data.cmu("16_15")
a = walk[:118]
signal.alarm({SECONDS})  # the default action ends the process: a case that runs on is a failure
start = time.perf_counter()
try:
"""

EPILOGUE = """
except ValueError as exc:
    print("ValueError:", exc)
except MemoryError as exc:
    print("MemoryError:", exc)
else:
    print("no error")
print("seconds", time.perf_counter() - start)
"""

CASES = {
    "soft Sync offset of 10,000 s": (
        "edit([a, a], [Sync(1, 0, other=0, other_frame=0, offset=10_000.0)]).motions[0]",
        "`offset` within +-19.6667 s (10 times the scene's duration",
    ),
    "hard AbsoluteTime at 1e6 s": (
        "edit([a, a], [AbsoluteTime(1, 0, 1e6, hard=True)]).motions[0]",
        "Expected `time` within +-19.6667 s",
    ),
    "AbsoluteTime measured from the character's start": (
        "edit([a, a], [AbsoluteTime(1, 0, 5.0 + 19.7)], start_times=[0.0, 5.0]).motions[0]",
        "Expected `time` from -14.6667 to 24.6667 s",
    ),
    "soft Duration of 1e6 s": (
        "edit([a], [Duration(0, 0, 100, 1e6)]).motions[0]",
        "Expected `duration` within +-9.83333 s",
    ),
    "start_times 1e6 s apart": (
        "edit([a, a], [], start_times=[0.0, 1e6]).motions[0]",
        "Expected `start_times[1]` within +-19.6667 s",
    ),
    "clock_fps 1e5": (
        "edit([a], [], clock_fps=1e5).motions[0]",
        "Expected `clock_fps` from 0.1 to MAX_CLOCK_FPS = 1000 frames per second, got 100000.0",
    ),
    "clock_fps 9,999 (a rate a Motion may have)": (
        "edit([a, a, a, a], [], clock_fps=9_999.0).motions[0]",
        "Expected `clock_fps` from 0.1 to MAX_CLOCK_FPS = 1000 frames per second, got 9999.0",
    ),
    "clock_fps NaN": ("edit([a], [], clock_fps=float('nan')).motions[0]", "Expected `clock_fps` from 0.1"),
    "Syncs chained to the reach, at 1000 fps": (
        "edit([a] * 6, [Sync(k + 1, 0, other=k, other_frame=0, offset=58.9, hard=True) for k in range(5)], "
        "clock_fps=1000.0).motions[0]",
        "more than MAX_CLOCK_FRAMES = 1000000 in all",
    ),
    "a drag of a Sync offset to 10,000 s": (
        "ed = SceneEditor([a, a], [Sync(1, 0, other=0, other_frame=0, offset=0.5)])\n"
        "    ed.drag(0, 10_000.0)",
        "constraint #0 Sync(",
    ),
    "extract at 10,000 fps": (
        "extract(walk.sample(np.arange(0.0, 1.0, 1e-4), fps=10_000.0))",
        "Expected the clip's frame rate from 0 to MAX_FPS = 1000 frames per second",
    ),
    "extract(filter_sigma=1e9)": (
        "extract(walk, filter_sigma=1e9)",
        "Expected `filter_sigma` from 0 to MAX_FILTER_SECONDS = 1 seconds, got 1000000000.0",
    ),
    "extract(constraint_window=1e9)": (
        "extract(walk, constraints=True, constraint_window=1e9)",
        "Expected `constraint_window` from 0 to MAX_FILTER_SECONDS = 1 seconds",
    ),
    "analyze(filter_width=1e9)": (
        "analyze(walk, filter_width=1e9)",
        "Expected `filter_width` from 0 to MAX_FILTER_SECONDS = 1 seconds",
    ),
    "analyze(smoothing=10**12)": (
        "analyze(walk, smoothing=10**12)",
        "Expected `smoothing` from 0 to 28800 iterations at 120 fps",
    ),
    "orientation_filter with sigma 1e9 s": (
        "orientation_filter(walk.rotations, 1e9, 120.0)",
        "Expected `sigma` from 0 to MAX_FILTER_SECONDS = 1 seconds",
    ),
}


@posix_only
@pytest.mark.parametrize("case", list(CASES))
def test_each_option_that_sizes_work_fails_fast_and_small(case, mocap_dir):
    code, message = CASES[case]
    script = PRELUDE + "    " + code + EPILOGUE
    env = {**os.environ, "OPENBLAS_NUM_THREADS": "1", "OMP_NUM_THREADS": "1", "MKL_NUM_THREADS": "1"}
    done = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, timeout=120, env=env)
    assert done.returncode == 0, f"the case did not end by itself (code {done.returncode}): {done.stderr[-2000:]}"
    first, seconds = done.stdout.strip().splitlines()[-2:]
    assert first.startswith("ValueError: "), first
    assert message in first
    assert float(seconds.split()[1]) < SECONDS


def test_time_limits_scale_with_the_scene(cmu):
    """The reach is 10 scene durations: a longer scene may place its characters farther apart."""
    from mocaplab.editing import Sync, edit
    from mocaplab.editing.timewarp import TIME_REACH, time_reach

    walk = cmu("16_15")
    short, long = walk[:118], walk[:400]
    assert time_reach([118, 400], [walk.dt, walk.dt]) == pytest.approx(TIME_REACH * 518 * walk.dt)
    reach_short = time_reach([118, 118], [walk.dt, walk.dt])
    with pytest.raises(ValueError, match="Expected `offset`"):
        edit([short, short], [Sync(1, 0, other=0, other_frame=0, offset=reach_short * 1.01)])
    # the same offset is within the reach of a scene with a longer clip; it is met, and the clock spans it
    res = edit([short, long], [Sync(1, 0, other=0, other_frame=0, offset=reach_short * 1.01, hard=True)])
    assert res.times[1][0] - res.times[0][0] == pytest.approx(reach_short * 1.01)
    assert res.clock[-1] - res.clock[0] >= reach_short


def test_the_largest_allowed_options_still_edit(cmu):
    """At the limits (1000 fps clock, offsets at the reach) an edit is built and plays."""
    from mocaplab.editing import Sync, edit
    from mocaplab.editing.scene import MAX_CLOCK_FPS
    from mocaplab.editing.timewarp import time_reach

    a = cmu("16_15")[:118]
    reach = time_reach([118, 118], [a.dt, a.dt])
    res = edit([a, a], [Sync(1, 0, other=0, other_frame=0, offset=reach, hard=True)], clock_fps=MAX_CLOCK_FPS)
    assert res.motions[1].fps == MAX_CLOCK_FPS
    assert res.motions[1].n_frames == len(res.clock) == pytest.approx((reach + a.duration) * MAX_CLOCK_FPS, abs=2)


def test_a_rejected_drag_changes_nothing(cmu):
    from mocaplab.editing import SceneEditor, Sync

    a = cmu("16_15")[:118]
    ed = SceneEditor([a, a], [Sync(1, 0, other=0, other_frame=0, offset=0.5)])
    before = ed.result
    with pytest.raises(ValueError, match=r"constraint #0 .*Expected `offset` within \+-19.6667 s"):
        ed.drag(0, 1e4)
    assert ed.result is before and ed.constraints[0].offset == 0.5


def test_extract_at_the_highest_rate_is_bounded(cmu):
    """At MAX_FPS the trail smoothing is one sine transform, not 1,667 passes over the trails."""
    from mocaplab.staggered.features import MAX_FPS, analyze

    walk = cmu("16_15")
    fast = walk.sample(np.arange(0.0, 0.5, 1.0 / MAX_FPS), fps=MAX_FPS)
    analysis = analyze(fast, contacts=None)
    assert analysis.probability.shape == (fast.n_frames,)


def test_smoothing_in_one_pass_matches_the_iterations(rng):
    """laplacian_smooth in closed form: explicit passes give the same trails, for any count and clip length."""
    from mocaplab.staggered.features import laplacian_smooth

    def iterate(x, iterations, lam):
        y = np.array(x, dtype=float, copy=True)
        for _ in range(iterations):
            y[1:-1] += lam * (0.5 * (y[:-2] + y[2:]) - y[1:-1])
        return y

    cases = [(471, 24, 0.5), (10, 24, 0.5), (3, 24, 0.5), (300, 37, 0.3), (300, 7, 1.0), (40, 1600, 0.5)]
    for frames, iterations, lam in cases:
        x = np.cumsum(rng.normal(size=(frames, 4, 3)), axis=0)
        got = laplacian_smooth(x, iterations=iterations, lam=lam)
        assert np.abs(got - iterate(x, iterations, lam)).max() < 1e-12 * np.ptp(x)
    still = np.broadcast_to(rng.normal(size=(1, 4, 3)), (50, 4, 3))
    assert np.array_equal(laplacian_smooth(still, iterations=24), still)  # bitwise: a still trail has no length
    with pytest.raises(ValueError, match=r"Expected `iterations` >= 0, got -1"):
        laplacian_smooth(np.zeros((10, 3)), iterations=-1)
