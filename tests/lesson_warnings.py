"""The warnings a student may see in a lesson: only those the lesson teaches (issue #28).

A warning under a cell is read by a student as "something is wrong".  A
lesson shows one only where it teaches something (a target out of reach, a
file whose path joint is not joint 0); any other is fixed at its cause, or
the lesson passes the option that states its intent (``scale=`` for a file
whose unit it wrote), never hidden by a blanket filter.

:data:`TAUGHT` lists, per lesson, the warnings it may show and why.  The
check runs on every cell of every lesson: on nbval's outputs in the test run
(``lessons/conftest.py``) and on nbclient's in full mode
(``tests/test_lessons_full_mode.py``).  A warning as the kernel prints it is
the line ``<file>:<line>: <Category>: <message>`` on the cell's stderr.
"""

from __future__ import annotations

import re
from collections.abc import Iterable, Mapping
from typing import Any

#: lesson file -> {(warning category, start of its message): why the lesson shows it}
TAUGHT: dict[str, dict[tuple[str, str], str]] = {
    "06_full_body_refinement.ipynb": {
        ("UnreachableTargetWarning", "target of 'LeftFoot' out of reach"): (
            "the 'beyond reach' check: the leg straightens toward a target 1.1 m away, and says so"
        ),
    },
    "14_your_own_motion_capture.ipynb": {
        ("UserWarning", "The motion path follows joint 'Hips' (index 1), not joint 0"): (
            "the studio file's static Root: each new reading of the file announces its path joint (the text says so)"
        ),
    },
}

#: A warning as ``warnings.showwarning`` prints it: ``/tmp/ipykernel_1/2.py:3: UserWarning: text``.
WARNING_LINE = re.compile(r"^\S[^\n]*?:\d+: (?P<category>[A-Za-z_][\w.]*Warning): (?P<message>[^\n]*)$", re.M)


def shown_warnings(stderr: str) -> list[tuple[str, str]]:
    """The ``(category, message)`` of every warning printed in ``stderr``.

    >>> shown_warnings("/tmp/ipykernel_7/1.py:3: UserWarning: BVH has no unit\\n  back = load(path)\\n")
    [('UserWarning', 'BVH has no unit')]
    """
    return [(m["category"].rsplit(".", 1)[-1], m["message"]) for m in WARNING_LINE.finditer(stderr)]


def untaught(lesson: str, stderr: str, taught: Mapping[str, Mapping[tuple[str, str], str]] = TAUGHT) -> list[str]:
    """The warnings in ``stderr`` (one cell's) that lesson ``lesson`` (a file name) does not teach."""
    allowed = taught.get(lesson, {})
    return [
        f"{category}: {message}"
        for category, message in shown_warnings(stderr)
        if not any(category == c and message.startswith(start) for c, start in allowed)
    ]


def stderr_text(outputs: Iterable[Any]) -> str:
    """The stderr stream of a cell's outputs (nbformat nodes or dicts)."""
    return "".join(
        str(o.get("text", "")) for o in outputs if o.get("output_type") == "stream" and o.get("name") == "stderr"
    )


def check_cell(lesson: str, cell: str, outputs: Iterable[Any]) -> None:
    """Fail when cell ``cell`` of ``lesson`` showed a warning the lesson does not teach (see :data:`TAUGHT`)."""
    found = untaught(lesson, stderr_text(outputs))
    if found:
        raise AssertionError(
            f"{lesson} {cell} shows a warning it does not teach (fix its cause, pass the option that states the "
            f"intent, or list it in tests/lesson_warnings.py.TAUGHT with the reason): " + "; ".join(found)
        )
