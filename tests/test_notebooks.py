"""Every committed lesson is a clean nbformat v4 notebook that asserts something."""

from __future__ import annotations

import ast
from pathlib import Path

import nbformat
import pytest

LESSONS = sorted((Path(__file__).resolve().parent.parent / "lessons").glob("*.ipynb"))


def test_there_are_lessons():
    assert LESSONS, "no lessons/*.ipynb found"
    assert any(p.name.startswith("01_") for p in LESSONS)


@pytest.fixture(params=LESSONS, ids=[p.name for p in LESSONS])
def notebook(request):
    path = request.param
    return path, nbformat.read(path, as_version=nbformat.NO_CONVERT)


def test_valid_nbformat_v4(notebook):
    path, nb = notebook
    assert nb.nbformat == 4, f"{path.name}: nbformat {nb.nbformat}, expected 4"
    nbformat.validate(nb)
    assert path.name[:2].isdigit() and path.name[2] == "_", f"{path.name}: expected NN_topic.ipynb"


def test_committed_without_outputs(notebook):
    path, nb = notebook
    dirty = [
        k
        for k, cell in enumerate(nb.cells)
        if cell.cell_type == "code" and (cell.get("outputs") or cell.get("execution_count") is not None)
    ]
    assert not dirty, f"{path.name}: cells {dirty} carry outputs or execution counts; clear them before committing"


def test_asserts_what_it_teaches(notebook):
    path, nb = notebook
    code = [cell.source for cell in nb.cells if cell.cell_type == "code"]
    asserts = 0
    for src in code:
        # drop IPython magics and shell escapes so the rest parses as Python
        lines = [ln for ln in src.splitlines() if not ln.lstrip().startswith(("%", "!"))]
        try:
            tree = ast.parse("\n".join(lines))
        except SyntaxError:
            continue
        asserts += sum(isinstance(node, ast.Assert) for node in ast.walk(tree))
    assert asserts >= 1, f"{path.name}: no `assert` in any code cell"


def test_no_blocking_input(notebook):
    path, nb = notebook
    for cell in nb.cells:
        if cell.cell_type == "code":
            assert "input(" not in cell.source, f"{path.name}: a cell waits for keyboard input"
