"""The check that lessons show only the warnings they teach (``lesson_warnings.py``) reads what a kernel prints."""

from __future__ import annotations

import warnings
from pathlib import Path

import pytest
from lesson_warnings import TAUGHT, check_cell, shown_warnings, untaught

from mocaplab.ik import UnreachableTargetWarning

LESSONS = Path(__file__).resolve().parent.parent / "lessons"


def printed(message: str, category: type[Warning]) -> str:
    """A warning as the kernel prints it under a cell (``warnings.showwarning``'s text, then the source line)."""
    return warnings.formatwarning(message, category, "/tmp/ipykernel_7/123.py", 4, "back = load(path)")


def test_the_printed_warnings_are_found_with_their_category():
    text = "some output\n" + printed("BVH has no unit; assuming centimetres", UserWarning)
    text += printed("target of 'LeftFoot' out of reach on frames 0-9", UnreachableTargetWarning)
    assert shown_warnings(text) == [
        ("UserWarning", "BVH has no unit; assuming centimetres"),
        ("UnreachableTargetWarning", "target of 'LeftFoot' out of reach on frames 0-9"),
    ]
    assert shown_warnings("a plain line: no warning\n") == []


def test_only_the_lessons_taught_warnings_pass():
    reach = printed("target of 'LeftFoot' out of reach on frames 0-470", UnreachableTargetWarning)
    unit = printed("walk.bvh: BVH has no unit; assuming centimetres", UserWarning)
    assert untaught("06_full_body_refinement.ipynb", reach) == []
    assert untaught("03_laplacian_path_editing.ipynb", reach) == [
        "UnreachableTargetWarning: target of 'LeftFoot' out of reach on frames 0-470"
    ], "taught in lesson 06 only"
    with pytest.raises(AssertionError, match="09_touch_up_ground.ipynb Cell 23 shows a warning it does not teach"):
        check_cell("09_touch_up_ground.ipynb", "Cell 23", [{"output_type": "stream", "name": "stderr", "text": unit}])
    check_cell("09_touch_up_ground.ipynb", "Cell 23", [{"output_type": "stream", "name": "stdout", "text": unit}])


def test_every_taught_warning_names_a_lesson_and_a_reason():
    for lesson, entries in TAUGHT.items():
        assert (LESSONS / lesson).is_file(), lesson
        assert entries and all(reason.strip() for reason in entries.values()), lesson
