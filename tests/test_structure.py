"""The shape of the house: one-way imports, paper packages apart, no oversized room without a reason.

Every module of ``mocaplab/`` and ``widgets/`` (installed as
``mocaplab.widgets``) is parsed, and every import counts: module level,
inside functions (a function-level import hides a cycle from Python's
import machinery, not from the design) and under ``TYPE_CHECKING``.

- no import cycle anywhere;
- the three paper packages (``editing`` for Kim et al., ``physics`` for
  Shin et al., ``staggered`` for Coleman et al.) never import each other;
  what they share lives on the ground floor (``goals``, ``ik``,
  ``displacement``, ``contacts``, ``motion``, ...), which imports none of
  them;
- the core never imports the widgets, and the widgets never import the
  lessons' helpers;
- no file over :data:`MAX_LINES` lines unless its module docstring says
  why, in a sentence starting with :data:`REASON`.
"""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
PACKAGES = {"mocaplab": ROOT / "mocaplab", "mocaplab.widgets": ROOT / "widgets"}
PAPERS = ("mocaplab.editing", "mocaplab.physics", "mocaplab.staggered")
GROUND = (
    "mocaplab.motion", "mocaplab.roles", "mocaplab.quat", "mocaplab.kinematics", "mocaplab.ik", "mocaplab.goals",
    "mocaplab.displacement", "mocaplab.contacts", "mocaplab.anatomy", "mocaplab.undo",
)
# mocaplab.quality is not on the ground floor: it judges every paper's output and measures balance with
# mocaplab.physics (no paper package imports it)
MAX_LINES = 800
REASON = "Longer than 800 lines"


def modules(packages: dict[str, Path]) -> dict[str, Path]:
    """Dotted module name -> file, for every ``.py`` file under each package root."""
    out = {}
    for package, root in packages.items():
        for path in sorted(root.rglob("*.py")):
            parts = path.relative_to(root).with_suffix("").parts
            name = ".".join((package, *parts)).removesuffix(".__init__")
            out[name] = path
    return out


def import_graph(mods: dict[str, Path]) -> dict[str, dict[str, int]]:
    """For each module, the modules of ``mods`` it imports anywhere in its file, with the first line."""
    graph = {}
    for name, path in mods.items():
        package = name if path.name == "__init__.py" else name.rpartition(".")[0]
        found: dict[str, int] = {}
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"), filename=str(path))):
            if isinstance(node, ast.ImportFrom):
                base = node.module or ""
                if node.level:
                    parts = package.split(".")
                    parent = ".".join(parts[: len(parts) - node.level + 1])
                    base = f"{parent}.{base}" if base else parent
                for alias in node.names:
                    full = f"{base}.{alias.name}"
                    found.setdefault(full if full in mods else base, node.lineno)
            elif isinstance(node, ast.Import):
                for alias in node.names:
                    found.setdefault(alias.name, node.lineno)
        graph[name] = {m: line for m, line in found.items() if m in mods and m != name}
    return graph


