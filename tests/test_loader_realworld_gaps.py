"""What real files from other tools still tripped the loader (issue 22, items 4 and 5).

Each case is a file written here (to ``tmp_path``) or a shared real file read
from ``MOCAPLAB_DATA_DIR``; none is copied into the repository.

* blank lines and stray whitespace anywhere in a BVH file;
* bytes that are not UTF-8 (a Latin-1 accent in a name or a comment);
* ``load(amc, asf=...)`` when a folder holds several skeletons;
* the up axis found from the body when the file does not say;
* frame times written with few digits snapped to the rate they round.
"""

from __future__ import annotations

import math
import re
import shutil
import warnings
from pathlib import Path

import numpy as np
import pytest

from mocaplab import Motion, Skeleton, load, quat
from mocaplab.io import MocapFormatError, load_asf_amc, load_bvh, save_bvh
from mocaplab.io.load import find_up_axis, snap_fps

DATA = Path(__file__).parent / "data"
CHAIN = (DATA / "chain3.bvh").read_text()
ASF = (DATA / "tiny.asf").read_text()
AMC = (DATA / "tiny.amc").read_text()
CMU_UNIT = 0.0254 / 0.45
TOL = 1e-6  # metres


def write(folder: Path, text: str | bytes, name: str = "x.bvh") -> Path:
    path = folder / name
    path.write_bytes(text if isinstance(text, bytes) else text.encode("utf-8"))
    return path


def recorded(call, *args, **kwargs):
    """``call(*args, **kwargs)`` and the warnings it gave (every one recorded)."""
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        result = call(*args, **kwargs)
    return result, caught


# ------------------------------------------------------- 1. whitespace


def _trailing(text: str, pad: str = " \t") -> str:
    return "\n".join(line + pad for line in text.split("\n"))


WHITESPACE_VARIANTS = {
    "blank line after MOTION (Perception Neuron)": CHAIN.replace("MOTION\n", "MOTION\n\n"),
    "whitespace-only lines between the header lines": CHAIN.replace("MOTION\n", "MOTION\n \t\n").replace(
        "Frames: 2\n", "Frames: 2\n\t\n\n"
    ),
    "blank lines between frames and at the end": CHAIN.replace(
        "0 0 0 0 0 0 0 0 0 0 0 0\n", "0 0 0 0 0 0 0 0 0 0 0 0\n\n \n"
    ) + "\n\n",
    "blank lines inside the hierarchy": CHAIN.replace("{\n", "{\n\n").replace("}\n", "}\n \n"),
    "trailing spaces and tabs on every line": _trailing(CHAIN),
    "leading tabs on every line": "\n".join("\t" + line for line in CHAIN.split("\n")),
    "spaces inside the header labels": CHAIN.replace("Frames:", "Frames :").replace("Frame Time:", "Frame  Time :"),
    "CRLF with all of the above": _trailing(CHAIN.replace("MOTION\n", "MOTION\n\n")).replace("\n", "\r\n"),
}


@pytest.mark.parametrize("variant", list(WHITESPACE_VARIANTS))
def test_blank_lines_and_stray_whitespace_anywhere_read_the_same(tmp_path, variant):
    ref = load_bvh(DATA / "chain3.bvh", scale=0.01)
    m = load_bvh(write(tmp_path, WHITESPACE_VARIANTS[variant]), scale=0.01)
    assert m.fps == ref.fps and m.n_frames == 2 and m.skeleton.names == ref.skeleton.names
    assert np.array_equal(m.global_positions(), ref.global_positions())


