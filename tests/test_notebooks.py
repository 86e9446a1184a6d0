"""Every committed lesson is a clean nbformat v4 notebook that asserts something."""

from __future__ import annotations

import ast
import builtins
import re
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


GLOSSARY = LESSONS[0].parent / "00_glossary.md" if LESSONS else None
_LINK = re.compile(r"\]\(([^)\s]+)\)")


def test_glossary_links_resolve():
    """The glossary exists and every lesson it links to exists."""
    assert GLOSSARY is not None and GLOSSARY.is_file(), "lessons/00_glossary.md is missing"
    targets = _LINK.findall(GLOSSARY.read_text(encoding="utf-8"))
    assert targets, "the glossary links no lesson"
    missing = sorted({t for t in targets if not (GLOSSARY.parent / t).is_file()})
    assert not missing, f"00_glossary.md links files that do not exist: {missing}"


def test_links_the_glossary(notebook):
    path, nb = notebook
    linked = any("00_glossary.md" in _LINK.findall(cell.source) for cell in nb.cells if cell.cell_type == "markdown")
    assert linked, f"{path.name}: no markdown cell links the glossary, [glossary](00_glossary.md)"


def _nbgrader(cell) -> dict:
    return cell.get("metadata", {}).get("nbgrader", {})


_MARKERS = ("### BEGIN SOLUTION", "### END SOLUTION", "### BEGIN HIDDEN TESTS", "### END HIDDEN TESTS")


def _regions(source: str, begin: str, end: str) -> list[str] | None:
    """The text of each begin/end region in order, or None when the markers do not pair up."""
    out, inside, body = [], False, []
    for line in source.splitlines():
        mark = line.strip()
        if mark == begin:
            if inside:
                return None
            inside, body = True, []
        elif mark == end:
            if not inside:
                return None
            inside = False
            out.append("\n".join(body))
        elif inside:
            body.append(line)
    return None if inside else out


def test_exercises_are_well_formed_nbgrader_cells(notebook):
    """Solution cells hold paired SOLUTION markers, graded cells points, hidden tests and a check; ids unique."""
    path, nb = notebook
    ids: list[str] = []
    for k, cell in enumerate(nb.cells):
        meta = _nbgrader(cell)
        where = f"{path.name} cell {k}"
        if not meta:
            stray = [m for m in _MARKERS if m in cell.source]
            assert not stray, f"{where}: {stray} outside an nbgrader cell (no metadata.nbgrader)"
            continue
        assert cell.cell_type == "code", f"{where}: nbgrader metadata on a {cell.cell_type} cell"
        assert meta.get("schema_version") == 3, (
            f"{where}: nbgrader schema_version {meta.get('schema_version')}, expected 3"
        )
        gid = meta.get("grade_id")
        assert isinstance(gid, str) and re.fullmatch(r"[A-Za-z0-9_\-]+", gid), f"{where}: bad grade_id {gid!r}"
        ids.append(gid)
        solution, grade = meta.get("solution"), meta.get("grade")
        assert isinstance(solution, bool) and isinstance(grade, bool), f"{where}: solution/grade must be booleans"
        assert meta.get("task") is False, f"{where}: task cells are not used"
        if solution:
            assert not grade and meta.get("locked") is False, f"{where}: a solution cell is ungraded and unlocked"
            regions = _regions(cell.source, "### BEGIN SOLUTION", "### END SOLUTION")
            assert regions, f"{where}: a solution cell needs ### BEGIN SOLUTION / ### END SOLUTION, in pairs"
            assert all(r.strip() for r in regions), f"{where}: an empty solution region"
        else:
            assert "### BEGIN SOLUTION" not in cell.source, f"{where}: solution markers in a cell not marked solution"
        if grade:
            points = meta.get("points")
            assert isinstance(points, int | float) and points > 0, f"{where}: a graded cell needs points > 0"
            assert meta.get("locked") is True, f"{where}: a graded test cell is locked"
            hidden = _regions(cell.source, "### BEGIN HIDDEN TESTS", "### END HIDDEN TESTS")
            assert hidden and all(r.strip() for r in hidden), f"{where}: a graded cell needs non-empty hidden tests"
            visible = re.sub(r"(?s)### BEGIN HIDDEN TESTS.*?### END HIDDEN TESTS", "", cell.source)
            assert "check(" in visible, f"{where}: a graded cell gives feedback with mocaplab.lessons.check(...)"
    dup = sorted({g for g in ids if ids.count(g) > 1})
    assert not dup, f"{path.name}: duplicate nbgrader grade_ids {dup}"