def cycles(graph: dict[str, dict[str, int]]) -> list[list[str]]:
    """Strongly connected components of more than one module (Tarjan), each sorted."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    found: list[list[str]] = []

    def visit(v: str) -> None:
        index[v] = low[v] = len(index)
        stack.append(v)
        on_stack.add(v)
        for w in graph[v]:
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on_stack:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            comp = []
            while True:
                w = stack.pop()
                on_stack.discard(w)
                comp.append(w)
                if w == v:
                    break
            if len(comp) > 1:
                found.append(sorted(comp))

    for v in graph:
        if v not in index:
            visit(v)
    return found


def _in(name: str, package: str) -> bool:
    return name == package or name.startswith(package + ".")


def _describe(graph: dict[str, dict[str, int]], comp: list[str]) -> str:
    edges = [f"{a} -> {b} (line {graph[a][b]})" for a in comp for b in graph[a] if b in comp]
    return "import cycle: " + "; ".join(edges)


MODS = modules(PACKAGES)
GRAPH = import_graph(MODS)


def test_the_modules_are_found():
    for name in ("mocaplab.motion", "mocaplab.goals", "mocaplab.editing.scene", "mocaplab.widgets.viewer",
                 "mocaplab.physics.touchup", "mocaplab.staggered.representation"):
        assert name in MODS, name


def test_no_import_cycles():
    found = cycles(GRAPH)
    assert not found, "\n".join(_describe(GRAPH, c) for c in found)


@pytest.mark.parametrize("paper", PAPERS)
def test_paper_packages_never_import_each_other(paper):
    others = [p for p in PAPERS if p != paper]
    bad = [
        f"{m} imports {d} (line {line})"
        for m, deps in GRAPH.items() if _in(m, paper)
        for d, line in deps.items() if any(_in(d, o) for o in others)
    ]
    assert not bad, bad


def test_the_ground_floor_imports_no_paper_package_and_the_core_no_widget():
    bad = [
        f"{m} imports {d} (line {line})"
        for m in GROUND
        for d, line in GRAPH[m].items() if any(_in(d, p) for p in PAPERS)
    ]
    bad += [
        f"{m} imports mocaplab.quality (line {line})"
        for m, deps in GRAPH.items() if any(_in(m, p) for p in PAPERS)
        for d, line in deps.items() if d == "mocaplab.quality"
    ]
    bad += [
        f"{m} imports {d} (line {line})"
        for m, deps in GRAPH.items() if not _in(m, "mocaplab.widgets")
        for d, line in deps.items() if _in(d, "mocaplab.widgets")
    ]
    assert not bad, bad


def test_no_file_over_the_limit_without_a_reason():
    long = []
    for path in MODS.values():
        text = path.read_text(encoding="utf-8")
        n = text.count("\n")
        if n > MAX_LINES and REASON not in (ast.get_docstring(ast.parse(text)) or ""):
            long.append(f"{path.relative_to(ROOT)}: {n} lines")
    assert not long, f"over {MAX_LINES} lines with no '{REASON} ...' sentence in the module docstring: {long}"


def test_the_checks_bite(tmp_path):
    # a small package with a cycle hidden in a function, a paper crossing and a long file without a reason
    pkg = tmp_path / "mocaplab"
    for sub in ("editing", "physics"):
        (pkg / sub).mkdir(parents=True)
        (pkg / sub / "__init__.py").write_text("")
    (pkg / "__init__.py").write_text("")
    (pkg / "a.py").write_text("from . import b\n")
    (pkg / "b.py").write_text("def f():\n    from .a import x\n")
    (pkg / "editing" / "e.py").write_text("from ..physics import p\n")
    (pkg / "physics" / "p.py").write_text('"""Short."""\n' + "x = 1\n" * (MAX_LINES + 1))
    mods = modules({"mocaplab": pkg})
    graph = import_graph(mods)
    assert cycles(graph) == [["mocaplab.a", "mocaplab.b"]]
    assert "mocaplab.physics.p" in graph["mocaplab.editing.e"]
    assert "line 2" in _describe(graph, cycles(graph)[0])


def test_one_interval_convention_across_the_papers():
    # the same (start, stop) tuple selects the same frames in contacts, goals and every editing constraint
    import numpy as np

    from mocaplab.contacts import intervals_from_mask, mask_from_intervals
    from mocaplab.editing import EndEffectorConstraint, PinPosition
    from mocaplab.goals import EndEffector, interval_weights

    span = (10, 20)
    frames = np.arange(*span)
    assert intervals_from_mask(mask_from_intervals([span], 40)) == [span]
    assert np.flatnonzero(interval_weights(40, [span], window_frames=0) == 1.0).tolist() == frames.tolist()
    assert EndEffector("hand", span, (0.0, 1.0, 0.0)).intervals(40) == [span]
    assert EndEffectorConstraint(0, joint="hand", frames=span, target=(0.0, 1.0, 0.0)).constraint.intervals(40) == [span]
    pin = PinPosition(0, position=(0.0, 0.0), frames=span)
    assert pin.samples(1) == [(int(f),) for f in frames]
