"""Every lesson also runs in full mode, as a student runs it (``jupyter lab lessons/``).

The default test run executes the lessons with nbval under ``MOCAPLAB_FAST=1``
(set by ``conftest.py``), which shrinks clips and iteration counts.  Students
run them without it, so each lesson is executed here once more, in a fresh
kernel with ``MOCAPLAB_FAST=0``: every cell must run and every assert must
hold on the full-size data too, and no cell may show a warning its lesson does
not teach (``lesson_warnings.py``).
"""

from __future__ import annotations

import os
from pathlib import Path

import nbformat
import pytest
from lesson_warnings import check_cell
from nbclient import NotebookClient

LESSONS = sorted((Path(__file__).resolve().parent.parent / "lessons").glob("*.ipynb"))


@pytest.mark.parametrize("path", LESSONS, ids=[p.name for p in LESSONS])
def test_lesson_runs_in_full_mode(path: Path) -> None:
    nb = nbformat.read(path, as_version=4)
    # a last cell reports the mode the kernel ran in (lessons that do not shrink anything have no FAST flag)
    nb.cells.append(nbformat.v4.new_code_cell("import os\nprint('FAST =', os.environ.get('MOCAPLAB_FAST') == '1')"))
    client = NotebookClient(nb, timeout=600, kernel_name="python3", resources={"metadata": {"path": str(path.parent)}})
    client.execute(env=dict(os.environ, MOCAPLAB_FAST="0"))
    shown = "".join(o.get("text", "") for o in nb.cells[-1].outputs)
    assert shown.strip() == "FAST = False", shown
    for k, cell in enumerate(nb.cells):
        check_cell(path.name, f"cell {k}", cell.get("outputs", []))
