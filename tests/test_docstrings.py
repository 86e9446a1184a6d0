"""Every public entry point says what it takes and shows a runnable example (issue #26 item 5).

An entry point is a function or class named in the ``__all__`` of one of :data:`PACKAGES`. Its docstring (numpydoc)
has a ``Parameters`` section naming each parameter of its signature, a ``Returns`` (or ``Yields``) section when it
returns something, and an ``Examples`` section with at least one doctest that shows a result. The doctests of every
module of the core (``mocaplab.*``; the widgets are tested elsewhere) run here, one test per module, with the options
the docs are written for; an example may be skipped only where running it is impossible (a file on the user's disk,
a browser), and no more than :data:`MAX_SKIPPED` of the entry points may have a skipped example.
"""

from __future__ import annotations

import doctest
import importlib
import inspect
import io
import pkgutil
import re
import time
from types import ModuleType

import pytest

import mocaplab

PACKAGES = (
    "mocaplab",
    "mocaplab.io",
    "mocaplab.editing",
    "mocaplab.physics",
    "mocaplab.staggered",
    "mocaplab.contacts",
    "mocaplab.quality",
    "mocaplab.data",
    "mocaplab.roles",
    "mocaplab.goals",
    "mocaplab.motion",
    "mocaplab.lessons",
    "mocaplab.anatomy",
)
#: Largest share of entry points whose examples carry a ``# doctest: +SKIP``.
MAX_SKIPPED = 0.10
#: Seconds one docstring's examples may take. They are written to take under 0.5 s; the margin is for a busy
#: machine and for the first read of a CMU clip, which later examples find in the cache.
EXAMPLE_BUDGET_S = 2.0
OPTIONS = doctest.ELLIPSIS | doctest.NORMALIZE_WHITESPACE
_HEADING = re.compile(r"^-{3,}$")
_ITEM = re.compile(r"^(\*{0,2}\w+(?:\s*,\s*\*{0,2}\w+)*)\s*(?::.*)?$")


def entry_points() -> dict[str, object]:
    """Each entry point once, by the first package (in :data:`PACKAGES` order) that exports it."""
    found: dict[str, object] = {}
    seen: set[int] = set()
    for package in PACKAGES:
        module = importlib.import_module(package)
        for name in module.__all__:
            obj = getattr(module, name)
            if (inspect.isfunction(obj) or inspect.isclass(obj)) and id(obj) not in seen:
                seen.add(id(obj))
                found[f"{package}.{name}"] = obj
    return found


def core_modules() -> list[str]:
    """Every module of the core package (the widgets, installed as ``mocaplab.widgets``, are not core)."""
    names = ["mocaplab"]
    for info in pkgutil.walk_packages(mocaplab.__path__, "mocaplab."):
        if not info.name.startswith("mocaplab.widgets"):
            names.append(info.name)
    return sorted(names)


def docstring(obj: object) -> str:
    """The object's docstring; a class's ``__init__`` docstring is read with it when the class defines one."""
    text = inspect.getdoc(obj) or ""
    init = inspect.getdoc(getattr(obj, "__init__", None)) if inspect.isclass(obj) and "__init__" in vars(obj) else None
    if init and init != inspect.getdoc(object.__init__):
        text += "\n\n" + init
    return text


def sections(text: str) -> dict[str, list[str]]:
    """numpydoc sections of a cleaned docstring: heading -> its lines (a heading is underlined with dashes)."""
    lines = text.splitlines()
    out: dict[str, list[str]] = {}
    current: list[str] | None = None
    i = 0
    while i < len(lines):
        if i + 1 < len(lines) and lines[i].strip() and _HEADING.match(lines[i + 1].strip()) and not lines[i][0].isspace():
            current = out.setdefault(lines[i].strip(), [])
            i += 2
            continue
        if current is not None:
            current.append(lines[i])
        i += 1
    return out


def documented_parameters(found: dict[str, list[str]]) -> list[str]:
    """Names listed in the ``Parameters`` and ``Other Parameters`` sections (``a, b : float`` names two)."""
    names: list[str] = []
    for heading in ("Parameters", "Other Parameters"):
        for line in found.get(heading, []):
            if line and not line[0].isspace():
                match = _ITEM.match(line.strip())
                if match:
                    names += [n.strip() for n in match.group(1).split(",")]
    return names


