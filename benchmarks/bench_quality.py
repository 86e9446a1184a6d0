"""Benchmark: the whole pipeline on every clip of the data mirror, judged by mocaplab.quality.

Every clip under ``MOCAPLAB_DATA_DIR`` (the CMU BVH and ASF/AMC files, the
salsa pair, ``realworld/`` captures from other systems and exporters,
``fbx/``) and the CMU walk written in each generated convention of the tests
(``tests/conventions.py``: Mixamo names, a game studio's static root,
centimetres, Z up, 30 fps, ...) is loaded with no option, trimmed to 20 s, and
taken through ``tests/pipeline.py``: a bend and a squeeze of the path (each
then refined), refinement of the clip, touch-up of the clip and of the refined
bend, staggered poses with an exaggeration and a succession, and a BVH export
read back.  Each step's output is compared with its input by
:func:`mocaplab.quality.compare`.

One table: per clip and step, the ratio of each measure to the input's own
(``skate`` mean foot skate on the input's contacts, ``pen`` penetration below
the input's floor, ``pop`` the largest one-frame move of the worst joint,
``acc`` its peak angular acceleration, ``drift`` bone length change in mm,
``flips`` hinge frames bending the wrong way, input -> output, ``zmp`` mean ZMP
distance outside the support polygon), a ``!`` after a value beyond the
default :data:`mocaplab.quality.LIMITS`, and the step's time.  A summary counts
the regressions per step and measure.  The raw edits (``bend``, ``squeeze``)
are expected to skate: refinement is what plants the feet again.

Run: ``python benchmarks/bench_quality.py [--quick] [--clips PATTERN]``
(``--quick``: one clip per source).
"""

from __future__ import annotations

import argparse
import collections
import fnmatch
import os
import sys
import tempfile
import time
import warnings
from pathlib import Path

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE.parent / "tests"))

import pipeline  # noqa: E402  (tests/pipeline.py)

import mocaplab as ml  # noqa: E402

COLUMNS = (
    ("skate", "skate"),
    ("pen", "penetration"),
    ("pop", "displacement"),
    ("acc", "angular_acceleration"),
    ("drift", "bone_drift"),
    ("flips", "hinge_flips"),
    ("zmp", "zmp"),
    ("root", "static_root"),
)


def corpus(root: Path, *, quick: bool) -> list[tuple[str, Path, dict]]:
    """``(label, path, load options)`` for every clip of the mirror."""
    out: list[tuple[str, Path, dict]] = []
    groups = [
        ("cmu", sorted((root / "bvh").glob("*.bvh"))),
        ("amc", sorted((root / "asfamc").glob("*/*.amc"))),
        ("salsa", sorted((root / "pair_salsa_daz").glob("*.bvh"))),
        ("realworld", sorted((root / "realworld").glob("*/*.bvh"))),
        ("fbx", sorted((root / "fbx").glob("*.fbx"))),
    ]
    for source, paths in groups:
        for path in paths[:1] if quick and source != "realworld" else paths:
            out.append((f"{source}/{path.stem}", path, {}))
    return out


def generated(folder: Path, *, quick: bool) -> list[tuple[str, Path, dict]]:
    """The CMU walk 16_15 written in each convention of ``tests/conventions.py``."""
    from conventions import CONVERTERS, LOAD_OPTIONS, convert

    walk = ml.cmu("16_15")
    names = sorted(CONVERTERS)[:2] if quick else sorted(CONVERTERS)
    out = []
    for convention in names:
        path, _ = convert(walk, convention, folder)
        out.append((f"conv/{convention}", path, dict(LOAD_OPTIONS.get(convention, {}))))
    return out


def cell(row) -> str:
    if row is None:
        return "-"
    if row.name == "hinge_flips":
        text = f"{row.before:.0f}>{row.after:.0f}" if row.before == row.before else "nan"
    elif row.name in ("bone_drift", "static_root"):
        text = f"{row.after:.2g}" if row.after == row.after else "-"
    else:
        r = row.ratio
        text = "-" if r != r else ("inf" if r == float("inf") else f"{r:.2f}")
    return text + ("!" if row.regressed else "")


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="one clip per source")
    parser.add_argument("--clips", default="*", help="glob on the clip labels, e.g. 'realworld/*'")
    args = parser.parse_args()
    root = Path(os.environ.setdefault("MOCAPLAB_DATA_DIR", str(HERE.parent.parent / "shared" / "mocap")))
    if not root.is_dir():
        print(f"no data mirror at {root}: set MOCAPLAB_DATA_DIR")
        return 1
    start = time.perf_counter()
    regressions: collections.Counter[tuple[str, str]] = collections.Counter()
    failures: list[str] = []
    step_times: dict[str, list[float]] = collections.defaultdict(list)
    header = f"{'clip':34s} {'frames':>6s} {'step':22s} {'sec':>6s} " + " ".join(f"{c:>9s}" for c, _ in COLUMNS)
    print(header)
    print("-" * len(header))
    with tempfile.TemporaryDirectory(prefix="mocaplab_bench_quality_") as folder:
        clips = corpus(root, quick=args.quick) + generated(Path(folder), quick=args.quick)
        for label, path, options in clips:
            if not fnmatch.fnmatch(label, args.clips):
                continue
            try:
                with warnings.catch_warnings():
                    warnings.simplefilter("ignore")
                    clip = pipeline.trimmed(ml.load(path, **options))
            except Exception as exc:  # noqa: BLE001 - the corpus reports every failure and goes on
                failures.append(f"{label}: load: {type(exc).__name__}: {exc}")
                print(f"{label:34s} {'':>6s} {'load':22s} FAILED {type(exc).__name__}: {str(exc)[:80]}")
                continue
            for result in pipeline.run(clip):
                step_times[result.step].append(result.seconds)
                if result.report is None:
                    failures.append(f"{label}: {result.step}: {result.error}")
                    print(f"{label:34s} {clip.n_frames:6d} {result.step:22s} FAILED {result.error[:90]}")
                    continue
                rows = {r.name: r for r in result.report}
                for r in result.report.regressions:
                    regressions[(result.step, r.name)] += 1
                cells = " ".join(f"{cell(rows.get(name)):>9s}" for _, name in COLUMNS)
                print(f"{label:34s} {clip.n_frames:6d} {result.step:22s} {result.seconds:6.2f} {cells}", flush=True)
    total = time.perf_counter() - start
    print()
    print("Regressions (clips beyond the default limits), per step and measure:")
    steps = [s for s, _ in pipeline.STEPS]
    print(f"{'step':22s} " + " ".join(f"{c:>6s}" for c, _ in COLUMNS) + f" {'median s':>9s}")
    for step in steps:
        counts = " ".join(f"{regressions[(step, name)]:6d}" for _, name in COLUMNS)
        times = sorted(step_times.get(step, [0.0]))
        print(f"{step:22s} {counts} {times[len(times) // 2]:9.2f}")
    print()
    print(f"{len(failures)} failure(s)")
    for f in failures:
        print("  ", f[:300])
    print(f"whole corpus: {total:.0f} s (target under 600 s on 2 cores: ratio {total / 600:.2f})")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
