"""BVH reading and writing: hand-made files, every malformed case, round trips."""

from __future__ import annotations

import re
import warnings
from pathlib import Path

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from mocaplab import quat
from mocaplab.io import MocapFormatError, estimate_scale, load_bvh, save_bvh
from mocaplab.motion import Motion, Skeleton

DATA = Path(__file__).parent / "data"
CHAIN = (DATA / "chain3.bvh").read_text()
CMU_UNIT = 0.0254 / 0.45


def write(tmp_path: Path, text: str | bytes, name: str = "bad.bvh") -> Path:
    path = tmp_path / name
    if isinstance(text, bytes):
        path.write_bytes(text)
    else:
        path.write_bytes(text.encode("utf-8"))
    return path


def lines_of(text: str) -> list[str]:
    return text.split("\n")


def edit(text: str, line: int, new: str | None) -> str:
    """Replace 1-based line ``line`` (None deletes it)."""
    rows = lines_of(text)
    if new is None:
        del rows[line - 1]
    else:
        rows[line - 1] = new
    return "\n".join(rows)


def assert_format_error(path: Path, line: int, message: str) -> MocapFormatError:
    """The error names the file, the line and the expectation (message pinned)."""
    with pytest.raises(MocapFormatError) as info:
        load_bvh(path, scale=0.01)
    err = info.value
    assert err.path == str(path)
    assert err.line == line
    expected = f"{path}, line {line}: {message}" if line else f"{path}: {message}"
    assert str(err) == expected
    assert isinstance(err, ValueError)
    return err


# ------------------------------------------------------------- hand-made


def test_chain3_hand_computed_positions():
    m = load_bvh(DATA / "chain3.bvh", scale=0.01)
    assert m.skeleton.names == ("root", "mid", "tip")
    assert m.skeleton.parents.tolist() == [-1, 0, 1]
    assert m.fps == pytest.approx(10.0) and m.n_frames == 2 and m.name == "chain3"
    p = m.global_positions() * 100
    e = m.end_site_positions() * 100
    assert np.allclose(p[0], [[0, 0, 0], [0, 10, 0], [0, 15, 0]])
    assert np.allclose(e[0], [[0, 17, 0]])
    # frame 1: root at (1, 2, 3) turned 90 deg about Z, so mid = root + Rz (0, 10, 0);
    # mid turned 90 deg about X: tip = mid + Rz Rx (0, 5, 0) = mid + (0, 0, 5)
    assert np.allclose(p[1], [[1, 2, 3], [-9, 2, 3], [-9, 2, 8]], atol=1e-12)
    assert np.allclose(e[1], [[-9, 2, 10]], atol=1e-12)
    assert m.skeleton.channels[0] == ("Xposition", "Yposition", "Zposition", "Zrotation", "Yrotation", "Xrotation")


def test_mixed_file_crlf_tabs_exponents_and_joint_positions():
    """Root with position channels only, a joint with interleaved position and
    rotation channels in Y X Z rotation order; CRLF, tabs, 1e0 / 2.5E-1 / +90.0."""
    m = load_bvh(DATA / "mixed.bvh", scale=1.0)
    assert m.fps == pytest.approx(2.0)
    assert m.skeleton.channels[1] == ("Yrotation", "Xposition", "Yposition", "Zposition", "Xrotation", "Zrotation")
    p, e = m.global_positions(), m.end_site_positions()
    assert np.allclose(p[0], [[0.25, 1, -3], [2.25, 1, -3]], atol=1e-12)
    assert np.allclose(e[0, 0], [3.25, 1, -3], atol=1e-12)  # Ry(90) takes +z to +x
    assert np.allclose(p[1], [[0, 0, 0], [1, 1, 1]], atol=1e-12)
    assert np.allclose(e[1, 0], [1, 0, 1], atol=1e-12)  # Rx(90) Rz(90) takes +z to -y
    assert m.translations is not None
    assert np.allclose(m.translations[:, 1], [[2, 0, 0], [1, 1, 1]])


@pytest.mark.parametrize("newline", ["\r\n", "\r"])
def test_line_endings_do_not_matter(tmp_path, newline):
    m = load_bvh(write(tmp_path, CHAIN.replace("\n", newline), "x.bvh"), scale=0.01)
    ref = load_bvh(DATA / "chain3.bvh", scale=0.01)
    assert np.allclose(m.global_positions(), ref.global_positions())