def signature_parameters(obj: object) -> list[inspect.Parameter]:
    """The parameters a caller passes (no ``self``); a class without a signature (a warning) takes none."""
    try:
        params = inspect.signature(obj).parameters.values()  # type: ignore[arg-type]
    except (TypeError, ValueError):
        return []
    return [p for p in params if p.name not in ("self", "cls")]


def missing_parameters(obj: object, documented: list[str]) -> list[str]:
    """Signature parameters the docstring does not name; ``*args``/``**kwargs`` may go by any starred name."""
    missing = []
    for p in signature_parameters(obj):
        if p.kind is p.VAR_KEYWORD:
            ok = any(d.startswith("**") for d in documented)
        elif p.kind is p.VAR_POSITIONAL:
            ok = any(d.startswith("*") and not d.startswith("**") for d in documented)
        else:
            ok = p.name in documented
        if not ok:
            missing.append(p.name)
    return missing


def stale_parameters(obj: object, documented: list[str]) -> list[str]:
    """Named in ``Parameters`` but not in the signature (a renamed or removed argument)."""
    names = {p.name for p in signature_parameters(obj)}
    return [d for d in documented if not d.startswith("*") and d not in names]


def returns_something(obj: object) -> bool:
    """A function whose return annotation is not ``None`` (every core function is annotated)."""
    if not inspect.isfunction(obj):
        return False
    annotation = inspect.signature(obj).return_annotation
    return annotation not in (None, "None")


def examples_of(text: str) -> list[doctest.Example]:
    """The doctest examples in the ``Examples`` section of a docstring."""
    body = "\n".join(sections(text).get("Examples", []))
    return doctest.DocTestParser().get_examples(body)


def skipped(examples: list[doctest.Example]) -> bool:
    return any(e.options.get(doctest.SKIP) for e in examples)


ENTRY_POINTS = entry_points()


def test_every_package_exports_entry_points() -> None:
    per_package = {p: [n for n in ENTRY_POINTS if n.rsplit(".", 1)[0] == p] for p in PACKAGES}
    assert len(ENTRY_POINTS) > 150, len(ENTRY_POINTS)
    assert [p for p, names in per_package.items() if not names and p != "mocaplab.anatomy"] == []


@pytest.mark.parametrize("name", sorted(ENTRY_POINTS))
def test_entry_point_docstring(name: str) -> None:
    obj = ENTRY_POINTS[name]
    text = docstring(obj)
    found = sections(text)
    problems = []
    if not text.strip() or not text.splitlines()[0].strip():
        problems.append("no one-line summary")
    documented = documented_parameters(found)
    if signature_parameters(obj) and "Parameters" not in found:
        problems.append("no Parameters section")
    if missing := missing_parameters(obj, documented):
        problems.append(f"Parameters does not name {missing}")
    if stale := stale_parameters(obj, documented):
        problems.append(f"Parameters names {stale}, which the signature does not have")
    if returns_something(obj) and not ({"Returns", "Yields"} & found.keys()):
        problems.append("no Returns section")
    examples = examples_of(text)
    if "Examples" not in found:
        problems.append("no Examples section")
    elif not any(e.want.strip() and not e.options.get(doctest.SKIP) for e in examples):
        problems.append("the Examples section shows no result (no run `>>>` line with output)")
    assert not problems, f"{name}: " + "; ".join(problems)


def test_few_examples_are_skipped() -> None:
    with_skips = sorted(name for name, obj in ENTRY_POINTS.items() if skipped(examples_of(docstring(obj))))
    share = len(with_skips) / len(ENTRY_POINTS)
    assert share <= MAX_SKIPPED, f"{len(with_skips)} of {len(ENTRY_POINTS)} entry points skip examples: {with_skips}"


@pytest.mark.parametrize("module_name", core_modules())
def test_module_doctests(module_name: str, mocap_dir: object) -> None:
    module: ModuleType = importlib.import_module(module_name)
    runner = doctest.DocTestRunner(optionflags=OPTIONS)
    report = io.StringIO()
    slow = []
    for test in doctest.DocTestFinder().find(module):
        if not test.examples:
            continue
        start = time.perf_counter()
        runner.run(test, out=report.write)
        seconds = time.perf_counter() - start
        if seconds > EXAMPLE_BUDGET_S:
            slow.append(f"{test.name} ({seconds:.1f} s)")
    assert runner.failures == 0, report.getvalue()
    assert not slow, f"examples over {EXAMPLE_BUDGET_S} s: {slow}"
