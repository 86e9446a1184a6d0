"""mocaplab.load and skeleton conventions: CMU clips written in other conventions read back exactly.

Every clip is written (``tests/conventions.py``) in each convention to
``tmp_path``, read from disk with :func:`mocaplab.load`, and compared joint
by joint with the CMU original: the same global positions (to 1e-6 m, the
files' precision), the same end sites and the same frame rate.  Then the
loader's own contract: extension dispatch, Acclaim pairing, frame-rate
snapping, ``up=``, ``scale=``, ``roles=`` and untouched input files.
"""

from __future__ import annotations

import hashlib
import shutil
import warnings
from pathlib import Path

import numpy as np
import pytest
from conventions import CMU_UNIT_M, CONVENTIONS, EXTRA_JOINTS, LOAD_OPTIONS, convert

import mocaplab
from mocaplab import Motion, Skeleton, load, quat
from mocaplab.io import MocapFormatError, load_asf_amc, load_bvh, save_bvh

DATA = Path(__file__).parent / "data"
CLIPS = {"16_15": "walk", "16_05": "jump", "05_02": "dance"}
FRAMES = slice(0, 240)  # 2 s at 120 fps keeps the run fast
TOL = 1e-6  # metres


def fingerprint(path: Path) -> tuple[str, int]:
    return hashlib.sha256(path.read_bytes()).hexdigest(), path.stat().st_mtime_ns


def load_quiet(path: Path, **options) -> tuple[Motion, list[str]]:
    """``load(path)`` and the messages of the warnings it gave."""
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        motion = load(path, **options)
    return motion, [str(w.message) for w in caught]


def end_sites_by_joint(motion: Motion) -> dict[str, np.ndarray]:
    """End-site positions (F, k, 3) grouped by the name of their joint, in file order."""
    sk = motion.skeleton
    pos = motion.end_site_positions()
    return {sk.names[p]: pos[:, sk.end_site_parents == p] for p in np.unique(sk.end_site_parents)}


# ------------------------------------------------------------ conventions


@pytest.mark.parametrize("convention", CONVENTIONS)
@pytest.mark.parametrize("clip", list(CLIPS))
def test_convention_loads_to_the_cmu_positions(cmu, tmp_path, clip, convention):
    original = cmu(clip)[FRAMES]
    path, name_map = convert(original, convention, tmp_path)
    written = fingerprint(path)
    loaded, messages = load_quiet(path, **LOAD_OPTIONS.get(convention, {}))
    assert fingerprint(path) == written  # load never touches its input

    # the unit was estimated, and estimated right
    unit = "centimetres" if convention == "centimetres" else "CMU Acclaim units"
    assert len(messages) == 1 and f"assuming {unit}" in messages[0], messages

    reference = original.resample(30.0) if convention == "fps30" else original
    assert loaded.fps == reference.fps  # exactly: 0.0333333 s snaps to 30.0
    assert loaded.n_frames == reference.n_frames
    sk = loaded.skeleton
    assert set(sk.names) == set(name_map.values()) | set(EXTRA_JOINTS.get(convention, ()))
    assert len(set(name_map.values())) == len(name_map) == original.n_joints

    cmu_names = original.skeleton.names
    got = loaded.global_positions()[:, [sk.index(name_map[n]) for n in cmu_names]]
    err = np.abs(got - reference.global_positions()).max()
    assert err < TOL, f"{convention}: joints off by {err:.3g} m"

    # end sites: the same joints carry them, at the same places (on the joint when zeroed)
    want = end_sites_by_joint(reference)
    have = end_sites_by_joint(loaded)
    assert set(have) == {name_map[n] for n in want}
    for n, expected in want.items():
        if convention == "zero_end_sites":
            j = original.skeleton.index(n)
            expected = np.repeat(reference.global_positions()[:, j : j + 1], expected.shape[1], axis=1)
        assert have[name_map[n]].shape == expected.shape
        err = np.abs(have[name_map[n]] - expected).max()
        assert err < TOL, f"{convention}: end site of {n} off by {err:.3g} m"


