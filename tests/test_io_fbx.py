"""FBX reading: the four Blender-exported CMU clips against their BVH, hand-made ASCII files, bad files."""

from __future__ import annotations

import gc
import os
import struct
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from fbx_ascii import Bone, ascii_fbx
from scipy.spatial.transform import Rotation

import mocaplab as ml
from mocaplab.io import MocapFormatError, load_fbx
from mocaplab.io import fbx as fbx_module

pytest.importorskip("ufbx")

CLIPS = ["16_15", "05_02", "16_05", "02_01"]
CMU_UNIT = 0.0254 / 0.45


def _bvh(mocap_dir: Path, clip: str) -> ml.Motion:
    return ml.load(mocap_dir / "bvh" / f"{clip}.bvh", scale=CMU_UNIT)


@pytest.mark.parametrize("clip", CLIPS)
def test_blender_fbx_matches_the_bvh_clip(mocap_dir: Path, clip: str) -> None:
    """World positions of every joint, matched by name, agree with the BVH clip's forward kinematics."""
    fbx = ml.load(mocap_dir / "fbx" / f"{clip}.fbx")
    bvh = _bvh(mocap_dir, clip)
    assert fbx.fps == 120.0 and fbx.n_frames == bvh.n_frames
    assert sorted(fbx.skeleton.names) == sorted(bvh.skeleton.names)
    order = [bvh.skeleton.index(n) for n in fbx.skeleton.names]
    error = np.abs(fbx.global_positions() - bvh.global_positions()[:, order]).max()
    print(f"{clip}: max joint position error {error * 1000:.4f} mm")
    assert error < 1e-5  # 0.01 mm (measured 0.001-0.003 mm); the issue asks for 1 mm
    # the same roles, inferred from the same names and the same rest pose
    assert dict(fbx.skeleton.roles) == dict(bvh.skeleton.roles)
    assert fbx.translations is None  # rigid bones: constant offsets


def test_fps_option_resamples_the_take(mocap_dir: Path) -> None:
    fbx = load_fbx(mocap_dir / "fbx" / "16_05.fbx", fps=60)
    bvh = _bvh(mocap_dir, "16_05")
    assert fbx.fps == 60 and fbx.n_frames == (bvh.n_frames + 1) // 2
    order = [bvh.skeleton.index(n) for n in fbx.skeleton.names]
    assert np.abs(fbx.global_positions() - bvh.global_positions()[::2, order]).max() < 1e-5


def test_take_by_name_and_index(mocap_dir: Path) -> None:
    path = mocap_dir / "fbx" / "16_05.fbx"
    first = load_fbx(path)
    for take in (0, -1, "Scene"):
        assert np.array_equal(load_fbx(path, take=take).rotations, first.rotations)
    with pytest.raises(MocapFormatError, match=r"16_05\.fbx: expected an animation stack \(take\) named 'Walk', got takes \['Scene'\]"):
        load_fbx(path, take="Walk")
    with pytest.raises(MocapFormatError, match="take index below 1"):
        load_fbx(path, take=3)


def test_scale_option_overrides_the_file_unit(mocap_dir: Path) -> None:
    path = mocap_dir / "fbx" / "16_05.fbx"
    metres = load_fbx(path)
    doubled = load_fbx(path, scale=0.02)  # the file says centimetres
    assert np.allclose(doubled.global_positions(), 2 * metres.global_positions())


def test_repeated_loads_are_stable(mocap_dir: Path) -> None:
    """ufbx 0.0.5's bindings crash on released elements; the worker process keeps the caller safe and exact."""
    path = mocap_dir / "fbx" / "16_05.fbx"
    first = load_fbx(path)
    for _ in range(3):
        gc.collect()
        again = load_fbx(path)
        assert np.array_equal(again.rotations, first.rotations)
        assert np.array_equal(again.root_positions, first.root_positions)


# ----------------------------------------------------------- hand-made files
def _write(tmp_path: Path, bones: list[Bone], name: str = "rig.fbx", **kw) -> Path:
    path = tmp_path / name
    path.write_text(ascii_fbx(bones, **kw))
    return path