def test_tabs_blank_lines_and_byte_order_mark(tmp_path):
    text = "\ufeff\n" + CHAIN.replace("  ", "\t").replace("MOTION\n", "MOTION\n").replace("0.1\n0 0", "0.1\n\n0 0")
    m = load_bvh(write(tmp_path, text, "x.bvh"), scale=0.01)
    assert m.n_frames == 2 and np.allclose(m.global_positions()[1, 2] * 100, [-9, 2, 8])


def test_joint_names_with_spaces(tmp_path):
    m = load_bvh(write(tmp_path, CHAIN.replace("JOINT mid", "JOINT left  knee"), "x.bvh"), scale=0.01)
    assert m.skeleton.names[1] == "left knee"


@pytest.mark.parametrize("order", ["XYZ", "XZY", "YXZ", "YZX", "ZXY", "ZYX"])
def test_any_channel_order_matches_scipy(tmp_path, order, rng):
    angles = rng.uniform(-170, 170, size=(5, 3))
    chans = " ".join(f"{a}rotation" for a in order)
    rows = "\n".join("0 0 0 " + " ".join(f"{v:.10f}" for v in a) for a in angles)
    text = (
        "HIERARCHY\nROOT r\n{\n OFFSET 0 0 0\n CHANNELS 6 Xposition Yposition Zposition "
        f"{chans}\n End Site\n {{\n OFFSET 0 1 0\n }}\n}}\nMOTION\nFrames: 5\nFrame Time: 0.01\n{rows}\n"
    )
    m = load_bvh(write(tmp_path, text, "x.bvh"), scale=1.0)
    expected = Rotation.from_euler(order, angles, degrees=True).as_quat()
    d = np.minimum(np.abs(m.rotations[:, 0] - expected).max(-1), np.abs(m.rotations[:, 0] + expected).max(-1))
    assert d.max() < 1e-10
    assert np.allclose(m.end_site_positions()[:, 0], Rotation.from_quat(expected).apply([0, 1, 0]), atol=1e-9)


def test_fewer_rotation_channels(tmp_path):
    text = CHAIN.replace("CHANNELS 3 Zrotation Yrotation Xrotation\n    JOINT tip", "CHANNELS 1 Xrotation\n    JOINT tip")
    text = text.replace("0 0 0 0 0 0 0 0 0 0 0 0", "0 0 0 0 0 0 0 0 0 0").replace(
        "1 2 3 90 0 0 0 0 90 0 0 0", "1 2 3 90 0 0 90 0 0 0"
    )
    m = load_bvh(write(tmp_path, text, "x.bvh"), scale=0.01)
    assert np.allclose(m.end_site_positions()[1, 0] * 100, [-9, 2, 10], atol=1e-12)


# ------------------------------------------------------------ scale


def test_scale_is_estimated_with_a_warning(mocap_dir):
    with pytest.warns(UserWarning, match=re.escape("assuming CMU Acclaim units (1/0.45 inch)")):
        m = load_bvh(mocap_dir / "bvh" / "16_35.bvh")
    ref = load_bvh(mocap_dir / "bvh" / "16_35.bvh", scale=CMU_UNIT)
    assert np.allclose(m.global_positions(), ref.global_positions())
    with pytest.warns(UserWarning, match="assuming centimetres"):
        load_bvh(mocap_dir / "pair_salsa_daz" / "60_10.bvh")


def test_explicit_scale_gives_no_warning_and_scales_everything():
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        m1 = load_bvh(DATA / "chain3.bvh", scale=1.0)
        m2 = load_bvh(DATA / "chain3.bvh", scale=0.5)
    assert np.allclose(m2.global_positions(), 0.5 * m1.global_positions())
    assert np.allclose(m2.end_site_positions(), 0.5 * m1.end_site_positions())


def test_estimate_scale_rule():
    sk = Skeleton(["a", "b"], [-1, 0], [[0, 0, 0], [0, 170, 0]])
    assert estimate_scale(sk) == (0.01, "centimetres")
    sk = Skeleton(["a", "b"], [-1, 0], [[0, 0, 0], [0, 1.8, 0]])
    assert estimate_scale(sk) == (1.0, "metres")
    sk = Skeleton(["a"], [-1], [[0, 0, 0]])
    assert estimate_scale(sk) == (1.0, "metres")