def test_blank_lines_between_many_frames_take_the_fast_reader(tmp_path, cmu):
    clip = cmu("16_15")[:400]
    save_bvh(clip, tmp_path / "a.bvh", scale=CMU_UNIT)
    lines = (tmp_path / "a.bvh").read_text().split("\n")
    start = lines.index("MOTION")
    spaced = lines[: start + 1] + [""] + lines[start + 1 : start + 3] + [x + "\n  " for x in lines[start + 3 :]]
    b = write(tmp_path, "\n".join(spaced), "b.bvh")
    a_motion = load_bvh(tmp_path / "a.bvh", scale=CMU_UNIT)
    b_motion = load_bvh(b, scale=CMU_UNIT)
    assert np.array_equal(a_motion.rotations, b_motion.rotations)
    assert np.array_equal(a_motion.root_positions, b_motion.root_positions)


@pytest.mark.parametrize(
    ("text", "line", "message"),
    [
        # the header lines are found past the blank lines, and errors name their real line
        (CHAIN.replace("MOTION\n", "MOTION\n\n").replace("Frames: 2", "Frames: two"), 23,
         "expected an integer frame count, got 'two'"),
        (CHAIN.replace("MOTION\n", "MOTION\n\n \n").replace("Frame Time: 0.1", "Frame Time: fast"), 25,
         "expected a number of seconds per frame, got 'fast'"),
        (CHAIN.replace("MOTION\n", "MOTION\n\n").replace("Frame Time: 0.1\n", ""), 24,
         "expected 'Frame Time: <value>', got '0 0 0 0 0 0 0 0 0 0 0 0'"),
        (CHAIN.replace("Frames: 2\n", "Frames: 2\n\n\n").replace("0.1", "0"), 25,
         "expected a positive, finite Frame Time, got 0"),
        # a bad row between blank lines is named at its own line
        (CHAIN.replace("0 0 0 0 0 0 0 0 0 0 0 0\n", "\n0 0 0 0 0 0 0 0 0 0 0\n\n"), 25,
         "expected 12 numbers in frame row 1, got 11"),
        (CHAIN.replace("MOTION\n", "MOTION\n\n\n"), 22, None),
    ],
)
def test_errors_past_blank_lines_name_the_real_line(tmp_path, text, line, message):
    path = write(tmp_path, text)
    if message is None:  # control: blank lines alone are no error
        assert load_bvh(path, scale=0.01).n_frames == 2
        return
    with pytest.raises(MocapFormatError) as info:
        load_bvh(path, scale=0.01)
    assert str(info.value) == f"{path}, line {line}: {message}"


def test_frame_time_label_alone_is_still_an_error(tmp_path):
    path = write(tmp_path, CHAIN.replace("Frames: 2\n", "Frames: 2\n\n").replace("Frame Time: 0.1", "Frame Time:"))
    with pytest.raises(MocapFormatError, match=r"line 24: expected a number of seconds per frame, got ''"):
        load_bvh(path, scale=0.01)


# ------------------------------------------------------- 2. encodings


def test_latin1_byte_in_a_bvh_joint_name_is_read_with_a_warning(tmp_path):
    raw = CHAIN.replace("JOINT mid", "JOINT H\u00fcfte").encode("latin-1")  # one byte 0xfc
    path = write(tmp_path, raw)
    m, caught = recorded(load_bvh, path, scale=0.01)
    assert m.skeleton.names == ("root", "H\u00fcfte", "tip")
    assert [str(w.message) for w in caught] == [
        f"{path}, line 6: byte 0xfc is not UTF-8; read as the Latin-1 character '\u00fc' "
        "(the line reads 'JOINT H\u00fcfte'). Save the file as UTF-8 to silence this"
    ]
    assert caught[0].category is UserWarning and caught[0].filename == __file__
    ref = load_bvh(DATA / "chain3.bvh", scale=0.01)
    assert np.array_equal(m.global_positions(), ref.global_positions())


