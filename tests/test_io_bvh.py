"""BVH reading and writing: hand-made files, every malformed case, round trips."""

from __future__ import annotations

import os
import re
import tracemalloc
import warnings
from pathlib import Path

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from mocaplab import quat
from mocaplab.io import MocapFormatError, estimate_scale, load_bvh, save_bvh
from mocaplab.io.bvh import FPS_RANGE, MAX_INDENT, MAX_INTEGER_DIGITS
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
    m = load_bvh(write(tmp_path, CHAIN.replace("JOINT mid", "JOINT left knee"), "x.bvh"), scale=0.01)
    assert m.skeleton.names[1] == "left knee"
    # a name the writer could not give back is refused, not rewritten (it was read as 'left knee')
    with pytest.raises(MocapFormatError, match="line 6: expected a joint name .* got 'left  knee': it has leading"):
        load_bvh(write(tmp_path, CHAIN.replace("JOINT mid", "JOINT left  knee"), "x.bvh"), scale=0.01)


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


def test_bytes_that_are_not_utf8_are_read_as_latin1_then_parsed(tmp_path):
    """Not UTF-8: read as Latin-1 with a warning naming line and byte; garbage then fails where it lies."""
    data = CHAIN.encode()
    pos = data.index(b"MOTION")
    path = write(tmp_path, data[:pos] + b"\xff\xfe\x80" + data[pos:])
    with pytest.warns(UserWarning, match=r"line 21: byte 0xff is not UTF-8; read as the Latin-1 character 'ÿ'"):
        assert_format_error(path, 21, "expected 'MOTION' after the hierarchy, got 'ÿþ\\x80MOTION'")


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


# ------------------------------------------ bounds and paths (issue 17)


def test_frame_count_is_checked_against_the_rows_before_allocating(tmp_path):
    """'Frames: 1000000000' over two rows: the truncated-file error, allocating only what the file holds."""
    path = write(tmp_path, edit(CHAIN, 22, "Frames: 1000000000"))
    tracemalloc.start()
    try:
        assert_format_error(
            path, 25, "expected 1000000000 frame row(s) as declared by 'Frames:', got 2 (truncated file?)"
        )
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert peak < 20_000_000  # bytes; the header alone used to ask for 89 GiB
    most = "9" * MAX_INTEGER_DIGITS
    assert_format_error(
        write(tmp_path, edit(CHAIN, 22, f"Frames: {most}")),
        25,
        f"expected {most} frame row(s) as declared by 'Frames:', got 2 (truncated file?)",
    )


@pytest.mark.parametrize("digits", [MAX_INTEGER_DIGITS + 1, 21, 4301, 100_000])
def test_header_integers_are_bounded_before_conversion(tmp_path, digits):
    big = "1" + "0" * (digits - 1)  # 21 digits: 1e20 written out
    assert_format_error(
        write(tmp_path, edit(CHAIN, 22, f"Frames: {big}")),
        22,
        f"expected a frame count of at most {MAX_INTEGER_DIGITS} digits, got {digits} digits",
    )
    assert_format_error(
        write(tmp_path, edit(CHAIN, 9, f"    CHANNELS {big} Zrotation Yrotation Xrotation")),
        9,
        f"expected a channel count between 0 and 6, got a {digits}-digit number",
    )


@pytest.mark.parametrize("value", ["1e-300", "0.00001", "0.0000999", "1e300", "10.5", "86400"])
def test_implausible_frame_time_is_rejected_at_its_line(tmp_path, value):
    fps = 1.0 / float(value)
    assert_format_error(
        write(tmp_path, edit(CHAIN, 23, f"Frame Time: {value}")),
        23,
        f"expected a Frame Time from 0.0001 to 10 s (0.1 to 10000 frames per second), got {value} ({fps:.6g} fps)",
    )


@pytest.mark.parametrize("value", ["0.0001", "10", "0.008333333", "1e-4", "0.04"])
def test_frame_time_range_is_inclusive(tmp_path, value):
    m = load_bvh(write(tmp_path, edit(CHAIN, 23, f"Frame Time: {value}")), scale=0.01)
    assert m.fps == 1.0 / float(value) and FPS_RANGE[0] <= m.fps <= FPS_RANGE[1]


def _symlink(link: Path, target: Path) -> Path:
    try:
        link.symlink_to(target)
    except (OSError, NotImplementedError):  # pragma: no cover - no symlinks on this system
        pytest.skip("symbolic links are not available")
    return link


