"""Acclaim ASF/AMC: a hand-made pair, agreement with the CMU BVH, malformed files."""

from __future__ import annotations

import os
import time
from pathlib import Path

import numpy as np
import pytest

from mocaplab import data
from mocaplab.io import MocapFormatError, load_asf_amc, load_bvh
from mocaplab.io.asfamc import CMU_BVH_NAMES, parse_asf
from mocaplab.io.bvh import MAX_INTEGER_DIGITS

DATA = Path(__file__).parent / "data"
ASF = (DATA / "tiny.asf").read_text()
AMC = (DATA / "tiny.amc").read_text()
INCH = 0.0254
ACCLAIM_CLIPS = [c for c in data.clips() if "asf" in data.describe(c)]


def write(tmp_path: Path, asf: str | bytes = ASF, amc: str | bytes = AMC) -> tuple[Path, Path]:
    paths = []
    for name, text in (("s.asf", asf), ("m.amc", amc)):
        p = tmp_path / name
        p.write_bytes(text if isinstance(text, bytes) else text.encode())
        paths.append(p)
    return paths[0], paths[1]


def edit(text: str, line: int, new: str | None) -> str:
    rows = text.split("\n")
    if new is None:
        del rows[line - 1]
    else:
        rows[line - 1] = new
    return "\n".join(rows)


def last_line(text: str) -> int:
    """Number of the last line with text ("end of file" errors point there)."""
    return len(text.rstrip().split("\n"))


def line_of(text: str, needle: str) -> int:
    return next(i for i, s in enumerate(text.split("\n"), start=1) if needle in s)


def assert_error(asf: Path, amc: Path, bad: Path, line: int, message: str) -> None:
    with pytest.raises(MocapFormatError) as info:
        load_asf_amc(asf, amc)
    err = info.value
    assert (err.path, err.line) == (str(bad), line)
    assert str(err) == (f"{bad}, line {line}: {message}" if line else f"{bad}: {message}")


# --------------------------------------------------------------- hand-made


def test_tiny_pair_hand_computed():
    m = load_asf_amc(DATA / "tiny.asf", DATA / "tiny.amc")
    assert m.skeleton.names == ("root", "hip", "arm", "hand")
    assert m.skeleton.parents.tolist() == [-1, 0, 1, 2]
    assert m.fps == 120.0 and m.n_frames == 2 and m.name == "tiny"
    # length 1.0 in :units means inches; bones from the root start at the root
    assert np.allclose(m.skeleton.offsets / INCH, [[0, 0, 0], [0, 0, 0], [0, 10, 0], [5, 0, 0]])
    assert m.skeleton.end_site_parents.tolist() == [3]
    p = m.global_positions() / INCH
    e = m.end_site_positions() / INCH
    # frame 1: arm rx = 90 about its axis C = Rz(90), i.e. 90 deg about +y: +x -> -z
    assert np.allclose(p[0], [[0, 0, 0], [0, 0, 0], [0, 10, 0], [0, 10, -5]], atol=1e-12)
    assert np.allclose(e[0], [[0, 10, -7]], atol=1e-12)
    # frame 2: root at (1, 2, 3) turned RZ = 90; hand "rz rx" = (90, 90): +x -> +y -> +z
    assert np.allclose(p[1], [[1, 2, 3], [1, 2, 3], [-9, 2, 3], [-9, 7, 3]], atol=1e-12)
    assert np.allclose(e[1], [[-9, 7, 5]], atol=1e-12)


def test_dof_order_is_the_order_of_application(tmp_path):
    asf = ASF.replace("    dof rz rx", "    dof rx rz")
    amc = AMC.replace("hand 90 90", "hand 90 90")  # now rx = 90 first, then rz = 90
    m = load_asf_amc(*write(tmp_path, asf, amc))
    # +x -> (rx) +x -> (rz) +y, turned by the root's RZ 90: -x
    assert np.allclose(m.end_site_positions()[1, 0] / INCH, [-11, 7, 3], atol=1e-12)