def test_utf8_text_around_a_stray_byte_stays_utf8(tmp_path):
    raw = CHAIN.replace("JOINT mid", "JOINT H\u00fcfte").encode("utf-8").replace(b"JOINT tip", b"JOINT t\xe9te")
    raw = raw.replace(b"ROOT root", b"ROOT r\xe9\xe9t")  # two more bytes, one line
    m, caught = recorded(load_bvh, write(tmp_path, raw), scale=0.01)
    assert m.skeleton.names == ("r\u00e9\u00e9t", "H\u00fcfte", "t\u00e9te")
    assert len(caught) == 1
    assert "line 2: byte 0xe9 is not UTF-8" in str(caught[0].message)
    assert "(2 more such byte(s) read the same way)" in str(caught[0].message)


def test_valid_utf8_gives_no_warning(tmp_path):
    m, caught = recorded(load_bvh, write(tmp_path, CHAIN.replace("JOINT mid", "JOINT H\u00fcfte")), scale=0.01)
    assert m.skeleton.names[1] == "H\u00fcfte" and caught == []


def test_nul_byte_is_still_binary_data(tmp_path):
    path = write(tmp_path, CHAIN.encode().replace(b"JOINT tip", b"JOINT t\x00\xe9p"))
    with pytest.raises(MocapFormatError, match=r"line 10: expected text, got binary data \(NUL byte\)"):
        load_bvh(path, scale=0.01)


def test_latin1_comment_in_an_amc_header_like_hdm05(tmp_path):
    """An AMC header comment with one Latin-1 byte reads the same motion, with a warning on that line."""
    lines = AMC.split("\n")
    raw = ("\n".join([lines[0], "# erstellt f\u00fcr HDM05"] + lines[1:])).encode("latin-1")
    amc = write(tmp_path, raw, "m.amc")
    m, caught = recorded(load_asf_amc, DATA / "tiny.asf", amc)
    assert len(caught) == 1
    assert str(caught[0].message).startswith(f"{amc}, line 2: byte 0xfc is not UTF-8; read as the Latin-1 character")
    assert caught[0].filename == __file__
    ref = load_asf_amc(DATA / "tiny.asf", DATA / "tiny.amc")
    assert np.array_equal(m.global_positions(), ref.global_positions())


def test_latin1_byte_in_an_asf_comment(tmp_path):
    asf = write(tmp_path, ("# Skelett f\u00fcr Probanden\n" + ASF).encode("latin-1"), "s.asf")
    m, caught = recorded(load_asf_amc, asf, DATA / "tiny.amc")
    assert [f"{asf}, line 1: byte 0xfc" in str(w.message) for w in caught] == [True]
    assert np.array_equal(m.global_positions(), load_asf_amc(DATA / "tiny.asf", DATA / "tiny.amc").global_positions())


# ------------------------------------------------------- 3. asf=


def _two_skeletons(folder: Path) -> tuple[Path, Path, Path]:
    """A motion beside two skeletons, neither named after it; the second in other units."""
    folder.mkdir()
    shutil.copyfile(DATA / "tiny.amc", folder / "take.amc")
    shutil.copyfile(DATA / "tiny.asf", folder / "actor1.asf")
    units = re.search(r"(?m)^\s*length\s+(\S+)", ASF)
    assert units is not None
    (folder / "actor2.asf").write_text(ASF.replace(units.group(0), units.group(0).replace(units.group(1), "2.0")))
    return folder / "take.amc", folder / "actor1.asf", folder / "actor2.asf"


def test_amc_with_asf_argument_chooses_the_skeleton(tmp_path):
    amc, one, two = _two_skeletons(tmp_path / "takes")
    for asf in (one, two, str(two), bytes(str(one), "utf-8")):
        m = load(amc, asf=asf)
        ref = load_asf_amc(asf, amc)
        assert m.name == "take" and np.array_equal(m.global_positions(), ref.global_positions())
    a, b = load(amc, asf=one), load(amc, asf=two)
    assert not np.allclose(a.global_positions(), b.global_positions())  # the argument was used


