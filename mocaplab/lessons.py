"""Instant feedback for the lessons' exercises, without giving the answer away.

The lessons end with predict-then-check exercises written in nbgrader's
format: the student's answer goes between ``### BEGIN SOLUTION`` and
``### END SOLUTION`` (removed in the student version), and a graded cell
checks it.  :func:`check` is what such a cell calls: it compares the answer
with a value the lesson computed independently and says *how* the answer is
off (too high, too low, wrong shape, how many entries) but never prints the
expected value, so a student can try again.

Example
-------
>>> check(0.52, 0.5, name="stride (m)", rtol=0.1)
ok: stride (m)
True
>>> try:
...     check(0.9, 0.5, name="stride (m)", rtol=0.1)
... except CheckError as e:
...     print(e)
stride (m): not yet, your answer is too high

Working copies
--------------
A student runs the lessons in a working copy, so a run (outputs, answers)
never dirties the course's copy.  ``python -m mocaplab.lessons copy DEST``
(:func:`copy_lessons`) copies the notebooks and ``00_glossary.md`` into
``DEST``.  Run again after the course's copy was updated (``git pull``), it
adds new lessons and updates the ones the student has not changed, keeps the
ones the student changed (``--force`` replaces them), and says which is which.
What it copied is recorded, by sha256, in ``DEST/.mocaplab-lessons.json``.
"""

from __future__ import annotations

import hashlib
import json
import math
import numbers
import os
import sys
from dataclasses import dataclass, field
from fractions import Fraction
from pathlib import Path
from typing import Any

import numpy as np

from ._atomic import atomic_write

__all__ = ["CheckError", "LessonsCopy", "check", "copy_lessons", "course_lessons"]

#: What a working copy holds besides the notebooks.
GLOSSARY = "00_glossary.md"
#: The record of what :func:`copy_lessons` copied (file name -> sha256), inside the working copy.
MANIFEST = ".mocaplab-lessons.json"


class CheckError(AssertionError):
    """An exercise answer that does not match (an AssertionError, so nbgrader counts it as failed).

    Examples
    --------
    >>> check([1, 2], [1, 3], name="contacts")
    Traceback (most recent call last):
    ...
    mocaplab.lessons.CheckError: contacts: not yet, 1 of 2 entries are off
    """


def check(
    answer: Any,
    expected: Any,
    *,
    name: str = "answer",
    rtol: float = 1e-2,
    atol: float = 0.0,
    hint: str | None = None,
    quiet: bool = False,
) -> bool:
    """Check an exercise answer against the lesson's own result.

    Parameters
    ----------
    answer : number, bool, str, sequence or ndarray
        The student's value.  ``...`` or None (the placeholder left in a
        student version) is reported as "no answer yet".
    expected : same kind as ``answer``
        The value the lesson computed.  Numbers and arrays match within
        ``atol + rtol * |expected|`` (elementwise); booleans, strings and
        other values must be equal.
    name : str
        What the answer is, shown in the feedback.
    rtol, atol : float
        Tolerances for numbers (default 1 %).
    hint : str, optional
        Appended to the feedback when the answer is off.
    quiet : bool
        Do not print the "ok" line.

    Returns
    -------
    bool
        True when the answer matches.

    Raises
    ------
    CheckError
        When it does not, saying how (never showing ``expected``).
    ValueError
        For a negative or infinite tolerance.

    Examples
    --------
    >>> check(0.52, 0.5, name="stride (m)", rtol=0.1)
    ok: stride (m)
    True
    >>> check(0.52, 0.5, rtol=0.1, quiet=True)
    True
    """
    if not (0 <= rtol < math.inf and 0 <= atol < math.inf):
        raise ValueError(f"Expected finite non-negative `rtol` and `atol`, got {rtol!r} and {atol!r}")
    problem = _problem(answer, expected, rtol=rtol, atol=atol)
    if problem is not None:
        raise CheckError(f"{name}: {problem}" + (f" ({hint})" if hint else ""))
    if not quiet:
        print(f"ok: {name}")
    return True


