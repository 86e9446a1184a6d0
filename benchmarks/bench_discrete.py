"""Benchmark: discrete motion editing (Kim et al. 2009, section 5, Table 1, Figure 1).

Runs with single-threaded BLAS (set below, before numpy is imported): the
dense blocks of the evaluation are small, and on a shared machine threads
only add contention.  Figures are CPU time (``time.process_time``) with
wall-clock beside them.

0. The relay of lesson 05 (high-five pairs in a chain, every tie hard),
   grown from 8 to 78 characters (Figure 1 has 78): the median CPU time of a
   whole discrete drag update (Algorithm 1: enumerate, prune, evaluate every
   candidate of every character on subsampled paths, verify, solve), peak
   traced memory of one update, a least-squares line through the
   characters-versus-time curve and the log-log slope (1 = linear).
   Targets: 10 characters < 30 ms, 30 < 100 ms and 500 MB, 78 < 300 ms, and
   78 no slower than before the sparse evaluation (issue 23 item 3).
   Then the same relay with longer clips (the clips resampled at 80 fps:
   about 270 frames per character, 314 and 229): 10 to 78 characters, and 78
   characters at 30, 60, 80 and 120 fps, with the log-log slopes in
   characters and in frames per character.  Target (issue 23 item 3): 78
   characters of about 270 frames < 300 ms per drag and < 500 MB peak,
   single-threaded, and both slopes at most about 1.
1. Per-update time to enumerate, prune and evaluate every candidate
   transformation (Algorithm 1, lines 6-8, on subsampled paths) for a scene
   sized like the paper's "high five" example: 4 characters, about 600
   frames in all at 30 fps, soft and hard path constraints, the characters
   linked by relative-position and synchronisation constraints.  One end pin
   is dragged in 40 steps (Table 1 averages 40 iterations); each step is one
   constraint update.  Printed beside the paper's 45.8 ms (target: < 20 ms),
   with the full-resolution Laplacian editing time of the same updates
   (paper: 58.9 ms).
   All candidates of all characters are evaluated in one batch
   (``mocaplab.editing.discrete``); the per-update figure is CPU time
   (``time.process_time``: the machine is shared), wall-clock beside it.
2. Building the ``SceneEditor`` of that scene (factorisations, hard-row
   rank checks), CPU and wall-clock.
3. Motion-graph construction for 10,000 frames (CMU walks at 120 fps, tiled
   with time-scaled copies), chunked: peak memory stays ``O(chunk * N)``.

Run: ``python benchmarks/bench_discrete.py [--steps 40] [--graph-frames 10000] [--relay-fps 30,60,80,120]``.
Needs the CMU mirror (``MOCAPLAB_DATA_DIR``).
"""

from __future__ import annotations

import os

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
os.environ.setdefault("OMP_NUM_THREADS", "1")

import argparse  # noqa: E402
import dataclasses  # noqa: E402
import gc  # noqa: E402
import statistics  # noqa: E402
import time  # noqa: E402
import tracemalloc  # noqa: E402

import numpy as np  # noqa: E402

from mocaplab import data  # noqa: E402
from mocaplab.editing import (  # noqa: E402
    AbsoluteTime,
    DiscreteEditor,
    DiscreteOptions,
    MotionPath,
    PinDirection,
    PinPosition,
    Relative,
    SceneEditor,
    Sync,
)
from mocaplab.editing.graph import build_graph  # noqa: E402

PAPER_DISCRETE_MS = 45.8
PAPER_LAPLACIAN_MS = 58.9
LONG_FPS = 80.0  # the relay's clips resampled: 314 and 229 frames, about 270 per character
LONG_TARGET_MS = 300.0  # issue 23 item 3: 78 characters of about 270 frames, per drag
LONG_TARGET_MB = 500.0
# the 78-character CMU relay (30 fps) before the sparse evaluation (f21a49e's parent), median CPU ms per drag
# measured by this benchmark, single-threaded, interleaved with the sparse one on 2 shared cores (load 6):
# the target is "no slower than before"
BEFORE_CMU_RELAY_78_MS = 243.0