def test_amc_beside_several_skeletons_lists_them(tmp_path):
    amc, _, _ = _two_skeletons(tmp_path / "takes")
    with pytest.raises(ValueError) as info:
        load(amc)
    folder = str(amc.parent)
    assert str(info.value) == (
        f"{amc}: expected the .asf skeleton take.asf or a single .asf in {folder!r}, got 2 others "
        f"(actor1.asf, actor2.asf); say which with asf=, e.g. load({str(amc)!r}, asf={str(amc.parent / 'actor1.asf')!r})"
    )


def test_asf_argument_errors(tmp_path):
    amc, _, _ = _two_skeletons(tmp_path / "takes")
    with pytest.raises(ValueError, match=r"Expected `asf` only with an .amc motion"):
        load(DATA / "chain3.bvh", asf=tmp_path / "takes" / "actor1.asf")
    with pytest.raises(ValueError, match=r"Expected `asf` only with an .amc motion"):
        load(tmp_path / "takes" / "actor1.asf", asf=tmp_path / "takes" / "actor2.asf")
    with pytest.raises(MocapFormatError, match=re.escape(f"{tmp_path / 'nope.asf'}: expected an ASF file, got no such")):
        load(amc, asf=tmp_path / "nope.asf")
    with pytest.raises(TypeError, match=r"Expected `asf` to be a str or os.PathLike, got int"):
        load(amc, asf=3)


# ------------------------------------------------------- 4. up axis

Y_TO_Z = np.array([math.sqrt(0.5), 0.0, 0.0, math.sqrt(0.5)])  # about +X by +90 degrees: +Y -> +Z
Y_TO_X = np.array([0.0, 0.0, -math.sqrt(0.5), math.sqrt(0.5)])  # about +Z by -90 degrees: +Y -> +X


def test_z_up_cmu_clip_is_found_and_turned_upright(cmu, tmp_path):
    walk = cmu("16_15")[:120]
    save_bvh(walk.transformed(rotation=Y_TO_Z), tmp_path / "z.bvh", scale=CMU_UNIT)
    m, caught = recorded(load, tmp_path / "z.bvh", scale=CMU_UNIT)
    assert [str(w.message) for w in caught] == [
        f"{tmp_path / 'z.bvh'}: the body stands along +Z (pelvis to head, feet to pelvis), so the file was read "
        "as Z up and turned to Y up. Pass up='z' to say so, or up='y' to keep the file's axes"
    ]
    assert caught[0].filename == __file__
    assert np.abs(m.global_positions() - walk.global_positions()).max() < TOL
    assert np.abs(m.end_site_positions() - walk.end_site_positions()).max() < TOL
    # up= overrides: "z" says the same without a warning; "y" keeps the file's axes (on its side)
    said, caught = recorded(load, tmp_path / "z.bvh", scale=CMU_UNIT, up="z")
    assert caught == [] and np.array_equal(said.global_positions(), m.global_positions())
    kept, caught = recorded(load, tmp_path / "z.bvh", scale=CMU_UNIT, up="y")
    assert caught == [] and find_up_axis(kept) == "+z"
    assert np.abs(kept.global_positions()[..., 2] - walk.global_positions()[..., 1]).max() < TOL


def test_y_up_clip_is_left_alone(cmu, tmp_path):
    walk = cmu("16_15")[:120]
    save_bvh(walk, tmp_path / "y.bvh", scale=CMU_UNIT)
    m, caught = recorded(load, tmp_path / "y.bvh", scale=CMU_UNIT)
    assert caught == [] and find_up_axis(m) == "+y"
    assert np.abs(m.global_positions() - walk.global_positions()).max() < TOL


def test_x_up_clip_is_kept_with_a_warning(cmu, tmp_path):
    walk = cmu("16_15")[:60]
    save_bvh(walk.transformed(rotation=Y_TO_X), tmp_path / "x.bvh", scale=CMU_UNIT)
    m, caught = recorded(load, tmp_path / "x.bvh", scale=CMU_UNIT)
    assert [str(w.message) for w in caught] == [
        f"{tmp_path / 'x.bvh'}: the body stands along +X (pelvis to head, feet to pelvis), not +Y or +Z; "
        "it is kept as read. Pass up='y' to silence this"
    ]
    assert np.array_equal(m.global_positions(), load_bvh(tmp_path / "x.bvh", scale=CMU_UNIT).global_positions())