@pytest.mark.parametrize("scale", [0, -1.0, float("nan"), float("inf")])
def test_bad_scale_argument(scale):
    with pytest.raises(ValueError, match=r"Expected `scale` > 0 \(metres per file unit\)"):
        load_bvh(DATA / "chain3.bvh", scale=scale)


# ------------------------------------------------------ malformed files


def test_empty_file(tmp_path):
    assert_format_error(write(tmp_path, ""), 1, "expected 'HIERARCHY', got an empty file")
    assert_format_error(write(tmp_path, " \n\t\n"), 1, "expected 'HIERARCHY', got an empty file")


def test_missing_hierarchy(tmp_path):
    assert_format_error(write(tmp_path, edit(CHAIN, 1, None)), 1, "expected 'HIERARCHY', got 'ROOT root'")


def test_missing_root(tmp_path):
    assert_format_error(write(tmp_path, edit(CHAIN, 2, "JOINT root")), 2, "expected 'ROOT', got 'JOINT'")


def test_missing_motion_section(tmp_path):
    text = "\n".join(lines_of(CHAIN)[:20]) + "\n"
    assert_format_error(write(tmp_path, text), 20, "expected a 'MOTION' section, got end of file")


def test_missing_motion_keyword(tmp_path):
    assert_format_error(
        write(tmp_path, edit(CHAIN, 21, None)), 21, "expected 'MOTION' after the hierarchy, got 'Frames:'"
    )


def test_unbalanced_braces_missing_close(tmp_path):
    assert_format_error(
        write(tmp_path, edit(CHAIN, 18, None)),
        20,
        "expected 'JOINT', 'End Site' or '}', got 'MOTION' (is a '}' missing?)",
    )


def test_unbalanced_braces_extra_close(tmp_path):
    text = edit(CHAIN, 17, "      }\n      }")
    assert_format_error(write(tmp_path, text), 21, "expected 'MOTION' after the hierarchy, got an unbalanced '}'")


def test_unbalanced_braces_missing_open(tmp_path):
    assert_format_error(write(tmp_path, edit(CHAIN, 7, None)), 7, "expected a joint name followed by '{', got 'OFFSET'")


def test_unknown_channel_name(tmp_path):
    text = edit(CHAIN, 9, "    CHANNELS 3 Zrotation Yrotation Wrotation")
    assert_format_error(write(tmp_path, text), 9, "expected a channel name (X/Y/Z position or rotation), got 'Wrotation'")


def test_too_few_channel_names(tmp_path):
    text = edit(CHAIN, 9, "    CHANNELS 3 Zrotation Yrotation")
    assert_format_error(write(tmp_path, text), 9, "expected 3 channel names after 'CHANNELS 3', got only 2")


def test_too_many_channel_names(tmp_path):
    text = edit(CHAIN, 9, "    CHANNELS 3 Zrotation Yrotation Xrotation Xposition")
    assert_format_error(write(tmp_path, text), 9, "expected 3 channel names after 'CHANNELS 3', got more ('Xposition')")


def test_bad_channel_count(tmp_path):
    text = edit(CHAIN, 9, "    CHANNELS 7 Zrotation Yrotation Xrotation")
    assert_format_error(write(tmp_path, text), 9, "expected a channel count between 0 and 6, got 7")
    text = edit(CHAIN, 9, "    CHANNELS three Zrotation Yrotation Xrotation")
    assert_format_error(write(tmp_path, text), 9, "expected an integer channel count, got 'three'")


def test_channel_named_twice(tmp_path):
    text = edit(CHAIN, 9, "    CHANNELS 3 Zrotation Zrotation Xrotation")
    assert_format_error(write(tmp_path, text), 9, "expected each channel once per joint, got Zrotation twice")


def test_row_with_too_few_numbers(tmp_path):
    text = edit(CHAIN, 24, "0 0 0 0 0 0 0 0 0 0 0")
    assert_format_error(write(tmp_path, text), 24, "expected 12 numbers in frame row 1, got 11")


def test_row_with_too_many_numbers(tmp_path):
    text = edit(CHAIN, 25, "1 2 3 90 0 0 0 0 90 0 0 0 7")
    assert_format_error(write(tmp_path, text), 25, "expected 12 numbers in frame row 2, got 13")