def test_units_radians_and_length(tmp_path):
    asf = ASF.replace("angle deg", "angle rad").replace("length 1.0", "length 0.5")
    asf = asf.replace("axis 0 0 90 XYZ", f"axis 0 0 {np.pi / 2!r} XYZ")
    amc = AMC.replace(":DEGREES\n", "").replace("arm 90", f"arm {np.pi / 2!r}")
    amc = amc.replace("root 1 2 3 0 0 90", f"root 1 2 3 0 0 {np.pi / 2!r}")
    amc = amc.replace("hand 90 90", f"hand {np.pi / 2!r} {np.pi / 2!r}")
    m = load_asf_amc(*write(tmp_path, asf, amc))
    ref = load_asf_amc(DATA / "tiny.asf", DATA / "tiny.amc")
    # length 0.5: one unit is 1/0.5 inch
    assert np.allclose(m.global_positions(), 2.0 * ref.global_positions(), atol=1e-12)


def test_amc_radians_header_overrides_asf_degrees(tmp_path):
    amc = AMC.replace(":DEGREES", ":RADIANS").replace("arm 90", f"arm {np.pi / 2!r}")
    amc = amc.replace("root 1 2 3 0 0 90", f"root 1 2 3 0 0 {np.pi / 2!r}")
    amc = amc.replace("hand 90 90", f"hand {np.pi / 2!r} {np.pi / 2!r}")
    m = load_asf_amc(*write(tmp_path, ASF, amc))
    ref = load_asf_amc(DATA / "tiny.asf", DATA / "tiny.amc")
    assert np.allclose(m.global_positions(), ref.global_positions(), atol=1e-12)


def test_root_order_and_position(tmp_path):
    asf = ASF.replace("order TX TY TZ RX RY RZ", "order RZ TY TX").replace("position 0 0 0", "position 0 0 7")
    amc = AMC.replace("root 0 0 0 0 0 0", "root 0 0 0").replace("root 1 2 3 0 0 90", "root 90 2 1")
    m = load_asf_amc(*write(tmp_path, asf, amc))
    # z has no translation dof: it takes the ASF position
    assert np.allclose(m.root_positions / INCH, [[0, 0, 7], [1, 2, 7]])
    assert np.allclose(m.global_positions()[1, 2] / INCH, [-9, 2, 7], atol=1e-12)


def test_explicit_scale_and_fps():
    m = load_asf_amc(DATA / "tiny.asf", DATA / "tiny.amc", scale=1.0, fps=30.0, name="t")
    assert m.fps == 30.0 and m.name == "t"
    assert np.allclose(m.global_positions()[1, 2], [-9, 2, 3])
    with pytest.raises(ValueError, match=r"Expected `fps` from 0.1 to 10000 frames per second, got 0"):
        load_asf_amc(DATA / "tiny.asf", DATA / "tiny.amc", fps=0)
    with pytest.raises(ValueError, match="Expected `scale` > 0"):
        load_asf_amc(DATA / "tiny.asf", DATA / "tiny.amc", scale=-1.0)


def test_missing_bones_keep_their_values_when_not_fully_specified(tmp_path):
    amc = AMC.replace(":FULLY-SPECIFIED\n", "").replace("arm 0\n", "")
    m = load_asf_amc(*write(tmp_path, ASF, amc))
    assert np.allclose(m.rotations[1, 2], m.rotations[0, 2])
    amc = AMC.replace(":FULLY-SPECIFIED\n", "").replace("arm 90\n", "")
    m = load_asf_amc(*write(tmp_path, ASF, amc))
    assert np.allclose(m.rotations[0, 2], [0, 0, 0, 1])


def test_comments_crlf_and_any_bone_order(tmp_path):
    amc = AMC.replace("arm 0\nhand 90 90", "hand 90 90\n# a comment\narm 0").replace("\n", "\r\n")
    m = load_asf_amc(*write(tmp_path, ASF.replace("\n", "\r\n"), amc))
    ref = load_asf_amc(DATA / "tiny.asf", DATA / "tiny.amc")
    assert np.allclose(m.global_positions(), ref.global_positions())