def test_converters_do_not_change_their_input(cmu, tmp_path):
    walk = cmu("16_15")[:20]
    before = (walk.skeleton.names, walk.skeleton.offsets.copy(), walk.rotations.copy(), walk.root_positions.copy())
    for convention in CONVENTIONS:
        convert(walk, convention, tmp_path)
    assert walk.skeleton.names == before[0]
    for a, b in zip((walk.skeleton.offsets, walk.rotations, walk.root_positions), before[1:], strict=True):
        assert np.array_equal(a, b)
    with pytest.raises(ValueError, match=r"Expected `convention` to be one of \['mixamo', "):
        convert(walk, "fbx", tmp_path)


def test_game_studio_static_root_and_per_joint_translation_channels(cmu, tmp_path):
    walk = cmu("16_15")[:60]
    path, name_map = convert(walk, "game_studio", tmp_path)
    text = path.read_text()
    assert text.count("CHANNELS 6 Xposition Yposition Zposition Zrotation Yrotation Xrotation") == 32
    back = load_bvh(path, scale=CMU_UNIT_M)
    sk = back.skeleton
    assert sk.names[:2] == ("joint_Root", "Hips") and sk.parents[1] == 0
    assert name_map["LHipJoint"] == "HipOffset_L" and name_map["RightHandIndex1"] == "Index_R"
    # joint_Root: zero position and identity rotation on every frame
    assert np.array_equal(back.root_positions, np.zeros((60, 3)))
    assert np.abs(quat.angle(back.rotations[:, 0])).max() == 0.0
    # Hips moves through its own position channels, read back to the last bit
    # of the file (its values are the CMU file's, 6 decimals in CMU units)
    assert back.translations is not None
    assert np.allclose(back.translations[:, 1], walk.root_positions, rtol=0, atol=1e-12)
    # the other joints' position channels hold their constant offsets
    assert np.allclose(back.translations[:, 2:], walk.skeleton.offsets[1:], rtol=0, atol=1e-12)


def test_per_joint_translation_channels_round_trip_exactly(tmp_path, rng):
    """A joint translating through its own channels: written and read back to file precision."""
    sk = Skeleton(
        ["root", "slider", "tip"],
        [-1, 0, 1],
        [[0, 0, 0], [0, 1, 0], [0.5, 0, 0]],
        channels=[
            ("Xposition", "Yposition", "Zposition", "Zrotation", "Yrotation", "Xrotation"),
            ("Yposition", "Zrotation", "Yrotation", "Xrotation"),  # too few: save must add X and Z
            ("Zrotation", "Yrotation", "Xrotation"),
        ],
    )
    frames = 5
    tr = np.empty((frames, 3, 3))
    tr[:] = sk.offsets
    tr[:, 1] = np.round(rng.normal(size=(frames, 3)), 3)
    rot = quat.from_axis_angle(rng.normal(size=(frames, 3, 3)), rng.uniform(0, 3, size=(frames, 3)))
    m = Motion(sk, rot, np.round(rng.normal(size=(frames, 3)), 3), 25.0, translations=tr)
    save_bvh(m, tmp_path / "s.bvh", scale=0.01)
    back = load_bvh(tmp_path / "s.bvh", scale=0.01)
    assert back.skeleton.channels[1][:3] == ("Xposition", "Yposition", "Zposition")
    assert back.translations is not None
    assert np.abs(back.translations - tr).max() < 1e-14
    assert np.abs(back.global_positions() - m.global_positions()).max() < 1e-7


def test_zero_length_end_sites_written_and_read(tmp_path):
    sk = Skeleton(
        ["root", "toe"], [-1, 0], [[0, 0, 0], [0, 0, 0.1]], end_site_parents=[1, 1], end_site_offsets=[[0, 0, 0]] * 2
    )
    m = Motion(sk, quat.identity((3, 2)), np.array([[0, 1, 0], [1, 1, 0], [2, 1, 0.0]]), 30.0)
    save_bvh(m, tmp_path / "z.bvh", scale=1.0)
    assert (tmp_path / "z.bvh").read_text().count("OFFSET 0.000000 0.000000 0.000000") == 3  # root + 2 ends
    back = load(tmp_path / "z.bvh", scale=1.0)
    assert back.skeleton.end_site_parents.tolist() == [1, 1]
    assert np.array_equal(back.skeleton.end_site_offsets, np.zeros((2, 3)))
    assert np.array_equal(back.end_site_positions(), np.repeat(back.global_positions()[:, 1:], 2, axis=1))