def test_has_an_exercise(notebook):
    """Each lesson ends with a predict-then-check exercise: a solution cell and a graded cell after it."""
    path, nb = notebook
    kinds = [(_nbgrader(c).get("solution"), _nbgrader(c).get("grade")) for c in nb.cells]
    solutions = [k for k, (s, _) in enumerate(kinds) if s]
    graded = [k for k, (_, g) in enumerate(kinds) if g]
    assert solutions and graded, f"{path.name}: no exercise (an nbgrader solution cell and a graded test cell)"
    assert graded[-1] > solutions[0], f"{path.name}: the graded cells come before the solutions they check"


def _code(source: str) -> ast.Module:
    """A code cell's Python, IPython magics and shell escapes dropped."""
    return ast.parse("\n".join(ln for ln in source.splitlines() if not ln.lstrip().startswith(("%", "!"))))


def _bound(tree: ast.AST) -> set[str]:
    """Every name a piece of code binds anywhere (over-approximated: locals of functions too)."""
    names: set[str] = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Name) and not isinstance(node.ctx, ast.Load):
            names.add(node.id)
        elif isinstance(node, ast.arg):
            names.add(node.arg)
        elif isinstance(node, ast.FunctionDef | ast.AsyncFunctionDef | ast.ClassDef):
            names.add(node.name)
        elif isinstance(node, ast.Import | ast.ImportFrom):
            assert not any(a.name == "*" for a in node.names), "a star import hides which names a cell defines"
            names |= {a.asname or a.name.split(".")[0] for a in node.names}
        elif isinstance(node, ast.ExceptHandler) and node.name:
            names.add(node.name)
    return names


def _loaded(tree: ast.AST) -> set[str]:
    return {n.id for n in ast.walk(tree) if isinstance(n, ast.Name) and isinstance(n.ctx, ast.Load)}


_BUILTINS = set(dir(builtins)) | {"display", "get_ipython"}  # IPython adds these two


def test_student_versions_reach_their_checks(notebook):
    """With the solutions removed (as nbgrader's student version), every graded cell still runs up to its check.

    A solution cell of the student version runs only what comes before its
    first ``### BEGIN SOLUTION`` (nbgrader puts ``raise NotImplementedError``
    there), so the answer's name must be bound by a placeholder line
    (``name = ...``) above the markers: a graded cell then says "no answer
    yet" instead of failing with a NameError.  Static, nothing is executed.
    """
    path, nb = notebook
    bound = set(_BUILTINS)
    placeholders: set[str] = set()
    for k, cell in enumerate(nb.cells):
        if cell.cell_type != "code":
            continue
        meta = _nbgrader(cell)
        if meta.get("solution"):
            before = cell.source.split("### BEGIN SOLUTION")[0]
            tree = _code(before)
            for node in tree.body:
                if isinstance(node, ast.Assign) and isinstance(node.value, ast.Constant) and node.value.value is ...:
                    placeholders |= {t.id for t in node.targets if isinstance(t, ast.Name)}
            bound |= _bound(tree)
            continue
        visible = re.sub(r"(?s)### BEGIN HIDDEN TESTS.*?### END HIDDEN TESTS", "", cell.source)
        tree = _code(visible)
        if meta.get("grade"):
            where = f"{path.name} cell {k} ({meta.get('grade_id')})"
            unbound = sorted(_loaded(tree) - bound - _bound(tree))
            assert not unbound, f"{where}: the student version has no {unbound} (a NameError before the check)"
            answers = _loaded(tree) & placeholders
            assert answers, f"{where}: checks no answer bound by a placeholder `name = ...` above BEGIN SOLUTION"
        bound |= _bound(_code(cell.source))
