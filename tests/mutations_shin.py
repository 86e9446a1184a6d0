"""Mutations of the Shin et al. 2003 lessons (08-10), run by ``test_lessons_falsifiable.py``.

Each case is ``(lesson, switch, message)``: ``switch(monkeypatch)`` breaks one
piece of the method, and the lesson must then fail an ``assert`` whose
message contains ``message`` (None: any assert).
"""

from __future__ import annotations

from collections.abc import Callable

import pytest

CASES: list[tuple[str, Callable[[pytest.MonkeyPatch], None], str | None]] = []