def test_rest_pose_does_not_decide_the_motion_does(cmu, tmp_path):
    """A skeleton built Y up whose root rotation lays every frame Z up stands along Z (and the other way)."""
    walk = cmu("16_15")[:30]
    turned = walk.transformed(rotation=Y_TO_Z)
    assert np.array_equal(turned.skeleton.offsets, walk.skeleton.offsets)  # the rest pose is still Y up
    assert find_up_axis(turned) == "+z" and find_up_axis(walk) == "+y"
    upside_down = walk.transformed(rotation=quat.mul(Y_TO_Z, Y_TO_Z))
    assert find_up_axis(upside_down) == "-y"


def test_shared_z_up_file_loads_upright(mocap_dir):
    path = mocap_dir / "realworld" / "pybvh" / "bvh_test1.bvh"
    m, caught = recorded(load, path, scale=0.0254)
    assert [("stands along +Z" in str(w.message)) for w in caught] == [True]
    r = m.skeleton.roles
    g = m.global_positions()
    pelvis, head = g[:, r.index("pelvis")], g[:, r.index("head")]
    feet = g[:, [r.index("left_ankle"), r.index("right_ankle")]]
    assert np.all(head[:, 1] - pelvis[:, 1] > 0.4)  # head above the pelvis on every frame
    assert np.all(pelvis[:, None, 1] - feet[..., 1] > 0.5)  # feet down
    assert np.array_equal(g, load(path, scale=0.0254, up="z").global_positions())


def test_up_axis_is_not_guessed_without_a_body(tmp_path):
    """A chain with no pelvis, head or legs: nothing to judge by, the file is kept as read, silently."""
    m, caught = recorded(load, DATA / "chain3.bvh", scale=0.01)
    assert caught == [] and find_up_axis(m) is None


# ------------------------------------------------------- 5. frame rate


def _with_frame_time(folder: Path, clip: Motion, frame_time: str) -> Path:
    path = folder / f"t{frame_time}.bvh"
    save_bvh(clip, path, scale=CMU_UNIT)
    text, n = re.subn(r"(?m)^Frame Time:.*$", f"Frame Time: {frame_time}", path.read_text())
    assert n == 1
    path.write_text(text)
    return path


@pytest.mark.parametrize(
    ("rate", "frame_times"),
    [
        (30.0, ["0.033333", "0.0333333", "0.03333333", "0.0333"]),
        (120.0, ["0.008333", "0.0083333", "0.00833333", "0.00833"]),
        (24.0, ["0.041667", "0.0416667"]),
        (25.0, ["0.04", "0.040000"]),
        (60.0, ["0.016667", "0.0166667"]),
        (30000 / 1001, ["0.033367", "0.0333667"]),
    ],
)
def test_the_same_clip_written_with_any_digits_loads_at_the_same_rate(cmu, tmp_path, rate, frame_times):
    clip = cmu("16_15")[:40]
    loaded = [load(_with_frame_time(tmp_path, clip, t), scale=CMU_UNIT) for t in frame_times]
    assert [m.fps for m in loaded] == [rate] * len(frame_times)
    for m in loaded[1:]:
        assert np.array_equal(m.global_positions(), loaded[0].global_positions())


@pytest.mark.parametrize(
    "frame_time",
    [
        "0.0417",  # four digits cannot tell 24 (0.041667) from 24000/1001 (0.041708)
        "0.03",  # one significant digit
        "0.033",  # two
        "0.016666",  # 60 fps truncated, not rounded
        "0.03336",  # 29.976: neither 30 nor 30000/1001 at five digits
        "0.0123",  # 81.3: no common rate
    ],
)
def test_rates_the_digits_do_not_pin_are_kept_as_read(tmp_path, frame_time):
    path = write(tmp_path, CHAIN.replace("Frame Time: 0.1", f"Frame Time: {frame_time}"))
    assert load(path, scale=0.01).fps == 1 / float(frame_time)
    assert snap_fps(1 / float(frame_time)) == 1 / float(frame_time)