def test_x_bones_rest_pose_is_along_x(cmu, tmp_path):
    walk = cmu("16_15")[:10]
    path, _ = convert(walk, "x_bones", tmp_path)
    back = load_bvh(path, scale=CMU_UNIT_M)
    sk = back.skeleton
    for j in range(sk.n_joints):
        kids = sk.children(j)
        if kids and np.linalg.norm(walk.skeleton.offsets[kids[0]]) > 0:
            first = sk.offsets[kids[0]]
            assert first[0] > 0 and np.abs(first[1:]).max() < 1e-6, (sk.names[j], first)
            assert np.isclose(first[0], np.linalg.norm(walk.skeleton.offsets[kids[0]]), atol=1e-6)
    # the rest pose is no longer the CMU one (the knee is not below the hip)
    knee = sk.index("LeftLeg")
    assert abs(sk.offsets[knee][1]) < 1e-6 and walk.skeleton.offsets[knee][1] < -0.3


def test_z_up_file_stands_along_z(cmu, tmp_path):
    walk = cmu("16_15")[:10]
    path, _ = convert(walk, "z_up", tmp_path)
    raw = load_bvh(path, scale=CMU_UNIT_M)  # as written: Z up
    head, foot = raw.skeleton.index("Head"), raw.skeleton.index("LeftFoot")
    p = raw.global_positions()
    assert np.all(p[:, head, 2] - p[:, foot, 2] > 1.0)
    assert np.allclose(p[:, :, 2], walk.global_positions()[:, :, 1], atol=TOL)
    assert np.allclose(p[:, :, 1], -walk.global_positions()[:, :, 2], atol=TOL)


# ---------------------------------------------------------------- load()

Z_UP_BVH = """HIERARCHY
ROOT root
{
\tOFFSET 0 0 7
\tCHANNELS 6 Xposition Yposition Zposition Zrotation Yrotation Xrotation
\tJOINT top
\t{
\t\tOFFSET 1 0 1
\t\tCHANNELS 3 Zrotation Yrotation Xrotation
\t\tEnd Site
\t\t{
\t\t\tOFFSET 0 0 0.5
\t\t}
\t}
}
MOTION
Frames: 2
Frame Time: FRAME_TIME
1 2 3 0 0 0 0 0 0
1 2 3 90 0 0 0 0 0
"""


def write_bvh(tmp_path: Path, frame_time: str = "0.1", name: str = "t.bvh") -> Path:
    path = tmp_path / name
    path.write_text(Z_UP_BVH.replace("FRAME_TIME", frame_time))
    return path


def test_up_z_is_a_rigid_turn_to_y_up_hand_computed(tmp_path):
    path = write_bvh(tmp_path)
    m = load(path, up="z", scale=1.0)
    p, e = m.global_positions(), m.end_site_positions()
    # (x, y, z) -> (x, z, -y); frame 1 turns 90 degrees about the file's up
    # axis (+Z), which becomes a turn about +Y: (1, 1, 0) -> (0, 1, -1)
    assert np.allclose(p[0], [[1, 3, -2], [2, 4, -2]], atol=1e-12)
    assert np.allclose(e[0], [[2, 4.5, -2]], atol=1e-12)
    assert np.allclose(p[1], [[1, 3, -2], [1, 4, -3]], atol=1e-12)
    assert np.allclose(e[1], [[1, 4.5, -3]], atol=1e-12)
    # only the root changes: its OFFSET turns (the root is placed by its
    # channels, not its OFFSET); the child's offset and rotation stay as in the file
    same = load(path, scale=1.0)
    assert np.array_equal(same.skeleton.offsets[0], [0, 0, 7]) and np.array_equal(m.skeleton.offsets[0], [0, 7, 0])
    assert np.array_equal(m.skeleton.offsets[1:], same.skeleton.offsets[1:])
    assert np.array_equal(m.rotations[:, 1:], same.rotations[:, 1:])
    assert np.allclose(quat.yaw(quat.mul(m.rotations[1, 0], quat.inv(m.rotations[0, 0]))), np.pi / 2)


