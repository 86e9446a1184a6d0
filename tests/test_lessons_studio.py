"""Every lesson runs on a studio file with a static root above the pelvis, and gives its answers there (issue #28).

A student's own capture often comes from a studio's exporter: a static
reference joint at the origin above the travelling pelvis, position channels
on every joint.  Lesson code that takes "the path" from joint 0
(``root_positions``), counts one control variable per joint plus one, or
hands forward kinematics the root alone is silently wrong on such a file.
Here each lesson runs in a fresh kernel (fast mode) after one added first
cell, :data:`conventions.STUDIO_CELL`: every ``mocaplab.cmu`` clip is written
below a static ``joint_Root`` and read back with ``mocaplab.load``, as a
student reads their file.  Every cell must run, every assert must hold, and
no cell may show a warning but those its lesson teaches
(``lesson_warnings.py``) and the file's own announcement of its path joint
(a :class:`~mocaplab.editing.PinPlacementWarning`, a pin far from the path,
fails).  Lesson 14 is itself about such a file and runs as it is.

``tests/test_browser_laptop.py`` runs lessons 01, 03, 10, 13 and 15 this way
in Chromium, for what a student sees; this test is the headless check of
every lesson's answers.
"""

from __future__ import annotations

import os
from pathlib import Path

import nbformat
import pytest
from conventions import STUDIO_CELL
from lesson_warnings import TAUGHT, stderr_text, untaught
from nbclient import NotebookClient
from nbclient.exceptions import CellExecutionError

LESSONS = sorted(
    p for p in (Path(__file__).resolve().parent.parent / "lessons").glob("[0-9][0-9]_*.ipynb") if p.name[:2] != "14"
)

#: Each new reading of a studio file names its path joint once (mocaplab.Motion.path_joint).
PATH_JOINT = ("UserWarning", "The motion path follows joint 'Hips' (index 1), not joint 0")


@pytest.mark.parametrize("path", LESSONS, ids=[p.name[:2] for p in LESSONS])
def test_lesson_runs_on_a_studio_file(path: Path) -> None:
    nb = nbformat.read(path, as_version=4)
    nb.cells.insert(0, nbformat.v4.new_code_cell(STUDIO_CELL))
    client = NotebookClient(nb, timeout=600, kernel_name="python3", resources={"metadata": {"path": str(path.parent)}})
    failed = None
    try:
        client.execute(env=dict(os.environ, MOCAPLAB_FAST="1"))
    except CellExecutionError as exc:
        failed = str(exc)
    if failed is not None:
        pytest.fail(f"{path.name} on studio files: {failed}", pytrace=False)
    taught = {path.name: {**TAUGHT.get(path.name, {}), PATH_JOINT: "a studio file's static root"}}
    shown = {k: untaught(path.name, stderr_text(cell.get("outputs", [])), taught) for k, cell in enumerate(nb.cells)}
    shown = {k: found for k, found in shown.items() if found}
    assert not shown, f"{path.name} on studio files shows warnings it does not teach (cell: warnings): {shown}"
