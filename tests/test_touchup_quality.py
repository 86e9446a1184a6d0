"""The physical touch-up judged by :mod:`mocaplab.quality`: it must not add artefacts to the motion it balances.

``compare(input, touch_up(input).motion)`` on the shared real-world files and on captured CMU walks, with
default options.  Each measure must stay within its default limit (:data:`mocaplab.quality.LIMITS`); the
table below says which measures are checked and why.

=================  ==========================================================================================
measure            why the touch-up must keep it
=================  ==========================================================================================
``skate``          the footplants are re-enforced after every step (the input's planted joints, frame by
``skate_max``      frame): a planted foot that slides more after the touch-up is a broken footplant step
``penetration``    the touch-up turns body parts about the pelvis or the ZMP's projection: a foot pushed into
                   the floor the input stands on would be a wrong rotation centre
``displacement``   the corrections are smoothed over 10-40 frames (sigma): a one-frame pop means an unsmoothed
``angular_``       correction (a kernel edge, a frame the line search should have refused), a knee snapped
``acceleration``   straight by the footplant IK (a hip turned beyond the leg's reach) or a knee flipped to its
                   hinge's side on frames the step never moved (issue 24)
``hinge_flips``    a rotation of the legs must not bend a knee against its own axis
``zmp``            the point of the touch-up: the ground frames end no worse balanced than the input (a flight
                   step may not buy its parabola with the take-off and landing windows)
=================  ==========================================================================================
"""

from __future__ import annotations

import warnings

import pytest

import mocaplab as ml
from mocaplab import quality

CHECKED = ("skate", "skate_max", "penetration", "displacement", "angular_acceleration", "hinge_flips", "zmp")

REALWORLD = (
    "bvhtoolbox/test_freebvh.bvh",
    "bvhtoolbox/test_mocapbank.bvh",
    "bvhtoolbox/walk01.bvh",
    "motionmachine/animation.bvh",
    "optitrack_mda/test_optitrack.bvh",
    "perfume/A_test.bvh",
    "pybvh/bvh_test1.bvh",
    "pymo/AV_8Walk_Meredith_HVHA_Rep1.bvh",
)

#: (file, measure) pairs known to regress, with the figures measured (strict expected failures).
KNOWN: dict[tuple[str, str], str] = {}


def _report(motion):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # notes about the input (rest pose, sliding feet)
        history = ml.touch_up(motion)
        return history, quality.compare(motion, history.motion)


@pytest.fixture(scope="module")
def realworld_reports(mocap_dir):
    cache: dict = {}

    def get(name):
        if name not in cache:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                motion = ml.load(mocap_dir / "realworld" / name)
            cache[name] = _report(motion)
        return cache[name]

    return get


@pytest.mark.parametrize("measure", CHECKED)
@pytest.mark.parametrize("name", REALWORLD)
def test_touch_up_adds_no_artefact_to_real_world_files(realworld_reports, name, measure, request):
    if (name, measure) in KNOWN:
        request.applymarker(pytest.mark.xfail(reason=KNOWN[(name, measure)], strict=True))
    history, report = realworld_reports(name)
    row = report[measure]
    limit = quality.LIMITS[measure]
    assert not row.regressed, f"{name}: {measure} {row.before:.3g} -> {row.after:.3g} at {row.where} (limit {limit})"
    assert not limit.exceeded(row.before, row.after)


@pytest.mark.parametrize("clip", ["16_15", "02_01", "16_11"])
def test_touch_up_adds_no_artefact_to_captured_walks(cmu, clip):
    walk = cmu(clip)
    history, report = _report(walk)
    assert history.best > 0  # it did change the walk
    for measure in CHECKED:
        row = report[measure]
        assert not row.regressed, f"{clip}: {measure} {row.before:.3g} -> {row.after:.3g} at {row.where}"
    # the walks' feet stay exactly as planted as in the capture
    assert report["skate"].after <= 1.01 * report["skate"].before