# ------------------------------------------------------------- CMU clips


@pytest.mark.parametrize("clip", ACCLAIM_CLIPS)
def test_agrees_with_cmu_bvh_within_1mm(mocap_dir, clip):
    entry = data.describe(clip)
    acclaim = load_asf_amc(mocap_dir / str(entry["asf"]), mocap_dir / str(entry["amc"]))
    bvh = load_bvh(mocap_dir / str(entry["bvh"]), scale=float(entry["scale"]))  # type: ignore[arg-type]
    # same joints in the same order, under the documented name map
    assert [CMU_BVH_NAMES[n] for n in acclaim.skeleton.names] == list(bvh.skeleton.names)
    assert acclaim.n_frames == bvh.n_frames == entry["frames"]
    err = np.abs(acclaim.global_positions() - bvh.global_positions()).max()
    assert err < 1e-3
    assert np.abs(acclaim.end_site_positions() - bvh.end_site_positions()).max() < 1e-3


# ---------------------------------------------------------- malformed ASF


def test_asf_empty(tmp_path):
    asf, amc = write(tmp_path, asf="")
    assert_error(asf, amc, asf, 1, "expected an ASF skeleton (':root', ':bonedata', ':hierarchy'), got an empty file")


def test_asf_missing_root(tmp_path):
    start, stop = line_of(ASF, ":root"), line_of(ASF, ":bonedata")
    rows = ASF.split("\n")
    text = "\n".join(rows[: start - 1] + rows[stop - 1 :])
    asf, amc = write(tmp_path, asf=text)
    assert_error(asf, amc, asf, last_line(text), "expected a ':root' section, got none")


def test_asf_missing_bonedata(tmp_path):
    rows = ASF.split("\n")
    text = "\n".join(rows[: line_of(ASF, ":bonedata") - 1] + [":hierarchy", "  begin", "  end", ""])
    asf, amc = write(tmp_path, asf=text)
    assert_error(asf, amc, asf, last_line(text), "expected a ':bonedata' section, got none")


def test_asf_missing_hierarchy(tmp_path):
    text = ASF[: ASF.index(":hierarchy")]
    asf, amc = write(tmp_path, asf=text)
    assert_error(asf, amc, asf, last_line(text), "expected a ':hierarchy' section, got none")


def test_asf_unknown_bone_in_hierarchy(tmp_path):
    text = ASF.replace("    arm hand", "    arm elbow")
    asf, amc = write(tmp_path, asf=text)
    assert_error(asf, amc, asf, line_of(text, "arm elbow"), "expected a bone defined in ':bonedata', got 'elbow'")


def test_asf_bone_not_in_hierarchy(tmp_path):
    text = ASF.replace("    arm hand\n", "")
    asf, amc = write(tmp_path, asf=text)
    line = line_of(text, "id 3") - 1
    assert_error(asf, amc, asf, line, "expected bone 'hand' attached to the hierarchy below 'root', got no path from the root")


def test_asf_bone_with_two_parents(tmp_path):
    text = ASF.replace("    arm hand", "    arm hand\n    hip hand")
    asf, amc = write(tmp_path, asf=text)
    assert_error(asf, amc, asf, line_of(text, "hip hand"), "expected one parent for bone 'hand', got 'arm' and 'hip'")


def test_asf_duplicate_bone(tmp_path):
    text = ASF.replace("name hand", "name arm")
    asf, amc = write(tmp_path, asf=text)
    line = line_of(text, "id 3") - 1
    assert_error(asf, amc, asf, line, "expected unique bone names (other than 'root'), got a second 'arm'")