def test_shared_files_with_six_digit_frame_times(mocap_dir):
    """MocapBank writes 0.033333 and OptiTrack 0.008333: 30 and 120 fps exactly."""
    bank = mocap_dir / "realworld" / "bvhtoolbox" / "test_mocapbank.bvh"
    opti = mocap_dir / "realworld" / "optitrack_mda" / "test_optitrack.bvh"
    for path, written in ((bank, "0.033333"), (opti, "0.008333")):
        assert re.findall(r"Frame Time:\s*(\S+)", path.read_text(encoding="latin-1")) == [written]
    assert load(bank, scale=0.01).fps == 30.0 and load_bvh(bank, scale=0.01).fps != 30.0
    assert load(opti, scale=1.0).fps == 120.0 and load_bvh(opti, scale=1.0).fps != 120.0


# ------------------------------------------------------- 7. not a biped, through load


def quadruped() -> Skeleton:
    """A four-legged figure standing in its rest pose (a dog's proportions, metres)."""
    spec: list[tuple[str, str | None, list[float]]] = [("Pelvis", None, [0.0, 0.6, 0.0])]

    def leg(prefix: str, side: str, top: str) -> None:
        x = 0.1 if side == "L" else -0.1
        spec.extend([
            (f"{prefix}Thigh_{side}", top, [x, -0.05, 0.0]),
            (f"{prefix}Shin_{side}", f"{prefix}Thigh_{side}", [0.0, -0.25, 0.05]),
            (f"{prefix}Foot_{side}", f"{prefix}Shin_{side}", [0.0, -0.25, -0.05]),
            (f"{prefix}Toe_{side}", f"{prefix}Foot_{side}", [0.0, -0.05, 0.05]),
        ])

    leg("Hind", "L", "Pelvis")
    leg("Hind", "R", "Pelvis")
    spec += [("Spine", "Pelvis", [0.0, 0.02, 0.3]), ("Chest", "Spine", [0.0, 0.0, 0.3])]
    leg("Front", "L", "Chest")
    leg("Front", "R", "Chest")
    spec += [("Neck", "Chest", [0.0, 0.15, 0.15]), ("Head", "Neck", [0.0, 0.1, 0.1]), ("Tail", "Pelvis", [0, 0, -0.3])]
    names = [n for n, _, _ in spec]
    return Skeleton(names, [-1 if p is None else names.index(p) for _, p, _ in spec], [o for _, _, o in spec])


def test_quadruped_file_loads_and_roles_say_it_is_not_a_biped(tmp_path):
    from mocaplab.roles import RolesError

    sk = quadruped()
    dog = Motion(sk, quat.identity((5, sk.n_joints)), np.tile(sk.offsets[0], (5, 1)), 30.0)
    save_bvh(dog, tmp_path / "dog.bvh", scale=0.01)
    m, caught = recorded(load, tmp_path / "dog.bvh", scale=0.01)
    assert caught == []  # no up axis guessed from a body that is not a biped's
    with pytest.raises(RolesError, match=r"not a biped human: 4 limbs reach the ground"):
        m.skeleton.roles  # noqa: B018
    hind = {"left_ankle": "HindFoot_L", "right_ankle": "HindFoot_R", "left_hip": "HindThigh_L", "right_hip": "HindThigh_R"}
    given, _ = recorded(load, tmp_path / "dog.bvh", scale=0.01, roles=hind)
    r = given.skeleton.roles
    assert r["pelvis"] == "Pelvis" and r["left_knee"] == "HindShin_L" and r["head"] == "Head"
