"""A student's working copy of the lessons (``python -m mocaplab.lessons copy``).

The course's copy is a small hand-made lessons folder (or, once, the real
``lessons/``); a course update is simulated by changing it as ``git pull``
would: a lesson changed, a lesson added.
"""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest

from mocaplab import lessons

ROOT = Path(__file__).resolve().parents[1]


def notebook(text: str) -> str:
    return json.dumps({"cells": [{"cell_type": "code", "source": text}], "nbformat": 4, "nbformat_minor": 5})


@pytest.fixture
def course(tmp_path: Path) -> Path:
    folder = tmp_path / "course" / "lessons"
    folder.mkdir(parents=True)
    (folder / "00_glossary.md").write_text("# Glossary\n")
    (folder / "01_a.ipynb").write_text(notebook("a = 1"))
    (folder / "02_b.ipynb").write_text(notebook("b = 2"))
    (folder / "conftest.py").write_text("# the test suite's, not the student's\n")
    return folder


def snapshot(folder: Path) -> dict[str, bytes]:
    return {str(p.relative_to(folder)): p.read_bytes() for p in sorted(folder.rglob("*")) if p.is_file()}


def test_a_first_copy_has_the_notebooks_and_the_glossary(course, tmp_path):
    before = snapshot(course)
    done = lessons.copy_lessons(tmp_path / "mine", source=course)
    assert done.added == ["00_glossary.md", "01_a.ipynb", "02_b.ipynb"]
    assert done.updated == done.kept == done.replaced == done.unchanged == []
    mine = snapshot(tmp_path / "mine")
    assert sorted(mine) == [".mocaplab-lessons.json", "00_glossary.md", "01_a.ipynb", "02_b.ipynb"]
    assert all(mine[name] == before[name] for name in done.added)
    assert snapshot(course) == before  # the course's copy is only read


def test_a_students_run_does_not_touch_the_course_copy(course, tmp_path):
    before = snapshot(course)
    lessons.copy_lessons(tmp_path / "mine", source=course)
    (tmp_path / "mine" / "01_a.ipynb").write_text(notebook("a = 1  # with my outputs"))
    assert snapshot(course) == before


def test_an_update_adds_new_lessons_updates_untouched_ones_and_keeps_changed_ones(course, tmp_path):
    mine = tmp_path / "mine"
    lessons.copy_lessons(mine, source=course)
    answer = notebook("a = 1\nmy_answer = 42")
    (mine / "01_a.ipynb").write_text(answer)  # the student works in 01
    # the course updates (git pull): both lessons change, a new one and a new glossary entry arrive
    (course / "01_a.ipynb").write_text(notebook("a = 1.0"))
    (course / "02_b.ipynb").write_text(notebook("b = 2.0"))
    (course / "03_c.ipynb").write_text(notebook("c = 3"))
    (course / "00_glossary.md").write_text("# Glossary\n\nc: the third letter\n")
    done = lessons.copy_lessons(mine, source=course)
    assert done.added == ["03_c.ipynb"]
    assert done.updated == ["00_glossary.md", "02_b.ipynb"]
    assert done.kept == ["01_a.ipynb"] and done.replaced == [] and done.unchanged == []
    assert (mine / "01_a.ipynb").read_text() == answer  # the student's work is not lost
    for name in ("02_b.ipynb", "03_c.ipynb", "00_glossary.md"):
        assert (mine / name).read_bytes() == (course / name).read_bytes()
    # again: nothing to do, the changed lesson is still kept
    again = lessons.copy_lessons(mine, source=course)
    assert again.kept == ["01_a.ipynb"] and again.added == again.updated == []
    assert again.unchanged == ["00_glossary.md", "02_b.ipynb", "03_c.ipynb"]
    # --force replaces it
    forced = lessons.copy_lessons(mine, source=course, force=True)
    assert forced.replaced == ["01_a.ipynb"] and forced.kept == []
    assert (mine / "01_a.ipynb").read_bytes() == (course / "01_a.ipynb").read_bytes()
    # once replaced it counts as untouched: the next course change updates it
    (course / "01_a.ipynb").write_text(notebook("a = 1.5"))
    assert lessons.copy_lessons(mine, source=course).updated == ["01_a.ipynb"]


def test_a_lesson_copied_by_hand_and_changed_is_kept(course, tmp_path):
    """Without a record of what was copied, a lesson that differs from the course's counts as the student's."""
    mine = tmp_path / "mine"
    mine.mkdir()
    (mine / "01_a.ipynb").write_text(notebook("a = 'mine'"))
    done = lessons.copy_lessons(mine, source=course)
    assert done.kept == ["01_a.ipynb"] and done.added == ["00_glossary.md", "02_b.ipynb"]
    assert (mine / "01_a.ipynb").read_text() == notebook("a = 'mine'")


def test_a_deleted_lesson_comes_back(course, tmp_path):
    mine = tmp_path / "mine"
    lessons.copy_lessons(mine, source=course)
    (mine / "02_b.ipynb").unlink()
    assert lessons.copy_lessons(mine, source=course).added == ["02_b.ipynb"]


def test_bad_folders_are_named(course, tmp_path):
    with pytest.raises(ValueError, match="another folder than the course's lessons"):
        lessons.copy_lessons(course, source=course)
    with pytest.raises(FileNotFoundError, match=r"empty: expected the course's lessons folder"):
        (tmp_path / "empty").mkdir()
        lessons.copy_lessons(tmp_path / "mine", source=tmp_path / "empty")
    mine = tmp_path / "mine"
    lessons.copy_lessons(mine, source=course)
    (mine / lessons.MANIFEST).write_text("{not json")
    with pytest.raises(ValueError, match=r"\.mocaplab-lessons\.json: expected the JSON record"):
        lessons.copy_lessons(mine, source=course)


def test_the_command_copies_the_real_lessons_and_refuses_to_overwrite(tmp_path):
    """``python -m mocaplab.lessons copy DEST`` with the repository's lessons/ as the course's copy."""
    dest = tmp_path / "student"

    def run(*args: str) -> subprocess.CompletedProcess[str]:
        return subprocess.run(
            [sys.executable, "-m", "mocaplab.lessons", "copy", str(dest), *args], capture_output=True, text=True
        )

    first = run()
    assert first.returncode == 0, first.stderr
    course = sorted(p.name for p in (ROOT / "lessons").glob("*.ipynb")) + ["00_glossary.md"]
    assert sorted(p.name for p in dest.iterdir() if not p.name.startswith(".")) == sorted(course)
    assert f"{len(course)} added" in first.stdout
    lesson = dest / "01_motion_data.ipynb"
    lesson.write_text(lesson.read_text().replace("forward kinematics", "FK", 1))
    second = run()
    assert second.returncode == 0
    assert "kept: 01_motion_data.ipynb (you changed it; --force replaces it" in second.stdout
    assert lesson.read_bytes() != (ROOT / "lessons" / lesson.name).read_bytes()
    third = run("--force")
    assert "replaced: 01_motion_data.ipynb" in third.stdout
    assert lesson.read_bytes() == (ROOT / "lessons" / lesson.name).read_bytes()
    missing = run("--from", str(tmp_path / "nowhere"))
    assert missing.returncode == 2 and "nowhere: expected the course's lessons folder" in missing.stderr