def _swing(**kw) -> list[Bone]:
    """A hip at 1 m with a 90-degree pre-rotation about Z, swinging about X from 0 to 90 degrees in 1 s; a knee 0.5 m below."""
    return [
        Bone("Hips", None, (0, 100, 0), pre_rotation=(0, 0, 90), keys={"X": [(0, 0), (1, 90)]}, **kw),
        Bone("Knee", "Hips", (0, -50, 0)),
    ]


def test_ascii_fbx_pre_rotation_hand_computed(tmp_path: Path) -> None:
    m = load_fbx(_write(tmp_path, _swing()))
    assert m.fps == 30 and m.n_frames == 31 and m.skeleton.names == ("Hips", "Knee")
    theta = np.radians(np.linspace(0, 90, 31))
    # knee = hip + Rz(90) Rx(theta) (0, -0.5, 0) = (0.5 cos, 1, -0.5 sin)
    expected = np.stack([0.5 * np.cos(theta), np.ones(31), -0.5 * np.sin(theta)], axis=1)
    assert np.allclose(m.global_positions()[:, 1], expected, atol=1e-9)
    assert np.allclose(m.root_positions, [0, 1, 0])


@pytest.mark.parametrize("order", range(6))
def test_rotation_order(tmp_path: Path, order: int) -> None:
    """FBX order XYZ (0) ... ZYX (5): Euler angles applied about X first for XYZ, as in every DCC tool."""
    axes = ("XYZ", "XZY", "YZX", "YXZ", "ZXY", "ZYX")[order]
    bones = [
        Bone("Hips", None, (0, 100, 0), rotation=(30, 50, 70), rotation_order=order, keys={"X": [(0, 30), (1, 30)]}),
        Bone("Knee", "Hips", (0, -50, 10)),
    ]
    m = load_fbx(_write(tmp_path, bones))
    angles = dict(zip("XYZ", (30, 50, 70), strict=True))
    r = Rotation.from_euler(axes.lower(), [angles[a] for a in axes], degrees=True)  # extrinsic: first axis first
    expected = np.array([0, 1, 0]) + r.apply([0, -0.5, 0.1])
    assert np.allclose(m.global_positions()[0, 1], expected, atol=1e-9)
    assert m.skeleton.channels[0][3:] == tuple(f"{a}rotation" for a in reversed(axes))


def test_unit_from_the_file(tmp_path: Path) -> None:
    metres = load_fbx(_write(tmp_path, _swing(), "m.fbx", unit_cm=100.0))
    centimetres = load_fbx(_write(tmp_path, _swing(), "cm.fbx"))
    assert np.allclose(metres.global_positions(), 100 * centimetres.global_positions())


def test_nodes_between_bones_and_above_are_folded(tmp_path: Path) -> None:
    """An armature node above the root and a null between two bones move the joints; they are not joints."""
    bones = [
        Bone("Armature", None, (10, 0, 0), kind="Null"),
        Bone("Hips", "Armature", (0, 100, 0), pre_rotation=(0, 0, 90), keys={"X": [(0, 0), (1, 90)]}),
        Bone("Group", "Hips", (0, -20, 0), kind="Null"),
        Bone("Knee", "Group", (0, -30, 0)),
    ]
    m = load_fbx(_write(tmp_path, bones))
    plain = load_fbx(_write(tmp_path, _swing(), "plain.fbx"))
    assert m.skeleton.names == ("Hips", "Knee")
    assert np.allclose(m.global_positions(), plain.global_positions() + [0.1, 0, 0], atol=1e-9)


def test_several_skeletons_need_a_choice(tmp_path: Path) -> None:
    bones = _swing() + [Bone("Tail", None, (0, 50, 0), keys={"Y": [(0, 0), (1, 10)]}), Bone("Tip", "Tail", (0, 0, -20))]
    path = _write(tmp_path, bones)
    with pytest.raises(MocapFormatError, match=r"rig\.fbx: expected one skeleton \(pass skeleton= .*got 2 skeletons with root joints 'Hips', 'Tail'"):
        load_fbx(path)
    assert load_fbx(path, skeleton="Tail").skeleton.names == ("Tail", "Tip")
    assert load_fbx(path, skeleton="Hips").skeleton.names == ("Hips", "Knee")
    with pytest.raises(MocapFormatError, match="named 'Head'"):
        load_fbx(path, skeleton="Head")