@pytest.mark.parametrize("up", ["x", "Y", "-z", "auto"])  # None is the default: the axis is found from the body
def test_bad_up_value(tmp_path, up):
    with pytest.raises(ValueError) as info:
        load(tmp_path / "missing.bvh", up=up)  # checked before the file is read
    assert str(info.value) == (
        f"Expected `up` to be 'y' or 'z' (the file's up axis) or None (found from the body), got {up!r}"
    )


def test_unknown_extension(tmp_path):
    path = tmp_path / "clip.c3d"
    path.write_text("not read")
    with pytest.raises(ValueError) as info:
        load(path)
    assert str(info.value) == (
        f"Expected `path` to end in one of .bvh, .asf, .amc, .fbx, .gltf, .glb (case-insensitive), got {str(path)!r}"
    )


def test_bvh_dispatch_any_case_and_name(tmp_path):
    path = write_bvh(tmp_path, name="Clip.BVH")
    m = load(path, scale=1.0)
    ref = load_bvh(path, scale=1.0)
    assert m.name == "Clip" and load(path, scale=1.0, name="x").name == "x"
    assert np.array_equal(m.global_positions(), ref.global_positions())


@pytest.mark.parametrize(
    ("frame_time", "fps"),
    [
        ("0.0333333", 30.0),
        ("0.008333333", 120.0),
        ("0.0416667", 24.0),
        ("0.0417083", 24000 / 1001),
        ("0.0333667", 30000 / 1001),
        ("0.0166833", 60000 / 1001),
        ("0.1", 10.0),
        ("0.0123", 1 / 0.0123),  # 81.30..., no standard rate near: kept
        ("0.03336", 1 / 0.03336),  # 29.976: between 30000/1001 and 30, near neither
        ("3", 1 / 3),  # below 1 fps: nothing to snap to
    ],
)
def test_frame_rate_snapping(tmp_path, frame_time, fps):
    m = load(write_bvh(tmp_path, frame_time), scale=1.0)
    assert m.fps == fps


def test_scale_is_honoured_and_silences_the_estimate(tmp_path):
    path = write_bvh(tmp_path)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        metres = load(path, scale=1.0)
        half = load(path, scale=0.5)
    assert np.allclose(half.global_positions(), 0.5 * metres.global_positions(), rtol=0, atol=1e-15)
    with pytest.raises(ValueError, match=r"Expected `scale` > 0"):
        load(path, scale=-1.0)


def test_estimated_unit_warning_points_at_the_caller(tmp_path):
    with pytest.warns(UserWarning, match="BVH has no unit; assuming") as record:
        load(write_bvh(tmp_path))
    assert [w.filename for w in record] == [__file__]


def tiny_acclaim(folder: Path, asf: str, *amcs: str) -> None:
    folder.mkdir(parents=True, exist_ok=True)
    shutil.copyfile(DATA / "tiny.asf", folder / asf)
    for amc in amcs:
        shutil.copyfile(DATA / "tiny.amc", folder / amc)


