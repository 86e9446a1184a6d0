"""A pytest plugin for tests/test_test_run.py: says, once collection is done, whether nbval was imported."""

from __future__ import annotations

import sys

import pytest


def pytest_collection_finish(session: pytest.Session) -> None:
    reporter = session.config.pluginmanager.get_plugin("terminalreporter")
    if reporter is not None:
        reporter.write_line(f"nbval imported: {'nbval' in sys.modules}")
