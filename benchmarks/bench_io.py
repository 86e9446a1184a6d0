"""Benchmark: read a CMU clip and run forward kinematics, against pybvh.

Work timed, on CMU 49_03 (1504 frames, 31 joints, 96 channels):

* mocaplab: ``load_bvh(path, scale=...)`` then ``Motion.global_positions()``;
* pybvh (a benchmark-only dependency): ``pybvh.read_bvh_file(path)`` then
  ``.joint_positions()`` (its warnings silenced);
* for information: ``load_asf_amc`` of the same clip from the Acclaim files,
  with forward kinematics; and ``data.cmu`` of the clip from the mirror, which
  reads the file once, checks its sha256 and parses those bytes on every call
  (the price of the integrity check over a bare ``load_bvh``).

* FBX and glTF beside BVH, on CMU 05_02 (1123 frames; the largest of the
  Blender FBX exports in ``fbx/``): ``load(bvh) + FK``, ``load(fbx) + FK``
  (ufbx in a worker process, see :mod:`mocaplab.io.fbx`), ``load(glb) + FK``
  of the clip written by ``save_gltf``, and ``save_gltf`` itself; the FBX and
  glTF results are checked against the BVH first.

The two BVH readers are run alternately in the same process; the medians of
the repeats and their ratio are printed (the target is mocaplab at least 2x
faster).  Both results are checked to be the same joint positions first.

Run: ``python benchmarks/bench_io.py [--repeats 30]``.  Needs the CMU mirror
(``MOCAPLAB_DATA_DIR``, default ``../shared/mocap`` beside the checkout).
"""

from __future__ import annotations

import argparse
import gc
import os
import statistics
import sys
import time
import warnings
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
TRIAL = "49_03"


def _mirror() -> Path:
    value = os.environ.get("MOCAPLAB_DATA_DIR") or str(ROOT.parent / "shared" / "mocap")
    path = Path(value)
    if not (path / "bvh" / f"{TRIAL}.bvh").is_file():
        sys.exit(f"CMU mirror not found at {path}: set MOCAPLAB_DATA_DIR")
    return path


def _time(fn, repeats: int) -> list[float]:
    out = []
    for _ in range(repeats):
        gc.collect()
        t0 = time.perf_counter()
        fn()
        out.append(time.perf_counter() - t0)
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=30)
    args = parser.parse_args()

    import pybvh

    from mocaplab import data
    from mocaplab.io import load_asf_amc, load_bvh

    mirror = _mirror()
    entry = data.describe(TRIAL)
    bvh_path = mirror / str(entry["bvh"])
    scale = float(entry["scale"])  # type: ignore[arg-type]

    def ours() -> np.ndarray:
        return load_bvh(bvh_path, scale=scale).global_positions()

    def theirs() -> np.ndarray:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            return pybvh.read_bvh_file(bvh_path).joint_positions()

    def acclaim() -> np.ndarray:
        return load_asf_amc(mirror / str(entry["asf"]), mirror / str(entry["amc"])).global_positions()

    def verified() -> None:
        data.cmu(TRIAL)

    def bare() -> None:
        load_bvh(bvh_path, scale=scale)

    # same answer first (pybvh in file units, ours in metres)
    a, b = ours(), np.asarray(theirs())
    if b.shape == a.shape:
        err = float(np.max(np.abs(a - b * scale)))
        print(f"check: max |mocaplab - pybvh| = {err * 1000:.2g} mm over {a.shape[0]} frames x {a.shape[1]} joints")
    else:
        print(f"check: pybvh returned shape {b.shape}, mocaplab {a.shape} (not compared)")

    ours_t: list[float] = []
    theirs_t: list[float] = []
    for _ in range(args.repeats):  # alternate, so load on the machine hits both alike
        ours_t += _time(ours, 1)
        theirs_t += _time(theirs, 1)
    acclaim_t = _time(acclaim, max(5, args.repeats // 3))
    os.environ.setdefault("MOCAPLAB_DATA_DIR", str(mirror))
    verified_t: list[float] = []
    bare_t: list[float] = []
    for _ in range(max(5, args.repeats // 3)):
        verified_t += _time(verified, 1)
        bare_t += _time(bare, 1)

    m_ours = statistics.median(ours_t) * 1e3
    m_theirs = statistics.median(theirs_t) * 1e3
    print(f"{TRIAL}: {a.shape[0]} frames, {a.shape[1]} joints; median of {args.repeats} runs")
    print(f"  mocaplab load_bvh + FK : {m_ours:7.2f} ms  (min {min(ours_t) * 1e3:.2f})")
    print(f"  pybvh read + positions : {m_theirs:7.2f} ms  (min {min(theirs_t) * 1e3:.2f})")
    print(f"  ratio pybvh / mocaplab : {m_theirs / m_ours:7.2f}x  (target >= 2x; ratio of minima {min(theirs_t) / min(ours_t):.2f}x)")
    print(f"  mocaplab load_asf_amc + FK (same clip, Acclaim files): {statistics.median(acclaim_t) * 1e3:.2f} ms")
    m_verified, m_bare = statistics.median(verified_t) * 1e3, statistics.median(bare_t) * 1e3
    print(f"  data.cmu (sha256 + load, every call) : {m_verified:7.2f} ms  vs load_bvh {m_bare:.2f} ms ({m_verified / m_bare:.2f}x)")
    _formats(mirror, max(5, args.repeats // 3))


def _formats(mirror: Path, repeats: int) -> None:
    """FBX and glTF load times beside BVH's, on the same clip."""
    import tempfile

    from mocaplab.io import load, save_gltf

    clip = "05_02"
    bvh_path, fbx_path = mirror / "bvh" / f"{clip}.bvh", mirror / "fbx" / f"{clip}.fbx"
    if not fbx_path.is_file():
        print(f"  (no {fbx_path}: FBX and glTF not timed)")
        return
    scale = 0.0254 / 0.45
    reference = load(bvh_path, scale=scale)
    with tempfile.TemporaryDirectory() as folder:
        glb_path = Path(folder) / f"{clip}.glb"
        save_gltf(reference, glb_path)
        runs = {
            "BVH  load + FK": lambda: load(bvh_path, scale=scale).global_positions(),
            "FBX  load + FK": lambda: load(fbx_path).global_positions(),
            "glTF load + FK": lambda: load(glb_path).global_positions(),
            "glTF save_gltf": lambda: save_gltf(reference, glb_path),
        }
        order = [reference.skeleton.index(n) for n in load(fbx_path).skeleton.names]
        err_fbx = np.abs(runs["FBX  load + FK"]() - reference.global_positions()[:, order]).max()
        err_glb = np.abs(runs["glTF load + FK"]() - reference.global_positions()).max()
        print(f"{clip}: {reference.n_frames} frames; FBX vs BVH {err_fbx * 1000:.4f} mm, glTF vs BVH {err_glb * 1000:.4f} mm")
        times: dict[str, list[float]] = {k: [] for k in runs}
        for _ in range(repeats):  # alternate, so load on the machine hits all alike
            for label, fn in runs.items():
                times[label] += _time(fn, 1)
        base = statistics.median(times["BVH  load + FK"])
        for label, t in times.items():
            m = statistics.median(t)
            print(f"  {label} : {m * 1e3:8.2f} ms  (min {min(t) * 1e3:.2f}; {m / base:5.1f}x BVH)")


if __name__ == "__main__":
    main()
