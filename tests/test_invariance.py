"""The same motion under another convention gives the same answers.

Each CMU clip is written in every convention of ``tests/conventions.py``
(other joint names, a static root above a travelling pelvis with 6 channels
on every joint, centimetres, zero-length end sites, bones along +X with the
rest rotations baked in, Z up, 30 fps), read back from disk with
:func:`mocaplab.load` and run through the core with **no joint name
passed**.  Roles, foot contacts, the path joint, mirroring and refinement
must agree with the CMU original joint by joint (1 mm; contacts exactly).
"""

from __future__ import annotations

import warnings

import numpy as np
import pytest
from conventions import CONVENTIONS, EXTRA_JOINTS, as_original

from mocaplab.contacts import foot_contacts, stillness_contacts
from mocaplab.editing.refinement import refine

CLIPS = ("16_15", "16_05", "05_02")
FRAMES = slice(0, 360)
TOL = 1e-3  # metres


def _original(cmu, clip, convention):
    return as_original(cmu(clip)[FRAMES], convention)


@pytest.fixture(scope="module")
def converted(converted):
    """The shared ``converted`` fixture (tests/conftest.py) on this module's frames."""
    return lambda clip, convention: converted(clip, convention, FRAMES)


def _columns(motion, names):
    return [motion.skeleton.index(n) for n in names]


@pytest.mark.parametrize("convention", CONVENTIONS)
@pytest.mark.parametrize("clip", CLIPS)
def test_roles_name_the_same_joints(cmu, converted, clip, convention):
    m, name_map = converted(clip, convention)
    want = cmu(clip).skeleton.roles
    got = m.skeleton.roles
    assert set(got) == set(want)
    for role, value in want.items():
        mapped = tuple(name_map[v] for v in value) if role == "spine" else name_map[value]
        assert got[role] == mapped, role


@pytest.mark.parametrize("convention", CONVENTIONS)
@pytest.mark.parametrize("clip", CLIPS)
def test_contacts_and_path_joint(cmu, converted, clip, convention):
    m, name_map = converted(clip, convention)
    ref = _original(cmu, clip, convention)
    # the path joint is the pelvis, wherever the file puts the travel
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        pelvis = m.pelvis_positions
    if convention in EXTRA_JOINTS:
        assert m.path_joint == m.skeleton.index(name_map["Hips"])
        assert any("never moves" in str(w.message) for w in caught)
    assert np.abs(pelvis - ref.root_positions).max() < TOL
    assert np.ptp(pelvis[:, [0, 2]], axis=0).max() > 0.1 or clip == "05_02"
    for detector in (foot_contacts, stillness_contacts):
        a, b = detector(ref), detector(m)
        assert b.joints == tuple(name_map[j] for j in a.joints)
        assert np.array_equal(a.mask, b.mask), detector.__name__


@pytest.mark.parametrize("convention", CONVENTIONS)
def test_mirror_swaps_the_same_joints(cmu, converted, convention):
    m, name_map = converted("16_15", convention)
    ref = _original(cmu, "16_15", convention)
    names = list(ref.skeleton.names)
    a = ref.mirror().global_positions()
    b = m.mirror().global_positions()[:, _columns(m, [name_map[n] for n in names])]
    assert np.abs(a - b).max() < TOL
    # and mirroring really swapped sides: the left ankle ends where the right one was, reflected
    left, right = names.index("LeftFoot"), names.index("RightFoot")
    flip = np.array([-1.0, 1.0, 1.0])
    assert np.abs(b[:, left] - ref.global_positions()[:, right] * flip).max() < TOL


@pytest.mark.parametrize("convention", CONVENTIONS)
def test_refine_gives_the_same_joint_positions(cmu, converted, convention):
    m, name_map = converted("16_15", convention)
    ref = _original(cmu, "16_15", convention)
    n = ref.n_frames
    bend = np.linspace(0.0, 0.6, n)  # a turning edit that makes the feet slide

    def edited(motion):
        p = motion.pelvis_positions
        turned = motion.transformed(yaw=bend)
        # keep the pelvis where it was: the edit only turns the body
        from mocaplab import quat

        back = p - quat.rotate(quat.from_yaw(bend), p)
        return motion.transformed(yaw=bend, translation=back), turned

    ea, _ = edited(ref)
    eb, _ = edited(m)
    ra = refine(ea, reference=ref)
    rb = refine(eb, reference=m)
    cols = _columns(m, [name_map[x] for x in ref.skeleton.names])
    assert np.abs(ea.global_positions() - eb.global_positions()[:, cols]).max() < TOL
    moved = np.abs(ra.global_positions() - ea.global_positions()).max()
    assert moved > 0.01  # refinement did something
    assert np.abs(ra.global_positions() - rb.global_positions()[:, cols]).max() < TOL
