"""Running a lesson's code in-process, for tests that switch a method off and expect a lesson assert to fail."""

from __future__ import annotations

from pathlib import Path

import nbformat

LESSONS = Path(__file__).resolve().parent.parent / "lessons"


def first_failing_assert(name: str) -> tuple[int, AssertionError] | None:
    """Run the lesson's code cells until an assert fails: (cell index, error), or None if all pass."""
    import matplotlib.pyplot as plt

    nb = nbformat.read(LESSONS / name, as_version=4)
    namespace: dict[str, object] = {"__name__": "__lesson__"}
    try:
        for k, cell in enumerate(nb.cells):
            if cell.cell_type != "code":
                continue
            try:
                exec(compile(cell.source, f"{name}[{k}]", "exec"), namespace)  # noqa: S102 (our own lessons)
            except AssertionError as exc:
                return k, exc
    finally:
        plt.close("all")
    return None