@pytest.mark.parametrize("token", ["abc", "1,5", "0x10", "1_000", "٣"])
def test_non_numeric_token(tmp_path, token):
    text = edit(CHAIN, 25, f"1 2 3 90 0 {token} 0 0 90 0 0 0")
    assert_format_error(write(tmp_path, text), 25, f"expected a number, got {token!r}")


@pytest.mark.parametrize("token", ["nan", "NaN", "inf", "-inf", "1e999"])
def test_non_finite_number(tmp_path, token):
    text = edit(CHAIN, 24, f"0 0 0 0 {token} 0 0 0 0 0 0 0")
    assert_format_error(write(tmp_path, text), 24, f"expected a finite number, got {token!r}")


def test_non_numeric_offset(tmp_path):
    assert_format_error(write(tmp_path, edit(CHAIN, 8, "    OFFSET 0 ten 0")), 8, "expected a number in OFFSET, got 'ten'")
    assert_format_error(
        write(tmp_path, edit(CHAIN, 8, "    OFFSET 0 nan 0")), 8, "expected a finite number in OFFSET, got 'nan'"
    )


def test_more_rows_than_frames(tmp_path):
    text = edit(CHAIN, 22, "Frames: 1")
    assert_format_error(write(tmp_path, text), 25, "expected 1 frame row(s) as declared by 'Frames:', got more rows")


def test_fewer_rows_than_frames(tmp_path):
    text = edit(CHAIN, 22, "Frames: 3")
    assert_format_error(
        write(tmp_path, text), 25, "expected 3 frame row(s) as declared by 'Frames:', got 2 (truncated file?)"
    )


def test_bad_frame_count(tmp_path):
    assert_format_error(write(tmp_path, edit(CHAIN, 22, "Frames: 0")), 22, "expected a frame count of at least 1, got 0")
    assert_format_error(write(tmp_path, edit(CHAIN, 22, "Frames: -2")), 22, "expected an integer frame count, got '-2'")
    assert_format_error(write(tmp_path, edit(CHAIN, 22, "Frames: 2.5")), 22, "expected an integer frame count, got '2.5'")
    assert_format_error(write(tmp_path, edit(CHAIN, 22, "Frame: 2")), 22, "expected 'Frames: <value>', got 'Frame: 2'")


@pytest.mark.parametrize("value", ["0", "-0.1", "0.0", "nan", "inf", "1e-320"])
def test_zero_or_negative_frame_time(tmp_path, value):
    text = edit(CHAIN, 23, f"Frame Time: {value}")
    assert_format_error(write(tmp_path, text), 23, f"expected a positive, finite Frame Time, got {value}")


def test_non_numeric_frame_time(tmp_path):
    text = edit(CHAIN, 23, "Frame Time: fast")
    assert_format_error(write(tmp_path, text), 23, "expected a number of seconds per frame, got 'fast'")


def test_duplicate_joint_names(tmp_path):
    text = edit(CHAIN, 10, "    JOINT mid")
    assert_format_error(write(tmp_path, text), 10, "expected unique joint names, got a second joint named 'mid'")


def test_joint_without_name(tmp_path):
    assert_format_error(write(tmp_path, edit(CHAIN, 10, "    JOINT")), 10, "expected a joint name, got none")


def test_bad_keyword_in_joint(tmp_path):
    text = edit(CHAIN, 14, "      Endsite")
    assert_format_error(write(tmp_path, text), 14, "expected 'JOINT', 'End Site' or '}', got 'Endsite'")


def test_no_channels_at_all(tmp_path):
    text = "HIERARCHY\nROOT a\n{\n OFFSET 0 0 0\n}\nMOTION\nFrames: 1\nFrame Time: 0.1\n\n"
    assert_format_error(write(tmp_path, text), 2, "expected at least one CHANNELS entry in the hierarchy, got none")


@pytest.mark.parametrize(
    ("keep", "line", "message"),
    [
        (12, 12, "expected 'JOINT', 'End Site' or '}', got end of file (truncated file?)"),
        (9, 9, "expected 'JOINT', 'End Site' or '}', got end of file (truncated file?)"),
        (21, 21, "expected 'Frames:' line, got end of file (truncated)"),
        (22, 22, "expected 'Frame Time:' line, got end of file (truncated)"),
        (24, 24, "expected 2 frame row(s) as declared by 'Frames:', got 1 (truncated file?)"),
    ],
)
def test_truncated_file(tmp_path, keep, line, message):
    text = "\n".join(lines_of(CHAIN)[:keep]) + "\n"
    assert_format_error(write(tmp_path, text), line, message)