def test_without_animation_or_skeleton(tmp_path: Path) -> None:
    with pytest.raises(MocapFormatError, match=r"expected an animation stack \(take\), got none"):
        load_fbx(_write(tmp_path, _swing(), take=None))
    still = [Bone("Hips", None, (0, 100, 0)), Bone("Knee", "Hips", (0, -50, 0))]
    with pytest.raises(MocapFormatError, match="animation curves on the skeleton's joints"):
        load_fbx(_write(tmp_path, still, "still.fbx"))
    nulls = [Bone("Hips", None, (0, 100, 0), kind="Null", keys={"X": [(0, 0), (1, 9)]})]
    with pytest.raises(MocapFormatError, match=r"expected a skeleton \(bone or limb nodes\), got none"):
        load_fbx(_write(tmp_path, nulls, "nulls.fbx"))


def test_not_an_fbx(tmp_path: Path) -> None:
    for content, got in ((b"HIERARCHY\nROOT Hips\n", "HIERARCHY"), (b"", "an empty file")):
        path = tmp_path / "dance.fbx"
        path.write_bytes(content)
        with pytest.raises(MocapFormatError, match=rf"dance\.fbx: expected an FBX file .*got .*{got}"):
            load_fbx(path)
    with pytest.raises(MocapFormatError, match="no such file"):
        load_fbx(tmp_path / "missing.fbx")


def test_truncated_binary_file(mocap_dir: Path, tmp_path: Path) -> None:
    raw = (mocap_dir / "fbx" / "16_05.fbx").read_bytes()
    for cut in (len(raw) // 2, 30, len(raw) - 200):
        path = tmp_path / "cut.fbx"
        path.write_bytes(raw[:cut])
        with pytest.raises(MocapFormatError, match=r"cut\.fbx: expected a complete FBX file.*truncated"):
            load_fbx(path)


def test_array_count_beyond_its_bytes_is_rejected_unread(mocap_dir: Path, tmp_path: Path) -> None:
    """A header value cannot make the reader allocate: an array promising 2**31 floats is refused before ufbx."""
    raw = bytearray((mocap_dir / "fbx" / "16_05.fbx").read_bytes())
    at = raw.index(b"KeyValueFloat") + len(b"KeyValueFloat")
    assert raw[at : at + 1] == b"f"
    raw[at + 1 : at + 5] = struct.pack("<I", 2**31)
    path = tmp_path / "huge.fbx"
    path.write_bytes(bytes(raw))
    with pytest.raises(MocapFormatError, match=r"whose 2,147,483,648 elements fit its"):
        load_fbx(path)


def test_frames_bounded_by_the_keys(tmp_path: Path) -> None:
    """A take whose span would need far more frames than its curves hold keys is refused, not allocated."""
    path = _write(tmp_path, _swing(), stop=1e6)  # two keys, a take of a million seconds
    with pytest.raises(MocapFormatError, match="a take of at most 100,000 frames"):
        load_fbx(path)


def test_a_crashing_worker_is_a_format_error(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """A worker killed by a signal (the bindings crashing) is reported on the file, not raised as a crash."""
    path = _write(tmp_path, _swing())
    real_run = subprocess.run

    def crash(args, **kw):
        kw.pop("input", None)
        return real_run([sys.executable, "-c", "import os, signal; os.kill(os.getpid(), signal.SIGSEGV)"], **kw)

    monkeypatch.setattr(fbx_module.subprocess, "run", crash)
    with pytest.raises(MocapFormatError, match=r"rig\.fbx: expected a file the ufbx reader can read, got the ufbx reader stopped by signal"):
        load_fbx(path)


def test_options_are_checked(tmp_path: Path) -> None:
    path = _write(tmp_path, _swing())
    with pytest.raises(ValueError, match="Expected `fps`"):
        load_fbx(path, fps=0)
    with pytest.raises(ValueError, match="Expected `scale`"):
        load_fbx(path, scale=-1.0)
    with pytest.raises(TypeError, match="Expected `take`"):
        load_fbx(path, take=1.5)


def test_load_dispatches_fbx(tmp_path: Path) -> None:
    path = _write(tmp_path, _swing(), "UPPER.FBX")
    m = ml.load(os.fspath(path))
    assert m.name == "UPPER" and m.n_frames == 31