def test_asf_non_numeric_and_non_finite(tmp_path):
    text = ASF.replace("length 5", "length five")
    asf, amc = write(tmp_path, asf=text)
    assert_error(asf, amc, asf, line_of(text, "length five"), "expected a number for the bone length, got 'five'")
    text = ASF.replace("direction 1 0 0\n     length 5", "direction 1 nan 0\n     length 5")
    asf, amc = write(tmp_path, asf=text)
    assert_error(asf, amc, asf, line_of(text, "1 nan 0"), "expected a finite number for the bone direction, got 'nan'")
    text = ASF.replace("direction 0 1 0", "direction 0 1")
    asf, amc = write(tmp_path, asf=text)
    assert_error(asf, amc, asf, line_of(text, "direction 0 1"), "expected 3 numbers for the bone direction, got 2")


def test_asf_unsupported_dof(tmp_path):
    text = ASF.replace("dof rx\n", "dof rx tx\n")
    asf, amc = write(tmp_path, asf=text)
    assert_error(
        asf,
        amc,
        asf,
        line_of(text, "dof rx tx"),
        "expected rotation dofs rx, ry, rz (bone translation and length dofs are not supported), got 'tx'",
    )


def test_asf_bad_units_and_root(tmp_path):
    text = ASF.replace("angle deg", "angle grad")
    asf, amc = write(tmp_path, asf=text)
    assert_error(asf, amc, asf, line_of(text, "angle grad"), "expected 'angle deg' or 'angle rad', got 'angle grad'")
    text = ASF.replace("order TX TY TZ RX RY RZ", "order TX TY TW")
    asf, amc = write(tmp_path, asf=text)
    assert_error(
        asf, amc, asf, line_of(text, "TW"), "expected root order entries from TX TY TZ RX RY RZ, each once, got 'TX TY TW'"
    )


def test_asf_truncated_in_a_bone(tmp_path):
    text = ASF[: ASF.index("  end\n  begin\n     id 3")]
    asf, amc = write(tmp_path, asf=text)
    begin = line_of(text, "id 2") - 1
    assert_error(asf, amc, asf, last_line(text), f"expected 'end' closing the bone beginning on line {begin}, got end of file")


def test_asf_truncated_in_the_hierarchy(tmp_path):
    text = ASF[: ASF.index("    arm hand")]
    asf, amc = write(tmp_path, asf=text)
    assert_error(asf, amc, asf, last_line(text), "expected 'end' closing the hierarchy, got end of file (truncated?)")


def test_asf_binary_garbage(tmp_path):
    asf, amc = write(tmp_path, asf=ASF.encode()[:200] + b"\x00\x00garbage")
    assert_error(asf, amc, asf, ASF[:200].count("\n") + 1, "expected text, got binary data (NUL byte)")


# ---------------------------------------------------------- malformed AMC


def test_amc_empty(tmp_path):
    asf, amc = write(tmp_path, amc="")
    assert_error(asf, amc, amc, 1, "expected AMC frames (a frame number, then one line per bone), got an empty file")
    asf, amc = write(tmp_path, amc=":FULLY-SPECIFIED\n:DEGREES\n")
    assert_error(asf, amc, amc, 2, "expected AMC frames (a frame number, then one line per bone), got end of file")


def test_amc_unknown_bone(tmp_path):
    text = AMC.replace("arm 0", "elbow 0")
    asf, amc = write(tmp_path, amc=text)
    assert_error(asf, amc, amc, line_of(text, "elbow"), "expected a bone of the ASF skeleton, got 'elbow'")


@pytest.mark.parametrize(("row", "count"), [("hand 90", 1), ("hand 90 90 90", 3)])
def test_amc_wrong_number_of_values(tmp_path, row, count):
    text = AMC.replace("hand 90 90", row)
    asf, amc = write(tmp_path, amc=text)
    assert_error(asf, amc, amc, line_of(text, row), f"expected 2 value(s) for bone 'hand', got {count}")


def test_amc_values_for_a_bone_without_dofs(tmp_path):
    text = AMC.replace("arm 0\n", "arm 0\nhip 5\n")
    asf, amc = write(tmp_path, amc=text)
    assert_error(asf, amc, amc, line_of(text, "hip 5"), "expected 0 value(s) for bone 'hip', got 1")