def test_truncated_inside_a_row(tmp_path):
    text = CHAIN[: CHAIN.rindex("90 0 0 0") + 4]
    assert_format_error(write(tmp_path, text), 25, "expected 12 numbers in frame row 2, got 10")


def test_binary_garbage_nul(tmp_path):
    data = CHAIN.encode()
    pos = data.index(b"JOINT tip")
    path = write(tmp_path, data[:pos] + b"\x00\x01\x02garbage" + data[pos:])
    assert_format_error(path, 10, "expected text, got binary data (NUL byte)")


def test_binary_garbage_invalid_utf8(tmp_path):
    data = CHAIN.encode()
    pos = data.index(b"MOTION")
    path = write(tmp_path, data[:pos] + b"\xff\xfe\x80" + data[pos:])
    assert_format_error(path, 21, "expected UTF-8 or ASCII text, got undecodable byte 0xff")


def test_random_binary_file(tmp_path, rng):
    path = write(tmp_path, rng.integers(0, 256, size=4000, dtype=np.uint8).tobytes())
    with pytest.raises(MocapFormatError, match=re.escape(str(path))):
        load_bvh(path, scale=0.01)


def test_directory_is_a_format_error(tmp_path):
    with pytest.raises(MocapFormatError, match="expected a BVH file, got a directory"):
        load_bvh(tmp_path, scale=0.01)


def test_overflowing_values_are_a_format_error(tmp_path):
    text = edit(CHAIN, 24, "1e308 0 0 0 0 0 0 0 0 0 0 0")
    with pytest.raises(MocapFormatError, match=r"root position values that stay finite in metres \(scale 10\)"):
        load_bvh(write(tmp_path, text), scale=10.0)


# ---------------------------------------------------------- round trips


def max_position_error(a: Motion, b: Motion) -> float:
    pa = np.concatenate([a.global_positions(), a.end_site_positions()], axis=1)
    pb = np.concatenate([b.global_positions(), b.end_site_positions()], axis=1)
    return float(np.abs(pa - pb).max())


@pytest.mark.parametrize("clip", ["16_15", "05_02", "60_10"])
def test_write_then_read_real_clips(tmp_path, mocap_dir, cmu, clip):
    m = cmu(clip)
    path = tmp_path / f"{clip}.bvh"
    save_bvh(m, path)
    back = load_bvh(path, scale=0.01)
    assert back.skeleton.names == m.skeleton.names
    assert back.skeleton.channels == m.skeleton.channels
    assert back.fps == pytest.approx(m.fps, rel=1e-8)
    assert max_position_error(m, back) < 1e-4  # 0.1 mm


@pytest.mark.parametrize("fps", [60.0, 120.0, 30.0, 24.0])
def test_write_then_read_keeps_fps_exactly(tmp_path, fps):
    # a clip written and read back must still concatenate with the original
    sk = Skeleton(["hips", "knee"], [-1, 0], [[0, 0, 0], [0, -0.5, 0]])
    m = Motion(sk, np.tile([0.0, 0.0, 0.0, 1.0], (3, 2, 1)), np.zeros((3, 3)), fps)
    save_bvh(m, tmp_path / "f.bvh")
    back = load_bvh(tmp_path / "f.bvh", scale=0.01)
    assert back.fps == fps


@pytest.mark.parametrize("order", ["XYZ", "XZY", "YXZ", "YZX", "ZXY", "ZYX"])
def test_write_then_read_random_poses(tmp_path, rng, order):
    parents = [-1, 0, 1, 2, 0, 4, 5, 0, 7]
    n = len(parents)
    chans = [("Xposition", "Yposition", "Zposition") + tuple(f"{a}rotation" for a in order)]
    chans += [tuple(f"{a}rotation" for a in order)] * (n - 1)
    sk = Skeleton(
        [f"j{i}" for i in range(n)],
        parents,
        rng.normal(scale=0.3, size=(n, 3)),
        channels=chans,
        end_site_parents=[3, 6, 8],
        end_site_offsets=rng.normal(scale=0.1, size=(3, 3)),
    )
    rot = Rotation.random(50 * n, random_state=rng).as_quat().reshape(50, n, 4)
    m = Motion(sk, rot, rng.normal(size=(50, 3)), 60.0)
    save_bvh(m, tmp_path / "r.bvh", scale=0.01)
    back = load_bvh(tmp_path / "r.bvh", scale=0.01)
    assert back.skeleton.channels == m.skeleton.channels
    assert max_position_error(m, back) < 1e-4