def _is_number(x: Any) -> bool:
    return isinstance(x, numbers.Real | np.floating | np.integer) and not isinstance(x, bool | np.bool_)


def _exact(x: Any) -> Fraction:
    """A real number as an exact fraction: no overflow for huge integers, no rounding for floats."""
    return Fraction(int(x)) if isinstance(x, numbers.Integral) else Fraction(float(x))


def _finite(x: Any) -> bool:
    return isinstance(x, numbers.Integral) or math.isfinite(float(x))


def _bad_expected(what: str) -> ValueError:
    # a bug in the lesson, not in the student's answer: say so, still without the value
    return ValueError(f"Expected {what} for `expected` (a bug in the lesson, not in your answer)")


def _equal(a: Any, e: Any) -> bool:
    try:
        same = a == e
        return bool(same) if isinstance(same, bool | np.bool_) else False
    except Exception:  # noqa: BLE001 (any comparison that cannot be made is "not equal")
        return False


def _problem(answer: Any, expected: Any, *, rtol: float, atol: float) -> str | None:
    if answer is None or answer is Ellipsis:
        return "no answer yet: replace the placeholder with your prediction"
    if isinstance(expected, np.ndarray) and expected.ndim == 0:
        expected = expected.item()
    if isinstance(answer, np.ndarray) and answer.ndim == 0:
        answer = answer.item()  # a 0-d array is a number (or a bool, or a string)
    if isinstance(expected, bool | np.bool_):
        if not isinstance(answer, bool | np.bool_):
            return f"expected True or False, got {type(answer).__name__}"
        return None if bool(answer) == bool(expected) else "not yet"
    if _is_number(expected):
        if not _finite(expected):
            raise _bad_expected("a finite number")
        if not _is_number(answer):
            return f"expected a number, got {type(answer).__name__}"
        if not _finite(answer):
            return "expected a finite number, got " + str(float(answer))
        a, e = _exact(answer), _exact(expected)
        if abs(a - e) <= _exact(atol) + _exact(rtol) * abs(e):
            return None
        return "not yet, your answer is too " + ("high" if a > e else "low")
    if isinstance(expected, np.ndarray | list | tuple):
        return _array_problem(answer, expected, rtol=rtol, atol=atol)
    return None if _equal(answer, expected) else "not yet"


def _array_problem(answer: Any, expected: Any, *, rtol: float, atol: float) -> str | None:
    try:
        e_arr = np.asarray(expected)
    except (ValueError, TypeError) as exc:
        raise _bad_expected("a regular array or nested list (not ragged)") from exc
    numeric = e_arr.dtype.kind in "biuf"
    try:
        a_arr = np.asarray(answer) if numeric else np.asarray(answer, dtype=object)
    except (ValueError, TypeError):
        return f"expected shape {e_arr.shape}, got a ragged {type(answer).__name__}"
    if a_arr.shape != e_arr.shape:
        return f"expected shape {e_arr.shape}, got {a_arr.shape}"
    if e_arr.dtype.kind == "b":
        if a_arr.dtype.kind != "b" and not (a_arr.dtype.kind in "iuf" and np.isin(a_arr, (0, 1)).all()):
            return f"expected True or False entries of shape {e_arr.shape}, got {a_arr.dtype} entries"
        off = a_arr.astype(bool) != e_arr
    elif numeric:
        ef = e_arr.astype(float)
        if not np.isfinite(ef).all():
            raise _bad_expected("finite numbers")
        if a_arr.dtype.kind not in "biuf":
            return f"expected numbers of shape {e_arr.shape}, got {a_arr.dtype} entries"
        off = ~(np.abs(a_arr.astype(float) - ef) <= atol + rtol * np.abs(ef))
    else:
        # strings, huge integers, mixed entries: each entry compared as a scalar answer
        off = np.array(
            [_problem(a, e, rtol=rtol, atol=atol) is not None for a, e in zip(a_arr.flat, e_arr.flat, strict=True)],
            dtype=bool,
        )
    n = int(np.count_nonzero(off))
    return None if n == 0 else f"not yet, {n} of {off.size} entries are off"