@pytest.mark.parametrize(("token", "message"), [("abc", "a number"), ("1_0", "a number"), ("nan", "a finite number"), ("-inf", "a finite number")])
def test_amc_bad_numbers(tmp_path, token, message):
    text = AMC.replace("root 1 2 3 0 0 90", f"root 1 2 {token} 0 0 90")
    asf, amc = write(tmp_path, amc=text)
    assert_error(asf, amc, amc, line_of(text, "root 1 2"), f"expected {message}, got {token!r}")


def test_amc_non_increasing_frame_numbers(tmp_path):
    text = AMC.replace("\n2\n", "\n1\n")
    asf, amc = write(tmp_path, amc=text)
    assert_error(asf, amc, amc, 8, "expected frame number 2, got 1")


def test_amc_missing_frame_number(tmp_path):
    text = AMC.replace("\n2\n", "\n3\n")
    asf, amc = write(tmp_path, amc=text)
    assert_error(asf, amc, amc, 8, "expected frame number 2, got 3")


def test_amc_bad_frame_number(tmp_path):
    text = AMC.replace("\n2\n", "\n2.0\n")
    asf, amc = write(tmp_path, amc=text)
    assert_error(asf, amc, amc, 8, "expected a frame number or a bone line, got '2.0'")


def test_amc_bone_before_first_frame(tmp_path):
    text = AMC.replace(":DEGREES\n1\n", ":DEGREES\n")
    asf, amc = write(tmp_path, amc=text)
    assert_error(asf, amc, amc, 4, "expected a frame number, got 'root 0 0 0 0 0 0'")


def test_amc_bone_twice_in_a_frame(tmp_path):
    text = AMC.replace("arm 0\n", "arm 0\narm 1\n")
    asf, amc = write(tmp_path, amc=text)
    assert_error(asf, amc, amc, line_of(text, "arm 1"), "expected bone 'arm' once in frame 2, got a second line")


def test_amc_truncated_frame(tmp_path):
    text = AMC[: AMC.index("hand 90 90")]
    asf, amc = write(tmp_path, amc=text)
    assert_error(
        asf, amc, amc, line_of(text, "arm 0"), "expected a line for bone 'hand' in frame 2 (the file is :FULLY-SPECIFIED), got none"
    )


def test_amc_binary_garbage(tmp_path):
    asf, amc = write(tmp_path, amc=AMC.encode() + b"\xc3\x28\xa0\xa1")
    line = AMC.count("\n") + 1
    with pytest.warns(UserWarning, match=rf"m.amc, line {line}: byte 0xc3 is not UTF-8"):
        assert_error(asf, amc, amc, line, "expected a bone of the ASF skeleton, got 'Ã('")


# ------------------------------------------ bounds and paths (issue 17)


@pytest.mark.parametrize("fps", [0, -1.0, 0.09, 10001.0, 1e5, 1e300, float("nan"), float("inf"), True, "120"])
def test_fps_outside_the_plausible_range(fps):
    with pytest.raises(ValueError) as info:
        load_asf_amc(DATA / "tiny.asf", DATA / "tiny.amc", fps=fps)
    assert str(info.value) == f"Expected `fps` from 0.1 to 10000 frames per second, got {fps!r}"


@pytest.mark.parametrize("fps", [0.1, 10000.0, 60])
def test_fps_range_is_inclusive(fps):
    assert load_asf_amc(DATA / "tiny.asf", DATA / "tiny.amc", fps=fps).fps == fps


@pytest.mark.parametrize("digits", [MAX_INTEGER_DIGITS + 1, 4301, 100_000])
@pytest.mark.parametrize("frame", [1, 2])
def test_amc_frame_numbers_are_bounded_before_conversion(tmp_path, digits, frame):
    line = 4 if frame == 1 else 8
    text = edit(AMC, line, "9" * digits)
    asf, amc = write(tmp_path, amc=text)
    assert_error(asf, amc, amc, line, f"expected a frame number of at most {MAX_INTEGER_DIGITS} digits, got {digits} digits")