def test_write_then_read_keeps_joint_translations(tmp_path):
    m = load_bvh(DATA / "mixed.bvh", scale=1.0)
    save_bvh(m, tmp_path / "m.bvh", scale=0.01)
    back = load_bvh(tmp_path / "m.bvh", scale=0.01)
    assert np.allclose(back.translations, m.translations, atol=1e-8)
    assert max_position_error(m, back) < 1e-6


def test_write_adds_channels_a_motion_needs(tmp_path, rng):
    sk = Skeleton(["a", "b"], [-1, 0], [[0, 0, 0], [0, 1, 0]], channels=[("Yposition",), ("Xrotation",)])
    rot = Rotation.random(8, random_state=rng).as_quat().reshape(4, 2, 4)
    m = Motion(sk, rot, rng.normal(size=(4, 3)), 30.0)
    save_bvh(m, tmp_path / "c.bvh", scale=1.0)
    back = load_bvh(tmp_path / "c.bvh", scale=1.0)
    assert back.skeleton.channels[0] == ("Xposition", "Yposition", "Zposition", "Zrotation", "Yrotation", "Xrotation")
    assert max_position_error(m, back) < 1e-6


def test_write_breadth_first_skeleton_reads_back_depth_first(tmp_path, rng):
    # joints listed breadth first: a, b, c, b1, c1  (b1 child of b, c1 child of c)
    sk = Skeleton(["a", "b", "c", "b1", "c1"], [-1, 0, 0, 1, 2], rng.normal(size=(5, 3)))
    rot = Rotation.random(15, random_state=rng).as_quat().reshape(3, 5, 4)
    m = Motion(sk, rot, rng.normal(size=(3, 3)), 30.0)
    save_bvh(m, tmp_path / "bfs.bvh", scale=1.0)
    back = load_bvh(tmp_path / "bfs.bvh", scale=1.0)
    assert back.skeleton.names == ("a", "b", "b1", "c", "c1")
    order = [sk.names.index(n) for n in back.skeleton.names]
    assert np.allclose(back.global_positions(), m.global_positions()[:, order], atol=1e-6)


@pytest.mark.parametrize("bad", ["", "two  spaces", " lead", "a{b}", "x }", "End"])
def test_write_rejects_names_a_bvh_cannot_hold(tmp_path, bad):
    sk = Skeleton(["root", bad], [-1, 0], np.zeros((2, 3)))
    m = Motion(sk, quat.identity((1, 2)), np.zeros((1, 3)), 30.0)
    if bad == "a{b}":  # braces inside a word are fine: they are not tokens
        save_bvh(m, tmp_path / "ok.bvh")
        assert load_bvh(tmp_path / "ok.bvh", scale=0.01).skeleton.names[1] == "a{b}"
        return
    with pytest.raises(ValueError, match="cannot be written to a BVH file"):
        save_bvh(m, tmp_path / "n.bvh")


def test_load_does_not_return_partial_motion_on_error(tmp_path):
    # a file correct up to its last row: still nothing but the error
    text = edit(CHAIN, 25, "1 2 3 90 0 0 0 0 90 0 0 oops")
    with pytest.raises(MocapFormatError):
        load_bvh(write(tmp_path, text), scale=0.01)


def test_estimate_scale_leaves_out_a_reference_root():
    # a figure 170 units tall whose pelvis sits 4000 units from a reference root at the origin
    names = ["Reference", "Pelvis", "Knee", "Foot", "Head"]
    offsets = [[0, 0, 0], [4000.0, 90, 0], [0, -45, 0], [0, -45, 0], [0, 80, 0]]
    sk = Skeleton(names, [-1, 0, 1, 2, 1], offsets)
    assert estimate_scale(sk) == (0.01, "centimetres")
    # the same figure with the pelvis as the root
    assert estimate_scale(Skeleton(names[1:], [-1, 0, 1, 0], offsets[1:])) == (0.01, "centimetres")