# ------------------------------------------------------------------ working copies
@dataclass(frozen=True)
class LessonsCopy:
    """What :func:`copy_lessons` did, file names sorted in each list.

    Parameters
    ----------
    added : list of str
        Lessons the working copy did not have.
    updated : list of str
        Lessons the student had not changed whose course version changed.
    kept : list of str
        Lessons the student changed, left as they are (without ``force``).
    replaced : list of str
        Lessons the student changed, replaced by the course version (``force``).
    unchanged : list of str
        Lessons already the same as the course's.

    Examples
    --------
    >>> LessonsCopy(added=["01_intro.ipynb"])
    LessonsCopy(added=['01_intro.ipynb'], updated=[], kept=[], replaced=[], unchanged=[])
    """

    added: list[str] = field(default_factory=list)
    updated: list[str] = field(default_factory=list)
    kept: list[str] = field(default_factory=list)
    replaced: list[str] = field(default_factory=list)
    unchanged: list[str] = field(default_factory=list)


def course_lessons() -> Path:
    """The course's ``lessons/`` folder: the one beside the installed (editable) package.

    Returns
    -------
    Path
        An absolute path; the folder holds ``00_glossary.md``.

    Raises
    ------
    FileNotFoundError
        When there is none (a package installed without the repository): pass the folder explicitly.

    Examples
    --------
    >>> folder = course_lessons()
    >>> folder.name, (folder / "00_glossary.md").is_file()
    ('lessons', True)
    """
    folder = Path(__file__).resolve().parents[1] / "lessons"
    if not (folder / GLOSSARY).is_file():
        raise FileNotFoundError(
            f"no lessons/ folder beside the mocaplab package (looked for {folder / GLOSSARY}); give the course's "
            "lessons folder with --from (python -m mocaplab.lessons copy DEST --from COURSE/lessons)"
        )
    return folder


def _sha256(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


def _lesson_files(source: Path) -> list[str]:
    names = sorted(p.name for p in source.glob("*.ipynb") if p.is_file())
    if not names:
        raise FileNotFoundError(f"{source}: expected the course's lessons folder (NN_topic.ipynb files), found none")
    return ([GLOSSARY] if (source / GLOSSARY).is_file() else []) + names


def _read_manifest(dest: Path) -> dict[str, str]:
    path = dest / MANIFEST
    if not path.is_file():
        return {}
    try:
        record = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, ValueError) as exc:
        raise ValueError(
            f"{path}: expected the JSON record of a lessons copy ({exc}); delete it to start over"
        ) from exc
    if not isinstance(record, dict) or not all(isinstance(v, str) for v in record.values()):
        raise ValueError(f"{path}: expected a JSON object of file name to sha256; delete it to start over")
    return record


