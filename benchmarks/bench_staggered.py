"""Staggered poses (Coleman et al. 2008): extraction, re-evaluation, and what the defaults give.

Targets: extracting CMU 49_03 (1504 frames, 31 joints) in under 250 ms
(issue 13; 2 s in issue 7) with a rotation fit error no worse than the
former default's (Nelder-Mead polish), and a dense re-evaluation after an
edit in under 50 ms so sliders feel live.  Prints medians of repeats (wall
clock and process CPU time: the machine may be shared) and the ratio to
each target.  Then the figures of issue 13: interior poses per second and
the closest two poses on a walk, runs, a dance and jumps (every maximum of
``P`` against distinct maxima), contacts on runs, the head's jitter after a
whole-body succession, and the knees under exaggerated legs; and those of
issue 25: a flick retimed whole, a true-pose edit's local acceleration,
a strong succession's one-frame moves and knee accelerations (ratios to the
input's, :mod:`mocaplab.quality`), the constraint layer's on CMU clips and
the shared files from other tools (with and without it), the longest
stretch left by culling.

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

from mocaplab import data, quality, quat
from mocaplab.contacts import stillness_contacts
from mocaplab.ik import hinge_axes, limb_joints
from mocaplab.motion import Motion, Skeleton
from mocaplab.staggered import (
    NoContactsWarning,
    StaggeredTimingWarning,
    UnreachableTargetWarning,
    analyze,
    edit_pose,
    exaggerate,
    extract,
    fit,
    randomize,
    succession,
)
from mocaplab.staggered.noise import jitter

EXTRACT_TARGET = 0.250
EVAL_TARGET = 0.050
LITERAL = {"min_separation": 0.0, "min_prominence": 0.0}  # every local maximum of P, as before issue 13


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
    for quiet in (StaggeredTimingWarning, NoContactsWarning, UnreachableTargetWarning):
        warnings.simplefilter("ignore", quiet)
    warnings.filterwarnings("ignore", "The motion path follows joint")
    clip = data.cmu("49_03")
    print(f"clip 49_03: {clip.n_frames} frames, {clip.n_joints} joints, {clip.fps:g} fps")
    extract(clip, optimize=False)  # warm caches (imports, FK)
    print(f"\nextraction (target {EXTRACT_TARGET * 1e3:.0f} ms); fit error: mean RMS angle between the samples and")
    print("their rotation spline over the segments that move (degrees)")
    literal = analyze(clip, **LITERAL)
    cases = {
        "default: distinct poses, filter, tangent start + Gauss-Newton": {},
        "  the same without the polish (optimize=False)": {"optimize": False},
        "  the same with Nelder-Mead (the paper's polish)": {"method": "nelder-mead"},
        "former default: every maximum, no filter, Nelder-Mead": {
            "method": "nelder-mead", "filter_sigma": None, "analysis": literal,
        },
        "  former poses and data, Gauss-Newton": {"filter_sigma": None, "analysis": literal},
    }
    sm = None
    for label, options in cases.items():
        repeats = 1 if options.get("method") == "nelder-mead" else 5
        errors: list[np.ndarray] = []
        wall, cpu, out_sm = timed(lambda o=options, e=errors: with_fit_errors(clip, e, **o), repeats)
        report(label, wall, cpu, EXTRACT_TARGET)
        print(f"{'':58s} fit error {np.degrees(errors[-1]).mean():.3f} deg, {out_sm.n_poses} poses")  # type: ignore[union-attr]
        sm = out_sm if sm is None else sm
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
        "succession s=0.01, l=2 on the whole body + evaluate": lambda: succession(sm, 0.01, 2.0).evaluate(),
        "succession s=0.03, l=2 below the left shoulder + evaluate": lambda: succession(
            sm, 0.03, 2.0, joint=roles["left_shoulder"]
        ).evaluate(),
        "random tau=0.03 s on every joint + evaluate": lambda: randomize(sm, 0.03, seed=1).evaluate(),
        "exaggerate arms of one pose (w_r=0.5) + evaluate": lambda: exaggerate(
            sm, 0.5, poses=[10], joints=shoulders
        ).evaluate(),
        "exaggerate arms of every pose (w_r=0.5) + evaluate": lambda: exaggerate(sm, 0.5, joints=arms).evaluate(),
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
    wall, cpu, _ = timed(lambda: succession(sm_b, 0.01, 2.0).evaluate(), 7)  # type: ignore[union-attr]
    report("succession s=0.01, l=2 on the whole body + evaluate", wall, cpu, EVAL_TARGET)
    figures()
    issue_25_figures()


def with_fit_errors(clip: Motion, errors: list[np.ndarray], **options: object) -> object:
    """``extract(clip, **options)``, appending the per-segment rotation fit errors (radians) of moving joints."""
    real = fit.fit_rotation_tangents

    def spy(seg, tn, q, q1, q4, **kw):  # type: ignore[no-untyped-def]
        alpha, beta, info = real(seg, tn, q, q1, q4, **kw)
        e = fit._segment_rms(seg, tn, q, q1, quat.mul(q1, alpha), quat.mul(q4, beta), q4)
        errors.append(e[info["start_error"] > 1e-9])
        return alpha, beta, info

    fit.fit_rotation_tangents = spy
    try:
        return extract(clip, **options)  # type: ignore[arg-type]
    finally:
        fit.fit_rotation_tangents = real


def figures() -> None:
    """The measured figures of issue 13, before (literal rules, no filter) and after (defaults)."""
    print("\ninterior poses per second (closest two poses): every maximum of P -> distinct maxima")
    clips = {
        "walk 16_15": "16_15", "walk 02_01": "02_01", "run 09_06": "09_06", "run 16_35": "16_35",
        "dance 05_02": "05_02", "broad jump 16_05": "16_05", "vertical jump 16_01": "16_01", "hops 49_03": "49_03",
    }
    for label, trial in clips.items():
        m = data.cmu(trial)
        row = []
        for options in ({"contacts": stillness_contacts(m), **LITERAL}, {}):
            cand = analyze(m, **options).candidates  # type: ignore[arg-type]
            row.append(f"{(cand.size - 2) / m.duration:4.1f} ({1000 * np.diff(cand).min() / m.fps:3.0f} ms)")
        print(f"  {label:22s} {row[0]} -> {row[1]}")
    gaps = []
    for trial in data.clips():
        m = data.cmu(trial)
        gaps.append(np.diff(analyze(m).candidates).min() / m.fps)
    print(f"  closest two poses over all {len(gaps)} CMU clips of the mirror: {1000 * min(gaps):.0f} ms")

    print("\ncontacts on runs (Appendix B): intervals over the four foot joints, 0.25 s -> scaled to the gait")
    for trial in ("09_06", "16_35"):
        m = data.cmu(trial)
        fixed, gait = stillness_contacts(m), stillness_contacts(m, min_duration="gait")
        stance = [(b - a) / m.fps for j in gait.joints for a, b in gait.intervals(j)]
        n0 = sum(len(fixed.intervals(j)) for j in fixed.joints)
        print(f"  run {trial}: {n0} -> {len(stance)} contacts, stances {min(stance):.2f}-{max(stance):.2f} s")

    walk = data.cmu("16_15")
    head = walk.skeleton.roles["head"]
    before = jitter(walk, head)
    print(f"\nhead jitter after whole-body succession s=0.03, l=2 on 16_15 (capture {1000 * before:.2f} mm)")
    for label, options in (("no filter", {"filter_sigma": None}), ("filtered (default)", {})):
        after = jitter(succession(extract(walk, **options), 0.03, 2.0).evaluate(), head)  # type: ignore[arg-type]
        print(f"  {label:20s} {1000 * after:.2f} mm, {after / before:.2f} x the capture's")

    print("\nknees under the walk's legs exaggerated by w_r = 0.5 (signed flexion about the input's hinge)")
    sk = walk.skeleton
    legs = [limb_joints(sk, sk.roles[f"{s}_ankle"]) for s in ("left", "right")]
    hinges = hinge_axes(walk.global_rotations(), walk.global_positions(), legs)
    sm = extract(walk, constraints=True)
    edited = exaggerate(sm, 0.5, joints=[sk.roles[f"{s}_{p}"] for s in ("left", "right") for p in ("hip", "knee", "ankle")])
    for label, m in (("capture", walk), ("edit, no layer", edited.evaluate(constraints=False)),
                     ("edit + constraint layer", edited.evaluate())):
        flex = knee_flexion(m, legs, hinges)
        acc = np.abs(np.diff(np.radians(flex), 2, axis=0)).max() * walk.fps**2
        print(f"  {label:24s} smallest flexion {flex.min():5.1f} deg, peak knee acceleration {acc:6.0f} rad/s^2")


def issue_25_figures() -> None:
    """What issue 25 asks of the staggered edits, as ratios to the input's (mocaplab.quality)."""
    print("\nissue 25: a flick retimed whole (16_05, succession 0.1 s below the right knee)")
    jump = data.cmu("16_05")
    j = jump.skeleton.index(jump.skeleton.roles["right_ankle"])
    knee = jump.skeleton.roles["right_knee"]

    def speed(m: Motion) -> np.ndarray:
        q = m.rotations[:, j]
        return np.degrees(quat.angle(quat.mul(quat.inv(q[:-1]), q[1:]))) * m.fps

    w0 = speed(jump)
    f0, n = int(w0.argmax()), int(round(0.1 * jump.fps))
    w = speed(succession(extract(jump), 0.1, 1.0, joint=knee).evaluate(constraints=False))
    print(f"  the foot's peak turn {w0[f0]:.0f} deg/s at frame {f0}; after: {w[f0 - 2 : f0 + 3].max():.0f} deg/s there, "
          f"{w[f0 + n - 3 : f0 + n + 4].max():.0f} deg/s {n} frames later")

    walk = data.cmu("16_15")
    sm = extract(walk)
    arm = walk.skeleton.index(walk.skeleton.roles["right_shoulder"])
    turn = quat.from_axis_angle([0, 0, 1], np.radians(20.0))
    worst = 0.0
    for k in range(1, sm.n_poses - 1):
        _, rot = sm.true_pose(k)
        target = np.array(rot)
        target[arm] = quat.mul(rot[arm], turn)
        out = edit_pose(sm, k, rotations=target, which="true").motion
        window = slice(int(round(sm.times[k - 1] * walk.fps)), int(round(sm.times[k + 1] * walk.fps)) + 1)
        ratio = quality.angular_acceleration(out[window])[arm] / quality.angular_acceleration(walk[window])[arm]
        worst = max(worst, float(ratio))
    print(f"  20-degree true-pose edit of the right arm, every pose of 16_15: local angular acceleration <= {worst:.2f}x")

    print("  strong succession s=0.03, l=2 (whole body): worst joint's largest one-frame move, peak knee acceleration")
    for trial in ("16_15", "05_02", "49_03"):
        m = data.cmu(trial)
        out = succession(extract(m), 0.03, 2.0).motion
        move = quality.displacement(out) / np.maximum(quality.displacement(m), 1e-9)
        knees = [m.skeleton.index(m.skeleton.roles[f"{s}_knee"]) for s in ("left", "right")]
        acc = quality.angular_acceleration(out)[knees].max() / quality.angular_acceleration(m)[knees].max()
        print(f"    {trial}: {move.max():.2f}x ({m.skeleton.names[int(move.argmax())]}), knees {acc:.2f}x")

    constraint_layer_figures()

    hops = data.cmu("49_03")
    a = analyze(hops)
    stretches = {n: np.diff(a.select(max_poses=n)).max() / hops.fps for n in (4, 6, 8)}
    print("  culling 49_03 (12.5 s) by count, longest stretch without a pose: "
          + ", ".join(f"{n} poses {t:.1f} s" for n, t in stretches.items()))