@pytest.mark.parametrize("regular", [True, False], ids=["one-table reader", "line-by-line reader"])
def test_amc_root_overflow_is_blamed_on_the_amc_line(tmp_path, regular):
    text = AMC.replace("root 1 2 3 0 0 90", "root 1 1e308 3 0 0 90")
    if not regular:  # a comment sends the file to the line-by-line reader
        text = text.replace("\n2\n", "\n# comment\n2\n")
    asf, amc = write(tmp_path, amc=text)
    with pytest.raises(MocapFormatError) as info:
        load_asf_amc(asf, amc, scale=10.0)
    line = line_of(text, "1e308")
    assert str(info.value) == f"{amc}, line {line}: expected root translation values that stay finite in metres (scale 10), got an overflow"


def test_amc_root_overflow_kept_from_an_earlier_frame_names_that_line(tmp_path):
    # not fully specified: frame 2 has no root line and keeps frame 1's overflowing value
    text = AMC.replace(":FULLY-SPECIFIED\n", "").replace("root 0 0 0 0 0 0", "root 0 1e308 0 0 0 0")
    text = text.replace("root 1 2 3 0 0 90\n", "")
    asf, amc = write(tmp_path, amc=text)
    with pytest.raises(MocapFormatError) as info:
        load_asf_amc(asf, amc, scale=10.0)
    assert (info.value.path, info.value.line) == (str(amc), line_of(text, "1e308"))


def test_asf_length_overflow_is_blamed_on_the_bone(tmp_path):
    text = ASF.replace("length 5", "length 1e308")
    asf, amc = write(tmp_path, asf=text)
    with pytest.raises(MocapFormatError) as info:
        load_asf_amc(asf, amc, scale=10.0)
    begin = line_of(text, "id 2") - 1
    assert str(info.value) == (
        f"{asf}, line {begin}: expected bone 'arm' direction * length values that stay finite in metres (scale 10), "
        "got an overflow"
    )


def _symlink(link: Path, target: Path) -> Path:
    try:
        link.symlink_to(target)
    except (OSError, NotImplementedError):  # pragma: no cover - no symlinks on this system
        pytest.skip("symbolic links are not available")
    return link


def bad_paths(tmp_path: Path, ext: str) -> dict[str, tuple[Path, str]]:
    """Paths that cannot be read, each with the 'got' part of its error."""
    loop_a, loop_b = tmp_path / f"loop_a{ext}", tmp_path / f"loop_b{ext}"
    _symlink(loop_a, loop_b)
    _symlink(loop_b, loop_a)
    gone = tmp_path / f"gone{ext}"
    (tmp_path / "folder").mkdir()
    cases = {
        "missing": (tmp_path / f"missing{ext}", "no such file"),
        "dangling symlink": (_symlink(tmp_path / f"dangling{ext}", gone), f"a dangling symbolic link (to {str(gone)!r})"),
        "symlink loop": (loop_a, "a symbolic link loop"),
        "directory": (tmp_path / "folder", "a directory"),
    }
    if hasattr(os, "mkfifo"):
        os.mkfifo(tmp_path / f"pipe{ext}")
        cases["named pipe"] = (tmp_path / f"pipe{ext}", "not a regular file (a device, pipe or socket)")
    return cases


@pytest.mark.timeout(20)  # a named pipe must not block the reader
@pytest.mark.parametrize("which", ["asf", "amc"])
def test_every_path_problem_is_a_format_error_naming_the_path(tmp_path, which):
    what = {"asf": "an ASF file", "amc": "an AMC file"}[which]
    for case, (path, got) in bad_paths(tmp_path, "." + which).items():
        args = (path, DATA / "tiny.amc") if which == "asf" else (DATA / "tiny.asf", path)
        with pytest.raises(MocapFormatError) as info:
            load_asf_amc(*args)
        assert str(info.value) == f"{path}: expected {what}, got {got}", case
        assert (info.value.path, info.value.line) == (str(path), 0)
    with pytest.raises(MocapFormatError) as info:
        load_asf_amc(*(("", DATA / "tiny.amc") if which == "asf" else (DATA / "tiny.asf", "")))
    assert str(info.value) == f"'': expected a path to {what}, got an empty path"


