"""Issue 27, items 4 and 5: frozen data, bounded reading, names, overflow, escaping, options.

Each test fails on the defect it names (checked by reverting the fix once).
"""

from __future__ import annotations

import os
import subprocess
import sys
import tracemalloc

import numpy as np
import pytest

import mocaplab as ml
from mocaplab.io import MocapFormatError, load_bvh, save_bvh
from mocaplab.motion import Motion, Skeleton, readonly


# --------------------------------------------------------------- frozen arrays
def _assert_frozen_for_good(arr: np.ndarray, what: str) -> None:
    """Neither ``arr`` nor any array reachable through ``.base`` can be made writeable."""
    x, depth = arr, 0
    while isinstance(x, np.ndarray):
        assert not x.flags.writeable, f"{what}{'.base' * depth} is writeable"
        with pytest.raises(ValueError):
            x.flags.writeable = True
        x, depth = x.base, depth + 1


def test_the_check_catches_an_owner_left_writeable():
    owner = np.zeros(3)
    owner.flags.writeable = False  # what motion.readonly did before: the owner could be switched back
    view = owner.view()
    view.flags.writeable = False
    with pytest.raises(pytest.fail.Exception, match="DID NOT RAISE"):
        _assert_frozen_for_good(view, "view")


def _tiny(frames: int = 4) -> Motion:
    sk = Skeleton(["hips", "knee", "ankle"], [-1, 0, 1], [[0, 1, 0], [0, -0.5, 0], [0, -0.5, 0]],
                  end_site_parents=[2], end_site_offsets=[[0, 0, 0.1]])
    rot = np.tile([0.0, 0.0, 0.0, 1.0], (frames, 3, 1))
    return Motion(sk, rot, np.zeros((frames, 3)), 30.0, translations=np.zeros((frames, 3, 3)) + sk.offsets)


def test_motion_and_skeleton_arrays_are_frozen_for_good(mocap_dir):
    for motion in (_tiny(), load_bvh(mocap_dir / "bvh" / "16_15.bvh", scale=0.0254 / 0.45)):
        sk = motion.skeleton
        arrays = {
            "rotations": motion.rotations, "root_positions": motion.root_positions,
            "global_positions": motion.global_positions(), "global_rotations": motion.global_rotations(),
            "parents": sk.parents, "offsets": sk.offsets, "end_site_parents": sk.end_site_parents,
            "end_site_offsets": sk.end_site_offsets,
        }
        if motion.translations is not None:
            arrays["translations"] = motion.translations
        for what, arr in arrays.items():
            _assert_frozen_for_good(arr, what)
        # an edit shares the frozen arrays it keeps instead of copying them
        assert np.shares_memory(motion.replace(name="x").rotations, motion.rotations)


def test_readonly_leaves_its_input_alone_and_copies_once():
    mine = np.arange(6.0)
    frozen = readonly(mine)
    assert mine.flags.writeable  # the caller's array stays theirs
    mine[0] = 99.0
    assert frozen[0] == 0.0
    _assert_frozen_for_good(frozen, "readonly(...)")
    again = readonly(frozen[1:])
    assert np.shares_memory(again, frozen)  # frozen already: no second copy


def test_balance_arrays_are_frozen_for_good(cmu):
    from mocaplab.physics import balance

    bal = balance(cmu("16_15")[:60])
    for name in ("zmp", "com", "support", "positions"):
        _assert_frozen_for_good(getattr(bal, name), name)


def test_staggered_times_and_refinements_are_frozen_for_good(cmu):
    from mocaplab.staggered import extract

    sm = extract(cmu("16_15")[:90], max_poses=6)
    _assert_frozen_for_good(sm.times, "times")
    _assert_frozen_for_good(sm.refinements, "refinements")


# ------------------------------------------------------------ reader memory
def _short_row_bvh(path, rows: int, joints: int = 3, newline: str = "\n") -> None:
    """A BVH file whose numbers are single digits: the most values per byte, the worst case for memory."""
    head = ["HIERARCHY", "ROOT Hips", "{", "OFFSET 0 0 0", "CHANNELS 6 Xposition Yposition Zposition Zrotation Yrotation Xrotation"]
    for j in range(1, joints):
        head += [f"JOINT J{j}", "{", "OFFSET 0 -5 0", "CHANNELS 3 Zrotation Yrotation Xrotation"]
    head += ["End Site", "{", "OFFSET 0 -1 0", "}"] + ["}"] * joints
    channels = 6 + 3 * (joints - 1)
    row = " ".join(str(k % 10) for k in range(channels))
    head += ["MOTION", f"Frames: {rows}", "Frame Time: 0.008333"]
    with open(path, "w", newline="") as f:
        f.write(newline.join(head) + newline)
        f.write((row + newline) * rows)


