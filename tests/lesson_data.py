"""Whether the CMU clips a lesson reads can be had, so that lessons without data skip in one line.

A lesson reads its clips with ``mocaplab.cmu("SS_TT")``.  Outside CI, when
neither the mirror (``MOCAPLAB_DATA_DIR``) nor a download gives one of them,
the lesson is skipped with one line naming the clip and what to do, instead
of failing in every cell with download tracebacks.  In CI (``CI`` set) nothing
is skipped: a missing mirror fails the run.

Used by ``lessons/conftest.py`` (the notebooks run by nbval) and
``tests/conftest.py`` (the tests that run lessons in full mode or with a
method switched off).
"""

from __future__ import annotations

import json
import os
import re
from functools import cache
from pathlib import Path

#: A CMU trial id written as a string literal in a lesson's code ("16_15", '127_04').
TRIAL_RE = re.compile(r"""["'](\d{2,3}_\d{2})["']""")


def in_ci() -> bool:
    """Whether the run is a CI run (``CI`` set to anything but empty, 0 or false)."""
    return os.environ.get("CI", "").strip().lower() not in ("", "0", "false", "no")


def lesson_trials(notebook: str | os.PathLike[str]) -> list[str]:
    """The CMU trial ids the code cells of a lesson notebook name, in order of first use."""
    nb = json.loads(Path(notebook).read_text(encoding="utf-8"))
    seen: dict[str, None] = {}
    for cell in nb.get("cells", []):
        if cell.get("cell_type") == "code":
            source = cell.get("source", "")
            for trial in TRIAL_RE.findall("".join(source) if isinstance(source, list) else source):
                seen.setdefault(trial, None)
    return list(seen)


@cache
def _unavailable(trial: str, mirror: str | None) -> str | None:
    """Why ``trial`` cannot be had (None when it can), for one mirror setting (cached per process)."""
    from mocaplab import data

    subject, trial = data.parse_trial(trial)
    if mirror is not None:
        # what data.cmu reads from a mirror (the files' hashes are checked when the lesson reads them)
        root = Path(mirror).expanduser()
        entry = data.CLIPS.get(trial)
        wanted = [str(entry["bvh"])] if entry is not None else [f"bvh/{trial}.bvh", f"asfamc/{subject}/{trial}.amc"]
        if any((root / rel).is_file() for rel in wanted):
            return None
        return f"{data.ENV_VAR}={root} has no {wanted[0]}"
    try:
        data.cmu(trial)  # downloads the clip once into the cache, or reads it from there
    except data.DataError:
        return f"no mirror ({data.ENV_VAR} unset) and {trial} could not be downloaded from {data.download_base()}"
    return None


def missing_data(notebook: str | os.PathLike[str]) -> str | None:
    """One line saying why a lesson cannot get its clips, or None when it can (or in CI, where it must)."""
    if in_ci():
        return None
    from mocaplab import data

    mirror = data.mirror_dir()
    for trial in lesson_trials(notebook):
        why = _unavailable(trial, None if mirror is None else str(mirror))
        if why is not None:
            return (
                f"no CMU data: {why}. Export {data.ENV_VAR}=<a mirror folder> in the shell that runs pytest, "
                "or connect to the network (see the README, 'Data')"
            )
    return None