#: The edits of issue 25's constraint-layer cases (tests/test_staggered_quality.py): CMU clips and the shared
#: files from other tools (under realworld/ of the mirror), each with the layer on and off.
LAYER_CASES = (
    ("16_05", "succession", 0.02), ("49_03", "succession", 0.02), ("05_02", "succession", 0.01),
    ("60_10", "exaggerate", 0.3), ("walk01.bvh", "succession", 0.02), ("animation.bvh", "succession", 0.02),
    ("test_optitrack.bvh", "succession", 0.02), ("A_test.bvh", "succession", 0.02),
    ("bvh_test1.bvh", "succession", 0.02), ("AV_8Walk_Meredith_HVHA_Rep1.bvh", "succession", 0.02),
    ("test_freebvh.bvh", "succession", 0.02), ("test_mocapbank.bvh", "succession", 0.02),
)


def constraint_layer_figures() -> None:
    """Each case's worst one-frame move and peak knee acceleration as ratios to the input's, layer on (off)."""
    from mocaplab import load

    print("  the constraint layer: worst joint's largest one-frame move and peak knee acceleration, ratios to the")
    print("  input's (quality's limits 1.5x + 2 mm, 2x + 20 rad/s^2), with the layer (without); held plants, mm")
    root = Path(os.environ["MOCAPLAB_DATA_DIR"])
    for clip, kind, amount in LAYER_CASES:
        m = load(sorted(root.glob(f"realworld/*/{clip}"))[0]) if clip.endswith(".bvh") else data.cmu(clip)
        sm = extract(m, constraints=True)
        edited = succession(sm, amount) if kind == "succession" else exaggerate(sm, amount)
        on, off = edited.evaluate(), edited.evaluate(constraints=False)
        knees = [m.skeleton.index(m.skeleton.roles[f"{s}_knee"]) for s in ("left", "right")]
        d0, a0 = quality.displacement(m), quality.angular_acceleration(m)
        cells = []
        for out in (on, off):
            move = quality.displacement(out) / np.maximum(d0, 1e-9)
            acc = (quality.angular_acceleration(out)[knees] / np.maximum(a0[knees], 1e-9)).max()
            cells.append((float(move.max()), m.skeleton.names[int(move.argmax())], float(acc)))
        layer = edited.constraints
        w, targets = layer.weights_and_targets(edited, on.times, motion=off)
        feet = [m.skeleton.index(n) for n in layer.joints]
        held = np.linalg.norm(on.global_positions()[:, feet] - targets, axis=-1)[w == 1.0]
        (mv, jn, acc), (mv0, _, acc0) = cells
        print(f"    {clip[:22]:22s} {kind} {amount:g}: move {mv:.2f}x ({jn}) ({mv0:.2f}x), knees {acc:.2f}x "
              f"({acc0:.2f}x), plants {1000 * held.max():.2f} mm")


def knee_flexion(m: Motion, legs: list[tuple[int, int, int]], hinges: np.ndarray) -> np.ndarray:
    """Signed knee flexion in degrees, shape (F, 2): negative bends backwards."""
    g, p = m.global_rotations(), m.global_positions()
    out = []
    for (u, k, a), h in zip(legs, hinges, strict=True):
        thigh, shank = p[:, u] - p[:, k], p[:, a] - p[:, k]
        axis = quat.rotate(g[:, k], h)
        out.append(np.degrees(np.arctan2(np.einsum("ij,ij->i", np.cross(thigh, shank), axis), -np.sum(thigh * shank, -1))))
    return np.stack(out, axis=1)


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