def high_five_scene() -> tuple[list, list]:
    """Four characters (~600 frames at 30 fps) with constraints like the paper's high-five example."""
    clips = [
        data.cmu("16_11").resample(30),
        data.cmu("16_17").resample(30),
        data.cmu("05_02").resample(30)[:210],
        data.cmu("16_15").resample(30),
    ]
    # place them side by side
    chars = [m.transformed(translation=(2.0 * k, 0.0, 0.0)) for k, m in enumerate(clips)]
    cons: list = []
    for k, m in enumerate(chars):
        P = m.root_positions[:, [0, 2]]
        F = m.n_frames
        cons.append(PinPosition(k, 0, P[0], hard=True))
        cons.append(PinPosition(k, F - 1, P[-1], hard=True))
        for f in (F // 3, 2 * F // 3):
            cons.append(PinDirection(k, f, P[f + 1] - P[f - 1]))
    # high fives: 0 meets 1, 2 meets 3, all synchronised (targets as in the input:
    # an edit in progress starts from a consistent scene)
    paths = [MotionPath.from_motion(m) for m in chars]
    mid = [m.n_frames // 2 for m in chars]
    for a, b in ((0, 1), (2, 3)):
        offset = paths[b].local_offset(mid[b], paths[a].positions[mid[a]])
        cons.append(Relative(a, mid[a], b, mid[b], offset))
        cons.append(Sync(a, mid[a], b, mid[b], offset=(mid[a] - mid[b]) / 30.0, hard=True))
    cons.append(Sync(1, mid[1], 2, mid[2], offset=(mid[1] - mid[2]) / 30.0))
    return chars, cons


def relay_scene(groups: int, fps: float = 30.0) -> tuple[list, list]:
    """Lesson 05's relay: ``groups`` high-five pairs, each group starting 0.8 m after the last one ends.

    A (16_15) walks; B (02_01, turned round) meets A 2 s in (frame 60 at 30 fps), 0.6 m to its left, facing it,
    at the same time (hard Relative + Sync); group g + 1's A starts one frame after group g's A ends,
    0.8 m ahead, walking the same way (hard Relative + Sync); soft pins on every group's start and on
    the last group's end (the handle dragged).  ``fps`` resamples both clips (30: 118 and 86 frames,
    80: 314 and 229).
    """
    a = data.cmu("16_15").resample(fps)
    b = data.cmu("02_01").resample(fps)
    pa, pb = a.root_positions[:, [0, 2]], b.root_positions[:, [0, 2]]
    b = b.transformed(yaw=np.pi - np.arctan2(*(pb[-1] - pb[0])))
    FA, FB = a.n_frames, b.n_frames
    fa, fb = round(2.0 * fps), FB // 2
    pb = b.root_positions[:, [0, 2]]
    b = b.transformed(translation=(pa[fa, 0] + 0.6 - pb[fb, 0], 0.0, pa[fa, 1] - pb[fb, 1]))
    step = pa[-1] - pa[0] + np.array([0.0, 0.8])
    chars: list = []
    cons: list = [AbsoluteTime(0, 0, 0.0, hard=True)]
    for g in range(groups):
        shift = (g * step[0], 0.0, g * step[1])
        chars += [a.transformed(translation=shift), b.transformed(translation=shift)]
        A, B = 2 * g, 2 * g + 1
        cons += [Relative(B, fb, A, fa, (0.0, 0.6), direction=np.pi, hard=True), Sync(B, fb, A, fa, hard=True)]
        if g:
            cons += [
                Relative(A, 0, A - 2, FA - 1, (0.8, 0.0), direction=0.0, hard=True),
                Sync(A, 0, A - 2, FA - 1, offset=a.dt, hard=True),
            ]
    starts = [c.root_positions[0, [0, 2]] for c in chars[::2]] + [chars[-2].root_positions[-1, [0, 2]]]
    cons += [PinPosition(2 * g, 0, starts[g]) for g in range(groups)]
    cons += [PinPosition(2 * groups - 2, FA - 1, starts[-1])]
    return chars, cons


@dataclasses.dataclass(frozen=True)
class RelayRun:
    characters: int
    frames: int
    fps: float
    candidates: float
    cpu_ms: float
    wall_ms: float
    max_wall_ms: float
    peak_mb: float
    applied: int


def run_relay(n: int, steps: int, fps: float = 30.0) -> RelayRun:
    """Median CPU time of ``steps`` discrete drags of the last pin of an ``n``-character relay, and one drag's peak."""
    chars, cons = relay_scene(n // 2, fps)
    ed = DiscreteEditor(chars, cons, discrete=DiscreteOptions(max_initial=0))
    i = len(cons) - 1
    p0 = np.asarray(cons[i].position)
    d = p0 - np.asarray(cons[i - 1].position)
    cpu, wall = [], []
    n0 = len(ed.timings)
    ed.drag(i, p0 + 0.01 * d)  # warm caches
    for s in range(1, steps + 1):
        gc.collect()
        t0, c0 = time.perf_counter(), time.process_time()
        ed.drag(i, p0 + d * 0.4 * s / steps)
        cpu.append(time.process_time() - c0)
        wall.append(time.perf_counter() - t0)
    cands = statistics.median([t.candidates for t in ed.timings[n0:]])
    gc.collect()
    tracemalloc.start()
    ed.drag(i, p0 + d * 0.45)
    peak = tracemalloc.get_traced_memory()[1] / 1e6
    tracemalloc.stop()
    return RelayRun(
        n, sum(m.n_frames for m in chars), fps, cands, 1e3 * statistics.median(cpu),
        1e3 * statistics.median(wall), 1e3 * max(wall), peak, len(ed.applied),
    )  # fmt: skip


def _row(r: RelayRun, verdict: str) -> str:
    return (
        f"{r.characters:10d} {r.fps:5.0f} {r.frames / r.characters:7.0f} {r.frames:7d} {r.candidates:6.0f} "
        f"{r.cpu_ms:8.1f} {r.wall_ms:8.1f} {r.max_wall_ms:7.0f} {r.peak_mb:8.1f} {r.applied:8d} {verdict}"
    )


_HEADER = (
    f"{'characters':>10s} {'fps':>5s} {'fr/char':>7s} {'frames':>7s} {'cands':>6s} {'CPU ms':>8s} {'wall ms':>8s} "
    f"{'max ms':>7s} {'peak MB':>8s} {'applied':>8s}"
)


def loglog_slope(x: list[float], y: list[float]) -> float:
    """Slope of log y against log x (1: linear, 2: quadratic)."""
    return float(np.polyfit(np.log(np.asarray(x, float)), np.log(np.asarray(y, float)), 1)[0])


def bench_relay(sizes: list[int], steps: int) -> list[tuple[int, float]]:
    """Discrete drag updates on relays of ``sizes`` characters (see the module docstring)."""
    print("Relay of lesson 05 (Figure 1 has 78 characters): one discrete drag update (Algorithm 1) of the last pin")
    print(_HEADER)
    targets = {10: 30.0, 30: 100.0, 78: 300.0}
    curve = []
    for n in sizes:
        r = run_relay(n, steps)
        target = targets.get(n)
        verdict = ""
        if target is not None:
            verdict = f"{r.cpu_ms / target:.2f}x of {target:.0f} ms: {'ok' if r.cpu_ms < target else 'MISSED'}"
        if n == 78:
            verdict += (
                f"; {r.cpu_ms / BEFORE_CMU_RELAY_78_MS:.2f}x the {BEFORE_CMU_RELAY_78_MS:.0f} ms before the sparse "
                f"evaluation: {'ok' if r.cpu_ms <= BEFORE_CMU_RELAY_78_MS else 'SLOWER'}"
            )
        print(_row(r, verdict), flush=True)
        curve.append((n, r.cpu_ms))
    k = np.array([c for c, _ in curve], dtype=float)
    t = np.array([m for _, m in curve])
    slope, icpt = np.polyfit(k, t, 1)
    fit = slope * k + icpt
    r2 = 1 - np.sum((t - fit) ** 2) / np.sum((t - t.mean()) ** 2)
    quad = np.polyfit(k, t, 2)
    print(
        f"least-squares line: {slope:.2f} ms per character + {icpt:.1f} ms (R^2 = {r2:.3f}); "
        f"a quadratic fit adds {quad[0] * 1e3:.2f} ms per 1000 characters^2; "
        f"log-log slope {loglog_slope(list(k), list(t)):.2f} (1 = linear)"
    )
    print(f"machine load average during the run: {os.getloadavg()[0]:.1f} on {os.cpu_count()} cores")
    print()
    return curve


def bench_long_relay(sizes: list[int], rates: list[float], steps: int) -> None:
    """The relay with longer clips: slopes in characters and in clip length (issue 23 item 3)."""
    print(
        f"Relay with longer clips (resampled at {LONG_FPS:g} fps: about 270 frames per character): "
        f"target {LONG_TARGET_MS:.0f} ms per drag and {LONG_TARGET_MB:.0f} MB peak at 78 characters, single-threaded"
    )
    print(_HEADER)
    runs: dict[tuple[int, float], RelayRun] = {}

    def run(n: int, fps: float) -> RelayRun:
        if (n, fps) not in runs:
            runs[n, fps] = run_relay(n, steps, fps)
            r = runs[n, fps]
            verdict = ""
            if n == 78 and fps == LONG_FPS:
                verdict = (
                    f"{r.cpu_ms / LONG_TARGET_MS:.2f}x of {LONG_TARGET_MS:.0f} ms: "
                    f"{'ok' if r.cpu_ms < LONG_TARGET_MS else 'MISSED'}; {r.peak_mb / LONG_TARGET_MB:.2f}x of "
                    f"{LONG_TARGET_MB:.0f} MB: {'ok' if r.peak_mb < LONG_TARGET_MB else 'MISSED'}"
                )
            print(_row(r, verdict), flush=True)
        return runs[n, fps]

    by_n = [run(n, LONG_FPS) for n in sizes]
    print(
        f"at {LONG_FPS:g} fps, log-log slope in characters: time {loglog_slope([r.characters for r in by_n], [r.cpu_ms for r in by_n]):.2f}, "
        f"peak memory {loglog_slope([r.characters for r in by_n], [r.peak_mb for r in by_n]):.2f} (1 = linear)"
    )
    by_f = [run(78, fps) for fps in rates]
    per = [r.frames / r.characters for r in by_f]
    print(
        f"78 characters, {per[0]:.0f} to {per[-1]:.0f} frames per character: log-log slope in frames "
        f"per character: time {loglog_slope(per, [r.cpu_ms for r in by_f]):.2f}, time per candidate "
        f"{loglog_slope(per, [r.cpu_ms / r.candidates for r in by_f]):.2f}, peak memory "
        f"{loglog_slope(per, [r.peak_mb for r in by_f]):.2f} (1 = linear; the motion graphs' transitions, "
        f"so the candidates, depend on the frame rate: {', '.join(f'{r.candidates:.0f}' for r in by_f)})"
    )
    print(f"machine load average during the run: {os.getloadavg()[0]:.1f} on {os.cpu_count()} cores")
    print()


def bench_updates(steps: int) -> None:
    chars, cons = high_five_scene()
    n = sum(m.n_frames for m in chars)
    i_end = 1  # end pin of character 0
    P0 = np.array(cons[i_end].position)
    d = P0 - np.array(cons[0].position)
    plain = SceneEditor(chars, cons)
    ed = DiscreteEditor(chars, cons, discrete=DiscreteOptions(max_initial=0))
    lap, disc, disc_cpu, enum, ncand, verify, cpu = [], [], [], [], [], [], []
    for s in range(1, steps + 1):
        target = P0 + d * (0.6 * s / steps)
        gc.collect()
        t0 = time.perf_counter()
        plain.drag(i_end, target)
        lap.append(time.perf_counter() - t0)
        before = len(ed.timings)
        c0 = time.process_time()
        ed.drag(i_end, target)
        cpu.append(time.process_time() - c0)
        tm = ed.timings[before]
        disc.append(tm.enumerate + tm.evaluate)
        disc_cpu.append(tm.cpu)
        enum.append(tm.enumerate)
        ncand.append(tm.candidates)
        if tm.verify:
            verify.append(tm.verify)
    med = statistics.median(disc) * 1e3
    med_cpu = statistics.median(disc_cpu) * 1e3
    p90_cpu = float(np.percentile(disc_cpu, 90)) * 1e3
    print(f"scene: {len(chars)} characters, {n} frames at 30 fps, {len(cons)} path constraints")
    print(
        f"candidates per update after pruning: median {statistics.median(ncand):.0f} "
        f"(first {ncand[0]}, last {ncand[-1]}); paper: 16 at the start, 31 at the end"
    )
    print(f"transformations applied while dragging: {len(ed.applied)}")
    for t in ed.applied:
        print(f"  update {t.update}: {t}")
    print(
        f"enumerate + prune + evaluate all candidates, per update: CPU time median {med_cpu:.1f} ms "
        f"(90th percentile {p90_cpu:.1f} ms); wall-clock median {med:.1f} ms "
        f"(of which enumerate + prune {statistics.median(enum) * 1e3:.1f} ms)"
    )
    print(
        f"  paper (2009 hardware): {PAPER_DISCRETE_MS} ms -> ratio paper / ours {PAPER_DISCRETE_MS / med_cpu:.2f}x (CPU), "
        f"{PAPER_DISCRETE_MS / med:.2f}x (wall); target < 20 ms: {'met' if med_cpu < 20 else 'NOT met'} (CPU), "
        f"{'met' if med < 20 else 'NOT met'} (wall)"
    )
    if verify:
        print(
            f"second scoring at 1/5 + full solve of the chosen candidate (updates where one was predicted to help): "
            f"median {statistics.median(verify) * 1e3:.1f} ms over {len(verify)} updates"
        )
    print(f"whole discrete drag update, everything included (CPU): median {statistics.median(cpu) * 1e3:.1f} ms")
    lm = statistics.median(lap) * 1e3
    print(
        f"full-resolution Laplacian editing per update (drag, no discrete): median {lm:.1f} ms; paper {PAPER_LAPLACIAN_MS} ms"
    )
    print(f"machine load average during the run: {os.getloadavg()[0]:.1f} on {os.cpu_count()} cores")


def bench_build(repeats: int) -> None:
    chars, cons = high_five_scene()
    SceneEditor(chars, cons)  # warm caches (imports, clip features)
    cpu, wall = [], []
    for _ in range(repeats):
        gc.collect()
        t0 = time.perf_counter()
        c0 = time.process_time()
        SceneEditor(chars, cons)
        cpu.append(time.process_time() - c0)
        wall.append(time.perf_counter() - t0)
    print(
        f"SceneEditor construction for that scene (factorisations + hard-row rank checks): "
        f"CPU median {statistics.median(cpu) * 1e3:.1f} ms, wall-clock {statistics.median(wall) * 1e3:.1f} ms "
        f"({repeats} repeats)"
    )


def bench_graph(n_frames: int) -> None:
    names = ["16_15", "16_11", "16_17", "16_34", "16_35", "127_04", "127_17"]
    base = [data.cmu(c) for c in names]
    fps = base[0].fps
    clips = []
    total = 0
    scale = 1.0
    while total < n_frames:
        for m in base:
            # time-scaled copy (sampled at fps / scale, relabelled): a faster or slower variant
            c = m if scale == 1.0 else m.resample(fps / scale).replace(fps=fps)
            c = c[: max(3, min(c.n_frames, n_frames - total))]
            clips.append(c)
            total += c.n_frames
            if total >= n_frames:
                break
        scale *= 1.09
    gc.collect()
    t0 = time.perf_counter()
    c0 = time.process_time()
    g = build_graph(clips, chunk=1024)
    dt = time.perf_counter() - t0
    dc = time.process_time() - c0
    print(
        f"motion graph: {g.n_frames} frames in {len(clips)} clips at {fps:g} fps -> {len(g.pairs)} similar pairs; "
        f"built in {dt:.2f} s wall, {dc:.2f} s CPU (chunks of 1024 rows: ~{1024 * g.n_frames * 8 / 1e6:.0f} MB per block, "
        f"a dense matrix would be {g.n_frames**2 * 8 / 1e9:.1f} GB)"
    )


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--steps", type=int, default=40)
    ap.add_argument("--relay-steps", type=int, default=12)
    ap.add_argument("--relay", type=str, default="8,10,20,30,40,60,78", help="relay sizes (characters)")
    ap.add_argument("--long-relay", type=str, default="10,20,40,78", help="long-clip relay sizes (characters)")
    ap.add_argument("--relay-fps", type=str, default="30,60,80,120", help="frame rates of the 78-character relay")
    ap.add_argument("--graph-frames", type=int, default=10_000)
    args = ap.parse_args()
    bench_relay([int(x) for x in args.relay.split(",")], args.relay_steps)
    bench_long_relay(
        [int(x) for x in args.long_relay.split(",")], [float(x) for x in args.relay_fps.split(",")], args.relay_steps
    )
    bench_updates(args.steps)
    bench_build(10)
    bench_graph(args.graph_frames)


if __name__ == "__main__":
    main()