def bad_paths(tmp_path: Path) -> dict[str, tuple[Path, str]]:
    """Paths that cannot be read, each with the 'got' part of its error."""
    regular = tmp_path / "regular.bvh"
    regular.write_text(CHAIN)
    loop_a, loop_b = tmp_path / "loop_a.bvh", tmp_path / "loop_b.bvh"
    _symlink(loop_a, loop_b)
    _symlink(loop_b, loop_a)
    gone = tmp_path / "gone.bvh"
    (tmp_path / "folder").mkdir()
    cases = {
        "missing": (tmp_path / "missing.bvh", "no such file"),
        "dangling symlink": (_symlink(tmp_path / "dangling.bvh", gone), f"a dangling symbolic link (to {str(gone)!r})"),
        "symlink loop": (loop_a, "a symbolic link loop"),
        "directory": (tmp_path / "folder", "a directory"),
        "symlink to a directory": (_symlink(tmp_path / "to_folder", tmp_path / "folder"), "a directory"),
        "file as a folder": (regular / "x.bvh", "no such file (a folder in the path is a file)"),
    }
    if hasattr(os, "mkfifo"):
        os.mkfifo(tmp_path / "pipe.bvh")
        cases["named pipe"] = (tmp_path / "pipe.bvh", "not a regular file (a device, pipe or socket)")
    if os.path.exists(os.devnull) and not os.path.isfile(os.devnull):
        cases["device"] = (Path(os.devnull), "not a regular file (a device, pipe or socket)")
    return cases


@pytest.mark.timeout(20)  # a named pipe must not block the reader
def test_every_path_problem_is_a_format_error_naming_the_path(tmp_path):
    for case, (path, got) in bad_paths(tmp_path).items():
        with pytest.raises(MocapFormatError) as info:
            load_bvh(path, scale=0.01)
        assert str(info.value) == f"{path}: expected a BVH file, got {got}", case
        assert (info.value.path, info.value.line) == (str(path), 0)
        assert isinstance(info.value, ValueError)


def test_empty_path():
    for empty in ("", b""):
        with pytest.raises(MocapFormatError) as info:
            load_bvh(empty, scale=0.01)
        assert str(info.value) == "'': expected a path to a BVH file, got an empty path"


def test_path_types(tmp_path):
    """str and PathLike as given, bytes decoded with os.fsdecode, anything else a TypeError."""
    (tmp_path / "ok.bvh").write_text(CHAIN)
    m = load_bvh(os.fsencode(tmp_path / "ok.bvh"), scale=0.01)
    assert m.name == "ok"
    save_bvh(m, os.fsencode(tmp_path / "back.bvh"))
    back = load_bvh(str(tmp_path / "back.bvh"), scale=0.01)
    assert back.name == "back" and max_position_error(m, back) < 1e-8
    for bad in (3, None, ["ok.bvh"]):
        with pytest.raises(TypeError, match=f"Expected `path` to be a str or os.PathLike, got {type(bad).__name__}"):
            load_bvh(bad, scale=0.01)  # type: ignore[arg-type]
        with pytest.raises(TypeError, match="Expected `path` to be a str or os.PathLike"):
            save_bvh(m, bad)  # type: ignore[arg-type]


def small_motion(rng: np.random.Generator, names=("root", "mid", "tip"), fps: float = 30.0) -> Motion:
    sk = Skeleton(
        list(names), [-1, 0, 1], [[0.1, 0.9, 0], [0, 0.4, 0.05], [0, 0.3, 0]], end_site_parents=[2],
        end_site_offsets=[[0, 0.1, 0]],
    )
    rot = Rotation.random(3 * 4, random_state=rng).as_quat().reshape(4, 3, 4)
    return Motion(sk, rot, rng.normal(size=(4, 3)), fps)