#: Peak memory of reading a BVH file, in multiples of the file's size (the
#: result alone is up to 5.3 times the file for one-digit numbers).
READ_MEMORY_BOUND = 8.0


@pytest.mark.parametrize(("joints", "newline"), [(1, "\n"), (3, "\r\n"), (31, "\n")])
def test_reading_a_bvh_file_peaks_within_a_bounded_multiple_of_its_size(tmp_path, joints, newline):
    path = tmp_path / "big.bvh"
    _short_row_bvh(path, rows=3_000_000 // (6 * joints + 6), joints=joints, newline=newline)
    size = path.stat().st_size
    tracemalloc.start()
    try:
        motion = load_bvh(path, scale=0.01)
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert motion.n_frames == 3_000_000 // (6 * joints + 6)
    assert peak < READ_MEMORY_BOUND * size, f"peak {peak / size:.1f} x the file size"


def test_reading_in_blocks_gives_the_values_of_the_file(tmp_path, monkeypatch):
    from mocaplab.io import bvh

    path = tmp_path / "rows.bvh"
    _short_row_bvh(path, rows=500, joints=3)
    whole = load_bvh(path, scale=0.01)
    monkeypatch.setattr(bvh, "ROW_BLOCK_CHARS", 37)  # blocks of a row or two
    blocks = load_bvh(path, scale=0.01)
    np.testing.assert_array_equal(whole.rotations, blocks.rotations)
    np.testing.assert_array_equal(whole.root_positions, blocks.root_positions)
    # errors still name the line: a bad token in row 321, and a truncated file
    lines = path.read_text().split("\n")
    first_row = lines.index("Frame Time: 0.008333") + 2
    bad = list(lines)
    bad[first_row + 320 - 1] = bad[first_row + 320 - 1].replace("7", "x", 1)
    path.write_text("\n".join(bad))
    with pytest.raises(MocapFormatError, match=rf"line {first_row + 320}: expected a number, got 'x'"):
        load_bvh(path, scale=0.01)
    path.write_text("\n".join(lines[: first_row + 100]))
    with pytest.raises(MocapFormatError, match=r"expected 500 frame row\(s\).*got 101 \(truncated"):
        load_bvh(path, scale=0.01)


# ---------------------------------------------------------- overflow in FK
_CHAIN = """HIERARCHY
ROOT a
{{
OFFSET 0 0 0
CHANNELS 6 Xposition Yposition Zposition Zrotation Yrotation Xrotation
JOINT b
{{
OFFSET 0 {o} 0
CHANNELS 3 Zrotation Yrotation Xrotation
JOINT c
{{
OFFSET 0 {o} 0
CHANNELS 3 Zrotation Yrotation Xrotation
End Site
{{
OFFSET 0 {o} 0
}}
}}
}}
}}
MOTION
Frames: 2
Frame Time: 0.01
0 {r} 0 0 0 0 0 0 0 0 0 0
0 0 0 0 0 0 0 0 0 0 0 0
"""


def test_forward_kinematics_overflow_is_refused_at_load_naming_the_file(tmp_path):
    path = tmp_path / "far.bvh"
    path.write_text(_CHAIN.format(o="1.7e308", r="0"))
    with pytest.raises(MocapFormatError, match=r"far\.bvh: expected joint positions that stay finite.*joint 'c'"):
        load_bvh(path, scale=1.0)
    path.write_text(_CHAIN.format(o="1e307", r="1.7e308"))  # the root alone is finite, its child is not
    with pytest.raises(MocapFormatError, match=r"far\.bvh.*overflow at frame 0"):
        load_bvh(path, scale=1.0)
    path.write_text(_CHAIN.format(o="1e300", r="1e300"))  # large but finite all the way: read
    assert np.isfinite(load_bvh(path, scale=1.0).global_positions()).all()


# ------------------------------------------------------------------ names
_NAMED = """HIERARCHY
ROOT hips
{{
OFFSET 0 0 0
CHANNELS 6 Xposition Yposition Zposition Zrotation Yrotation Xrotation
JOINT {name}
{{
OFFSET 0 -1 0
CHANNELS 3 Zrotation Yrotation Xrotation
End Site
{{
OFFSET 0 -1 0
}}
}}
}}
MOTION
Frames: 1
Frame Time: 0.01
0 0 0 0 0 0 0 0 0
"""


@pytest.mark.parametrize(
    ("name", "why"),
    [
        ("Site", "its word 'Site' is a BVH keyword"),
        ("left Site", "its word 'Site' is a BVH keyword"),
        ("a\x01b", "control character '\\\\x01'"),
        ("a\x1fb", "control character '\\\\x1f'"),  # str.split splits there: it used to read as 'a b'
        ("a\u00a0b", "whitespace other than a space"),
        ("a\u2003b", "whitespace other than a space"),
        ("two  spaces", "repeated whitespace"),
    ],
)
def test_reader_refuses_the_names_the_writer_refuses(tmp_path, name, why):
    path = tmp_path / "n.bvh"
    path.write_text(_NAMED.format(name=name), encoding="utf-8")
    with pytest.raises(MocapFormatError, match=rf"n\.bvh, line 6: expected a joint name .*{why}"):
        load_bvh(path, scale=0.01)


@pytest.mark.parametrize("name", ["LeftUpLeg", "left knee", "Bein_links", "épaule gauche", "脚 左"])
def test_names_are_kept_as_written_and_written_back(tmp_path, name):
    path = tmp_path / "n.bvh"
    path.write_text(_NAMED.format(name=name), encoding="utf-8")
    motion = load_bvh(path, scale=0.01)
    assert motion.skeleton.names[1] == name
    save_bvh(motion, tmp_path / "back.bvh", scale=0.01)
    assert load_bvh(tmp_path / "back.bvh", scale=0.01).skeleton.names == motion.skeleton.names


# -------------------------------------------------------------- ASF / AMC
def _tiny_acclaim(tmp_path, asf_text=None, amc_text=None):
    data = os.path.join(os.path.dirname(__file__), "data")
    asf = tmp_path / "tiny.asf"
    amc = tmp_path / "tiny.amc"
    asf.write_text(asf_text if asf_text is not None else open(os.path.join(data, "tiny.asf")).read())
    amc.write_text(amc_text if amc_text is not None else open(os.path.join(data, "tiny.amc")).read())
    return asf, amc


def test_amc_line_naming_nan_instead_of_its_bone_is_refused_at_its_line(tmp_path):
    from mocaplab.io import load_asf_amc

    asf, amc = _tiny_acclaim(tmp_path)
    good = load_asf_amc(asf, amc)
    lines = amc.read_text().split("\n")
    at = lines.index("arm 0")  # frame 2's arm line
    lines[at] = "nan 0"
    amc.write_text("\n".join(lines))
    with pytest.raises(MocapFormatError, match=rf"tiny\.amc, line {at + 1}: .*'nan'"):
        load_asf_amc(asf, amc)
    assert good.n_frames == 2


def test_asf_length_unit_that_overflows_is_blamed_on_the_asf(tmp_path):
    from mocaplab.io import load_asf_amc

    data = open(os.path.join(os.path.dirname(__file__), "data", "tiny.asf")).read()
    asf, amc = _tiny_acclaim(tmp_path, asf_text=data.replace("  length 1.0\n", "  length 1e-310\n"))
    line = data.split("\n").index("  length 1.0") + 1
    with pytest.raises(MocapFormatError, match=rf"tiny\.asf, line {line}: expected a length unit whose scale"):
        load_asf_amc(asf, amc)


# ---------------------------------------------------------------- options
def test_motion_fps_must_be_a_number_not_a_string_or_bool():
    m = _tiny()
    for bad in ("30", b"30", True, None):
        with pytest.raises(ValueError, match=r"Expected `fps` to be a number of frames per second"):
            Motion(m.skeleton, m.rotations, m.root_positions, bad)
    assert Motion(m.skeleton, m.rotations, m.root_positions, np.int32(30)).fps == 30.0


@pytest.mark.parametrize("bad", [True, False, "0.01", float("nan"), float("inf"), 0, -1.0, [0.01]])
def test_load_scale_is_checked_before_reading(tmp_path, bad):
    path = tmp_path / "n.bvh"
    path.write_text(_NAMED.format(name="knee"))
    for reader in (ml.load, load_bvh):
        with pytest.raises(ValueError, match=r"Expected `scale` > 0 \(metres per file unit\), got"):
            reader(path, scale=bad)


def test_save_bvh_names_what_it_was_given_instead_of_a_motion(tmp_path):
    class EditResult:  # what edit() returns: motions, not a motion
        motions = (_tiny(),)

    with pytest.raises(TypeError, match=r"Expected `motion` to be a Motion, got EditResult \(pass one of its `motions`"):
        save_bvh(EditResult(), tmp_path / "x.bvh")
    with pytest.raises(TypeError, match=r"Expected `motion` to be a Motion, got list$"):
        save_bvh([_tiny()], tmp_path / "x.bvh")
    assert not (tmp_path / "x.bvh").exists()


# ------------------------------------------------- text from data in figures
MATH = "$\\foo$"  # an unknown mathtext symbol: drawing it raises unless the '$' are escaped


def _draw(fig) -> None:
    fig.canvas.draw()


@pytest.fixture(scope="module")
def dollar_walk(cmu):
    import dataclasses

    walk = cmu("16_15")[:40]
    names = tuple(MATH if n == "Head" else n for n in walk.skeleton.names)
    return walk.replace(skeleton=dataclasses.replace(walk.skeleton, names=names), name=MATH)


def test_plot_functions_draw_names_with_dollar_signs_as_written(dollar_walk):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from mocaplab import plot
    from mocaplab.contacts import Contacts

    try:
        axes = [
            plot.skeleton(dollar_walk, 0, projection="front"),
            plot.root_path(dollar_walk),
            plot.joint_curves(dollar_walk, [MATH]),
            plot.contact_timeline(Contacts((MATH,), np.zeros((40, 1), dtype=bool), 30.0)),
            plot.time_warps([np.arange(40) / 30.0], [MATH], h=1 / 30, title=MATH)[0],
        ]
        for ax in axes:
            _draw(ax.figure)
        shown = [t.get_text() for ax in axes for t in ax.figure.findobj(matplotlib.text.Text)]
        assert any(MATH.replace("$", "\\$") in t for t in shown)
    finally:
        plt.close("all")
    assert plot.literal(MATH) == "\\$\\foo\\$"


def test_time_track_editor_draws_labels_with_dollar_signs(cmu):
    from mocaplab.widgets.time_track import TimeTrackEditor

    from mocaplab.editing import SceneEditor

    walk = cmu("16_15").resample(30)[:60]
    tt = TimeTrackEditor(SceneEditor([walk], []), labels=[MATH], title=MATH)
    _draw(tt.figure)


# ------------------------------------------------------ widget error display
class _Unprintable(Exception):
    def __str__(self):
        raise RuntimeError("the message itself fails")


def test_error_display_cannot_fail():
    from mocaplab.widgets._controls import error_html

    for err in (_Unprintable("x"), ValueError("<b>'quoted'</b>"), KeyError(None)):
        shown = error_html(err, trace=True)
        assert shown.startswith("<pre") and type(err).__name__ in shown
    assert "&lt;b&gt;" in error_html(ValueError("<b>"))  # escaped


def test_touch_up_widget_shows_an_error_whose_message_fails(cmu):
    from mocaplab.widgets.touchup import TouchUpStepper

    widget = TouchUpStepper(cmu("16_15").resample(30)[:45])

    def boom():
        raise _Unprintable("x")

    widget._guard(boom)  # must not raise
    assert "_Unprintable" in widget.status.value


def test_widgets_are_reachable_from_a_plain_import_lazily():
    script = (
        "import sys, mocaplab as ml\n"
        "assert 'ipywidgets' not in sys.modules and 'mocaplab.widgets' not in sys.modules\n"
        "assert 'widgets' in dir(ml)\n"
        "assert ml.widgets.__name__ == 'mocaplab.widgets'\n"
        "print('ok')\n"
    )
    out = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, timeout=300)
    assert out.returncode == 0 and out.stdout.strip() == "ok", out.stderr


def test_an_unusable_data_dir_is_a_data_error_naming_the_variable(monkeypatch, tmp_path):
    from mocaplab import data

    monkeypatch.setenv("MOCAPLAB_DATA_DIR", str(tmp_path / ("a" * 5000)))
    with pytest.raises(data.DataError, match=r"MOCAPLAB_DATA_DIR=.*\(5\d{3} characters\) is set but that folder cannot be used"):
        data.cmu("16_15")