def copy_lessons(
    dest: str | os.PathLike[str],
    *,
    source: str | os.PathLike[str] | None = None,
    force: bool = False,
) -> LessonsCopy:
    """Give a student a working copy of the lessons (notebooks and glossary), or bring one up to date.

    A lesson missing from ``dest`` is added.  A lesson in ``dest`` that is
    still what was copied there last time (the student has not changed it)
    is updated to the course's version.  A lesson the student changed (its
    content is neither what was copied nor the course's version) is kept,
    unless ``force``.  Every file is written whole or not at all
    (:func:`mocaplab._atomic.atomic_write`); the course's folder is only read.

    Parameters
    ----------
    dest : path
        The working copy (created if needed).
    source : path, optional
        The course's lessons folder; default :func:`course_lessons`.
    force : bool
        Replace the lessons the student changed too.

    Returns
    -------
    LessonsCopy
        Which files were added, updated, kept, replaced or already the same.

    Raises
    ------
    FileNotFoundError
        When ``source`` holds no lessons.
    ValueError
        When ``dest`` is the course's folder, or holds an unreadable record.

    Examples
    --------
    A course of two lessons; the student edits one, the course updates the
    other, and the second copy keeps the student's work:

    >>> import tempfile
    >>> from pathlib import Path
    >>> with tempfile.TemporaryDirectory() as tmp:
    ...     course, mine = Path(tmp, "course"), Path(tmp, "mine")
    ...     course.mkdir()
    ...     _ = (course / "01_intro.ipynb").write_text("{}")
    ...     _ = (course / "02_paths.ipynb").write_text("{}")
    ...     first = copy_lessons(mine, source=course)
    ...     _ = (mine / "01_intro.ipynb").write_text('{"answer": 1}')
    ...     _ = (course / "02_paths.ipynb").write_text('{"fixed": 1}')
    ...     again = copy_lessons(mine, source=course)
    >>> first.added, again.kept, again.updated
    (['01_intro.ipynb', '02_paths.ipynb'], ['01_intro.ipynb'], ['02_paths.ipynb'])
    """
    src = course_lessons() if source is None else Path(source).expanduser()
    out = Path(dest).expanduser()
    if out.resolve() == src.resolve():
        raise ValueError(f"Expected `dest` to be another folder than the course's lessons ({src}), got {dest!s}")
    names = _lesson_files(src)
    out.mkdir(parents=True, exist_ok=True)
    record = _read_manifest(out)
    done = LessonsCopy()
    for name in names:
        course, mine = src / name, out / name
        new = _sha256(course)
        if not mine.is_file():
            bucket = done.added
        else:
            have = _sha256(mine)
            if have == new:
                record[name] = new
                done.unchanged.append(name)
                continue
            if record.get(name) == have:
                bucket = done.updated
            elif force:
                bucket = done.replaced
            else:
                done.kept.append(name)
                continue
        raw = course.read_bytes()
        with atomic_write(mine) as fh:
            fh.write(raw)
        record[name] = hashlib.sha256(raw).hexdigest()
        bucket.append(name)
    with atomic_write(out / MANIFEST, mode="w", encoding="utf-8") as fh:
        json.dump(dict(sorted(record.items())), fh, indent=1)
        fh.write("\n")
    return done


def main(argv: list[str] | None = None) -> int:
    """``python -m mocaplab.lessons copy DEST [--from SRC] [--force]`` (exit code 0 when done)."""
    import argparse

    parser = argparse.ArgumentParser(
        prog="python -m mocaplab.lessons",
        description="Give a student a working copy of the lessons, or bring one up to date.",
    )
    sub = parser.add_subparsers(dest="command", required=True)
    p = sub.add_parser(
        "copy",
        help="copy the lessons into DEST",
        description="Copy the lesson notebooks and the glossary into DEST: new lessons are added, lessons you have "
        "not changed are updated, lessons you changed are kept (--force replaces them).",
    )
    p.add_argument("dest", metavar="DEST", help="your working copy (created if needed)")
    p.add_argument(
        "--from",
        dest="source",
        metavar="SRC",
        help="the course's lessons folder (default: the lessons/ folder beside the installed package)",
    )
    p.add_argument("--force", action="store_true", help="replace the lessons you changed too")
    args = parser.parse_args(argv)
    try:
        done = copy_lessons(args.dest, source=args.source, force=args.force)
    except (OSError, ValueError) as err:
        print(f"error: {err}", file=sys.stderr)
        return 2
    for label, names in (("added", done.added), ("updated", done.updated), ("replaced", done.replaced)):
        for name in names:
            print(f"{label}: {name}")
    for name in done.kept:
        print(f"kept: {name} (you changed it; --force replaces it with the course's version)")
    print(
        f"{args.dest}: {len(done.added)} added, {len(done.updated)} updated, {len(done.kept)} kept, "
        f"{len(done.replaced)} replaced, {len(done.unchanged)} already up to date"
    )
    return 0


if __name__ == "__main__":
    sys.exit(main())