@pytest.mark.parametrize(
    ("bad", "why"),
    [
        ("a\x00b", "it holds the control character '\\x00'"),
        ("a\tb", "it holds the control character '\\t'"),
        ("line\nbreak", "it holds the control character '\\n'"),
        ("bell\x07", "it holds the control character '\\x07'"),
        ("a\u00a0b", "it has leading, trailing or repeated whitespace, or whitespace other than a space"),
        ("a\u2028b", "it has leading, trailing or repeated whitespace, or whitespace other than a space"),
        ("two  spaces", "it has leading, trailing or repeated whitespace, or whitespace other than a space"),
        (" lead", "it has leading, trailing or repeated whitespace, or whitespace other than a space"),
        ("\ud800", "it is not valid Unicode text (it holds a lone surrogate)"),
        ("x }", "its word '}' is a BVH keyword or brace"),
        ("{", "its word '{' is a BVH keyword or brace"),
        ("End", "its word 'End' is a BVH keyword or brace"),
        ("", "it is empty"),
    ],
)
def test_write_refuses_a_name_it_cannot_give_back_naming_the_joint(tmp_path, rng, bad, why):
    m = small_motion(rng, names=("root", bad, "tip"))
    with pytest.raises(ValueError) as info:
        save_bvh(m, tmp_path / "n.bvh")
    assert str(info.value) == f"Joint 1 name {bad!r} cannot be written to a BVH file: {why}; rename the joint"
    assert not (tmp_path / "n.bvh").exists()  # checked before the file is opened


@pytest.mark.parametrize("scale", [1e300, 1e-3, 1.0, 1e-300])
def test_write_at_any_scale_reads_back(tmp_path, rng, scale):
    """Lengths keep their significant digits whatever the unit (scale 1e300 used to write zeros)."""
    m = small_motion(rng)
    save_bvh(m, tmp_path / "s.bvh", scale=scale)
    back = load_bvh(tmp_path / "s.bvh", scale=scale)
    assert max_position_error(m, back) < 1e-6
    assert np.allclose(back.skeleton.offsets, m.skeleton.offsets, rtol=1e-6, atol=0)


def test_write_refuses_a_scale_that_overflows_the_file_units(tmp_path, rng):
    with pytest.raises(ValueError) as info:
        save_bvh(small_motion(rng), tmp_path / "o.bvh", scale=1e-310)
    assert str(info.value) == (
        "Expected `scale` to keep every length finite in file units, got 1e-310: "
        "the motion's lengths divided by it overflow; pass a larger scale"
    )
    assert not (tmp_path / "o.bvh").exists()


@pytest.mark.parametrize("fps", [1e-3, 0.09, 10001.0, 1e6])
def test_no_motion_has_a_frame_rate_load_bvh_would_reject(tmp_path, rng, fps):
    # the Motion itself refuses it, so save_bvh can never write one
    with pytest.raises(ValueError, match=re.escape(f"Expected `fps` from 0.1 to 10000 frames per second, got {fps!r}")):
        small_motion(rng, fps=fps)


@pytest.mark.parametrize("fps", [0.1, 10000.0])
def test_write_then_read_at_the_ends_of_the_frame_rate_range(tmp_path, rng, fps):
    save_bvh(small_motion(rng, fps=fps), tmp_path / "f.bvh")
    assert load_bvh(tmp_path / "f.bvh", scale=0.01).fps == fps


@pytest.mark.parametrize("precision", [-1, 18, 2.5, True, "6"])
def test_write_refuses_a_bad_precision(tmp_path, rng, precision):
    with pytest.raises(ValueError, match=re.escape(f"Expected `precision` to be an integer from 0 to 17 (decimals), got {precision!r}")):
        save_bvh(small_motion(rng), tmp_path / "p.bvh", precision=precision)


def test_deep_skeleton_is_written_with_bounded_indentation(tmp_path):
    """A 20,000-joint chain: hierarchy lines of bounded width (tabs per level made it 1 GB), read back the same."""
    n = 20_000
    sk = Skeleton(
        [f"j{i}" for i in range(n)], np.arange(-1, n - 1), np.tile([0.0, 0.01, 0.0], (n, 1)),
        end_site_parents=[n - 1], end_site_offsets=[[0.0, 0.01, 0.0]],
    )
    m = Motion(sk, quat.identity((1, n)), np.zeros((1, 3)), 30.0)
    path = tmp_path / "deep.bvh"
    save_bvh(m, path)
    lines = path.read_text().split("\n")
    hierarchy = lines[: lines.index("MOTION")]
    assert max(len(s) - len(s.lstrip("\t")) for s in hierarchy) == MAX_INDENT + 2  # End Site OFFSET, deepest
    assert max(len(s) for s in hierarchy) < MAX_INDENT + 80
    assert path.stat().st_size < 10_000_000
    back = load_bvh(path, scale=0.01)
    assert back.skeleton.names == sk.names
    assert np.array_equal(back.skeleton.parents, sk.parents)
    assert np.allclose(back.skeleton.offsets, sk.offsets, rtol=0, atol=1e-12)
    assert np.allclose(back.skeleton.end_site_offsets, sk.end_site_offsets, rtol=0, atol=1e-12)