def test_amc_dispatch_finds_its_asf(tmp_path):
    ref = load_asf_amc(DATA / "tiny.asf", DATA / "tiny.amc")
    # the CMU rule: 07_01.amc goes with 07.asf, even beside another skeleton
    tiny_acclaim(tmp_path / "a", "07.asf", "07_01.amc")
    shutil.copyfile(DATA / "tiny.asf", tmp_path / "a" / "other.asf")
    # the same stem, and the only .asf in the folder
    tiny_acclaim(tmp_path / "b", "walk.asf", "walk.amc")
    tiny_acclaim(tmp_path / "c", "skeleton.ASF", "run_3.AMC")
    for path in (tmp_path / "a" / "07_01.amc", tmp_path / "b" / "walk.amc", tmp_path / "c" / "run_3.AMC"):
        before = {p: fingerprint(p) for p in path.parent.iterdir()}
        m = load(path)
        assert {p: fingerprint(p) for p in path.parent.iterdir()} == before
        assert m.name == path.stem and m.skeleton.names == ref.skeleton.names and m.fps == 120.0
        assert np.array_equal(m.global_positions(), ref.global_positions())
    # an .asf with the one motion in its folder
    m = load(tmp_path / "b" / "walk.asf", name="w")
    assert m.name == "w" and np.array_equal(m.global_positions(), ref.global_positions())
    # scale= is the ASF unit
    half = load(tmp_path / "b" / "walk.amc", scale=0.5 * 0.0254)
    assert np.allclose(half.global_positions(), 0.5 * ref.global_positions(), rtol=0, atol=1e-15)


def test_acclaim_pairing_errors(tmp_path):
    lonely = tmp_path / "lonely"
    lonely.mkdir()
    shutil.copyfile(DATA / "tiny.amc", lonely / "09_01.amc")
    with pytest.raises(MocapFormatError) as info:
        load(lonely / "09_01.amc")
    assert str(info.value) == (
        f"{lonely / '09_01.amc'}: expected an .asf skeleton beside the .amc motion (09.asf or 09_01.asf "
        f"or the only .asf in {str(lonely)!r}), got no .asf file there; put the skeleton next to the motion"
    )
    shutil.copyfile(DATA / "tiny.asf", lonely / "x.asf")
    shutil.copyfile(DATA / "tiny.asf", lonely / "y.asf")
    with pytest.raises(ValueError, match=r"09_01.amc: expected the .asf skeleton 09.asf or 09_01.asf or a single "):
        load(lonely / "09_01.amc")
    many = tmp_path / "many"
    tiny_acclaim(many, "16.asf", "16_01.amc", "16_02.amc")
    with pytest.raises(ValueError) as info:
        load(many / "16.asf")
    assert str(info.value) == (
        f"{many / '16.asf'}: an .asf holds only a skeleton; expected one .amc motion in {str(many)!r}, got 2 "
        f"(16_01.amc, 16_02.amc); pass the .amc path instead, e.g. load({str(many / '16_01.amc')!r})"
    )
    with pytest.raises(MocapFormatError, match="none.amc: expected an AMC file, got no such file"):
        load(tmp_path / "none.amc")


def test_cmu_amc_from_the_mirror(mocap_dir):
    amc = mocap_dir / "asfamc" / "16" / "16_15.amc"
    asf = amc.parent / "16.asf"
    before = fingerprint(amc), fingerprint(asf)
    m = load(amc)
    assert (fingerprint(amc), fingerprint(asf)) == before
    ref = load_asf_amc(asf, amc)
    assert m.name == "16_15" and m.fps == 120.0 and m.skeleton.names[:2] == ("root", "lhipjoint")
    assert np.array_equal(m.global_positions(), ref.global_positions())


def test_roles_argument(cmu, tmp_path):
    with pytest.raises(TypeError) as info:
        load(tmp_path / "x.bvh", roles=["pelvis"])
    assert str(info.value) == (
        "Expected `roles` to be a mapping of role name to joint name (or None), got list"
    )
    if not hasattr(Skeleton, "with_roles"):
        pytest.skip("Skeleton.with_roles (mocaplab/roles.py) is not there yet")
    path, name_map = convert(cmu("16_15")[:10], "mixamo", tmp_path)
    m, _ = load_quiet(path, roles={"pelvis": name_map["Hips"]})
    ref = load_bvh(path, scale=CMU_UNIT_M)
    assert m.skeleton.roles["pelvis"] == name_map["Hips"]
    assert m.skeleton.roles == ref.skeleton.with_roles(pelvis=name_map["Hips"]).roles


def test_exported_lazily():
    assert mocaplab.load is mocaplab.io.load is load
    assert "load" in mocaplab.__all__ and "load" in mocaplab.io.__all__