def test_path_types():
    m = load_asf_amc(os.fsencode(DATA / "tiny.asf"), os.fsencode(DATA / "tiny.amc"))
    assert m.name == "tiny"
    with pytest.raises(TypeError, match="Expected `asf_path` to be a str or os.PathLike, got int"):
        load_asf_amc(3, DATA / "tiny.amc")  # type: ignore[arg-type]
    with pytest.raises(TypeError, match="Expected `amc_path` to be a str or os.PathLike, got NoneType"):
        load_asf_amc(DATA / "tiny.asf", None)  # type: ignore[arg-type]


def big_asf(n: int, *, chain: bool) -> str:
    """An ASF of ``n`` bones, each 0.01 inch long with three rotation dofs, as a chain or a star."""
    rows = [":version 1.10", ":name big", ":units", "  length 1.0", "  angle deg", ":root",
            "   order TX TY TZ RX RY RZ", "   axis XYZ", "   position 0 0 0", "   orientation 0 0 0", ":bonedata"]
    for i in range(n):
        rows += ["  begin", f"     id {i + 1}", f"     name b{i}", "     direction 0 1 0", "     length 0.01",
                 "     axis 0 0 45 XYZ", "    dof rx ry rz", "    limits (-180.0 180.0)", "  end"]
    rows += [":hierarchy", "  begin"]
    if chain:
        rows += ["    root b0"] + [f"    b{i} b{i + 1}" for i in range(n - 1)]
    else:
        rows += ["    root " + " ".join(f"b{i}" for i in range(n))]
    return "\n".join(rows + ["  end", ""])


@pytest.mark.parametrize("chain", [True, False], ids=["chain", "star"])
def test_twenty_thousand_bones_parse_in_linear_time(tmp_path, chain):
    """The bone-to-root check once rebuilt a set per bone: 17 s for 20,000 bones.

    Checked by how the work grows, not by a clock bound (which fails on a
    busy machine): four times the bones must cost well under 16 times the CPU
    (a quadratic reader), the best of three runs each; linear is about 4.
    """
    n = 20_000

    def cpu(bones: int) -> float:
        path = tmp_path / f"b{bones}.asf"
        path.write_text(big_asf(bones, chain=chain))
        best = float("inf")
        for _ in range(3):
            start = time.process_time()
            parse_asf(path)
            best = min(best, time.process_time() - start)
        return best

    growth = cpu(n) / max(cpu(n // 4), 1e-3)
    assert growth < 9.0, f"parse_asf took {growth:.1f} times the CPU for four times the bones (quadratic: 16)"
    asf = tmp_path / "big.asf"
    asf.write_text(big_asf(n, chain=chain))
    parsed = parse_asf(asf)
    assert len(parsed.order) == n + 1 and parsed.parents[1] == 0
    assert parsed.parents[-1] == (n - 1 if chain else 0)
    amc = tmp_path / "big.amc"
    amc.write_text(":DEGREES\n1\nroot 0 0 0 0 0 0\n")  # not fully specified: the bones stay at zero
    m = load_asf_amc(asf, amc)
    assert m.n_joints == n + 1 and m.n_frames == 1
    # a child starts where its parent bone ends, 0.01 inch up; bones of the root start at the root
    up = np.array([0.0, 0.01 * INCH, 0.0])
    assert np.allclose(m.skeleton.offsets[2:], up if chain else 0.0, rtol=0, atol=1e-15)
    assert len(m.skeleton.end_site_parents) == (1 if chain else n)
