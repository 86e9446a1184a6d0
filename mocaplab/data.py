"""CMU Graphics Lab motion capture clips, by trial id.

>>> walk = cmu("16_15")
>>> walk.n_frames, walk.fps
(471, 120.0)
>>> other = cmu("35_01")           # any trial of the CMU database  # doctest: +SKIP

Which trials
------------
Any of the 2,605 trials of the CMU database (144 subjects): a trial id is
``"SS_TT"`` as CMU names its files, the subject from ``01`` to ``144`` (two
digits, three from 100) and the trial number in two digits (``"02_01"``,
``"16_15"``, ``"127_04"``); anything else is a ``ValueError``
(:func:`parse_trial`).  :func:`clips` lists the *registry*: the 17 clips
the lessons use, whose bytes are verified by sha256 and whose frame rate and
unit are known.  Other trials are read at CMU's 120 fps in metres, checked
only by parsing them, and an :class:`UnverifiedDataWarning` says so once per
trial and process.

Where the files come from
-------------------------
1. **A local mirror** named by the environment variable ``MOCAPLAB_DATA_DIR``,
   laid out like the project's data folder (``bvh/<SS_TT>.bvh``,
   ``asfamc/<SS>/<SS>.asf``, ``asfamc/<SS>/<SS_TT>.amc``,
   ``pair_salsa_daz/<SS_TT>.bvh``).  Used with no network at all; it serves
   every trial it holds, registry or not.  A registry clip is read from its
   BVH (fast); another trial from its BVH if the mirror has one, else from
   its Acclaim pair; ``source="asfamc"`` reads the Acclaim pair.
2. **A web server**, when no mirror is set: the ASF/AMC pair is downloaded
   once with :mod:`pooch` into a user cache (``MOCAPLAB_CACHE_DIR`` or the
   OS cache folder) and read from there.  A download is written to a
   temporary file beside its cache name and renamed into place only when
   complete (:func:`mocaplab._atomic.atomic_write`), and one that grows past
   :data:`MAX_DOWNLOAD_BYTES` is stopped (:class:`DataError`): an interrupted
   or runaway download never leaves a cached file.  The files are fetched from
   ``{base}/{SS}/{SS}.asf`` and ``{base}/{SS}/{SS_TT}.amc``, the layout of
   the CMU site, where ``base`` is ``MOCAPLAB_CMU_URL`` (default
   :data:`DEFAULT_CMU_URL`, ``http://mocap.cs.cmu.edu/subjects``): a course
   can serve its own copy of those files from any web server.  Long
   downloads show pooch's progress bar when ``tqdm`` is installed.

Checking the bytes
------------------
Each call reads each file once, checks those bytes and parses the same
bytes; nothing is remembered between calls, so a file changed after a first
load is checked again.

* Registry clips: a BVH by the sha256 of its bytes; an Acclaim file by the
  sha256 of its text **after converting CRLF to LF** (the files CMU serves
  may differ from other copies only in their line endings, so pooch's own
  byte hash is not used).  The ASF of another trial is verified the same way
  when its subject has a registry clip (one skeleton file per subject).
* Other files: they must parse (:class:`~mocaplab.io.MocapFormatError`
  otherwise), and the warning above names them.
* A downloaded file that fails its check (hash or parse) is removed from the
  cache and fetched once more; if the new copy fails too it is removed as
  well and a :class:`DataError` names the file, its address and what was
  wrong.  Mirror files are never removed: a mismatch there is a
  :class:`DataError` naming the file.

A classroom mirror
------------------
``python -m mocaplab.data fetch --lessons DEST`` (:func:`fetch_mirror`)
downloads every clip the lessons use (:func:`lesson_clips`) into ``DEST``,
laid out for ``MOCAPLAB_DATA_DIR``, with a progress bar; each file is
verified by its registry sha256 before it is put in place, and files already
there and verified are skipped, so an interrupted run is resumed by running
it again.  The files come from ``--url`` (or ``MOCAPLAB_MIRROR_URL``), a web
folder holding such a mirror (a course server) or a local folder (a path or
a ``file://`` URL: a USB stick, a shared drive); without one, the ASF/AMC
files come from the CMU layout at ``MOCAPLAB_CMU_URL`` and the BVH files,
which the CMU site does not have, are reported missing.
``python -m mocaplab.data check DEST`` (:func:`check_mirror`) verifies a
mirror: it lists missing and bad files and exits with 1, or 0 when complete.

The data was obtained from mocap.cs.cmu.edu; the database was created with
funding from NSF EIA-0196217 (see :data:`ACKNOWLEDGMENT`).

Longer than 800 lines because the clip registry, the download cache and the local mirror share one checksum, naming and atomic-write discipline; split apart, each would have to repeat it.
"""

from __future__ import annotations

import hashlib
import importlib.util
import os
import re
import sys
import warnings
from collections.abc import Callable
from pathlib import Path
from typing import IO, Literal

from ._atomic import atomic_write, stale_temporaries
from ._registry import CLIPS, CMU_SUBJECTS, CMU_UNIT_M, CMU_URL
from .motion import Motion

__all__ = [
    "cmu",
    "clips",
    "describe",
    "mirror_dir",
    "download_base",
    "parse_trial",
    "DataError",
    "UnverifiedDataWarning",
    "ACKNOWLEDGMENT",
    "ENV_VAR",
    "CACHE_ENV_VAR",
    "URL_ENV_VAR",
    "DEFAULT_CMU_URL",
    "MIRROR_URL_ENV_VAR",
    "lesson_clips",
    "fetch_mirror",
    "check_mirror",
    "mirror_url",
    "MAX_DOWNLOAD_BYTES",
]

ENV_VAR = "MOCAPLAB_DATA_DIR"
CACHE_ENV_VAR = "MOCAPLAB_CACHE_DIR"
URL_ENV_VAR = "MOCAPLAB_CMU_URL"
MIRROR_URL_ENV_VAR = "MOCAPLAB_MIRROR_URL"
#: Where the CMU site serves ``<SS>/<SS>.asf`` and ``<SS>/<SS_TT>.amc``.
DEFAULT_CMU_URL = CMU_URL
#: The frame rate of the CMU captures, used for trials outside the registry.
CMU_FPS = 120.0
#: Largest file a download may bring, in bytes (64 MiB; the largest CMU file is a few MB).  A server that
#: sends more (a wrong address serving something else, a file that never ends) is cut off with a
#: :class:`DataError` before the disk fills.
MAX_DOWNLOAD_BYTES = 64 * 2**20
ACKNOWLEDGMENT = (
    "The data used in this project was obtained from mocap.cs.cmu.edu. "
    "The database was created with funding from NSF EIA-0196217."
)


class DataError(RuntimeError):
    """A clip could not be found, fetched or verified.

    Examples
    --------
    >>> import os
    >>> from unittest import mock
    >>> with mock.patch.dict(os.environ, {"MOCAPLAB_DATA_DIR": "/no/such/folder"}):
    ...     cmu("16_15")
    Traceback (most recent call last):
    ...
    mocaplab.data.DataError: MOCAPLAB_DATA_DIR=/no/such/folder is set but that folder does not exist. ...
    """


class UnverifiedDataWarning(UserWarning):
    """A clip was read from files that no registry hash vouches for (they were only parsed).

    Examples
    --------
    A registry clip is checked against its hash, so it loads without this
    warning even when the warning is an error:

    >>> import warnings
    >>> with warnings.catch_warnings():
    ...     warnings.simplefilter("error", UnverifiedDataWarning)
    ...     walk = cmu("16_15")
    >>> walk.name
    '16_15'
    """


def clips() -> list[str]:
    """Trial ids in the registry, e.g. ``['16_15', '02_01', ...]``.

    Returns
    -------
    list of str
        A new list, in registry order.

    Examples
    --------
    >>> clips()[:2], "16_15" in clips()
    (['16_15', '02_01'], True)
    """
    return list(CLIPS)


def describe(trial: str) -> dict[str, object]:
    """Registry entry of a clip (description, frames, fps, scale, files).

    Parameters
    ----------
    trial : str
        A registry trial id (:func:`clips`).

    Returns
    -------
    dict
        A copy of the entry: ``description``, ``frames``, ``fps``,
        ``scale`` (metres per file unit), the file names and their sha256.

    Raises
    ------
    KeyError
        For a trial that is not in the registry (:func:`cmu` still loads any
        CMU trial).

    Examples
    --------
    >>> entry = describe("16_15")
    >>> entry["fps"], entry["frames"]
    (120.0, 471)
    """
    try:
        return dict(CLIPS[trial])
    except KeyError:
        raise KeyError(
            f"CMU clip {trial!r} is not in the registry; registry clips are {clips()} "
            "(cmu() loads any other CMU trial, unverified)"
        ) from None


def parse_trial(trial: str) -> tuple[str, str]:
    """The subject folder and the trial id of a CMU trial id, checked.

    Parameters
    ----------
    trial : str
        ``"SS_TT"``: subject ``01`` to ``144`` (two digits, three from 100),
        trial number in two digits, ``01`` to ``99``.

    Returns
    -------
    subject : str
        As in the CMU paths, e.g. ``"02"`` or ``"127"``.
    trial : str

    Raises
    ------
    ValueError
        For any other string, with the padded form when that is what was meant.
    TypeError
        For a ``trial`` that is not a str.

    Examples
    --------
    >>> parse_trial("02_01")
    ('02', '02_01')
    """
    if not isinstance(trial, str):
        raise TypeError(f"Expected `trial` to be a str such as '16_15', got {type(trial).__name__}")
    m = re.fullmatch(r"([0-9]{1,3})_([0-9]{1,3})", trial)
    if m is not None:
        subject, number = int(m.group(1)), int(m.group(2))
        canonical = f"{subject:02d}_{number:02d}"
        if 1 <= subject <= CMU_SUBJECTS and 1 <= number <= 99:
            if canonical == trial:
                return m.group(1), trial
            hint = f"; did you mean {canonical!r}?"
        else:
            hint = f" (subject {subject} is not in 1..{CMU_SUBJECTS})" if not 1 <= subject <= CMU_SUBJECTS else ""
    else:
        hint = ""
    raise ValueError(
        f"Expected `trial` as 'SS_TT': a CMU subject from 01 to {CMU_SUBJECTS} and a two-digit trial number, "
        f"as CMU names its files (e.g. '16_15', '02_01', '127_04'), got {trial!r}{hint}"
    )


def mirror_dir() -> Path | None:
    """The local mirror folder from ``MOCAPLAB_DATA_DIR``, or None if unset.

    Returns
    -------
    Path or None
        The folder, ``~`` expanded (not checked to exist).

    Examples
    --------
    >>> import os
    >>> from pathlib import Path
    >>> from unittest import mock
    >>> with mock.patch.dict(os.environ, {"MOCAPLAB_DATA_DIR": "~/mocap"}):
    ...     mirror_dir() == Path.home() / "mocap"
    True
    """
    value = os.environ.get(ENV_VAR)
    return Path(value).expanduser() if value else None


def _existing_mirror() -> Path | None:
    """:func:`mirror_dir`, checked to be a folder (a mistyped path is not a layout problem)."""
    root = mirror_dir()
    try:
        missing = root is not None and not root.is_dir()
        what = "is a file, not a folder" if missing and root.exists() else "does not exist"  # type: ignore[union-attr]
    except OSError as exc:  # a name too long, a folder that may not be read, ...
        shown = str(root) if len(str(root)) <= 120 else f"{str(root)[:100]}... ({len(str(root))} characters)"
        raise DataError(
            f"{ENV_VAR}={shown} is set but that folder cannot be used ({exc.strerror or exc}). Set {ENV_VAR} to "
            f"the folder holding the mirror (bvh/, asfamc/<subject>/, pair_salsa_daz/), or unset it to download."
        ) from None
    if missing:
        raise DataError(
            f"{ENV_VAR}={root} is set but that folder {what}. Set {ENV_VAR} to the folder holding the "
            f"mirror (bvh/, asfamc/<subject>/, pair_salsa_daz/), or unset it to download the clips."
        )
    return root


def download_base() -> str:
    """Where trials are downloaded from: ``MOCAPLAB_CMU_URL``, default :data:`DEFAULT_CMU_URL` (no trailing ``/``).

    Returns
    -------
    str

    Raises
    ------
    DataError
        When the variable is set to something that is not a URL.

    Examples
    --------
    >>> import os
    >>> from unittest import mock
    >>> with mock.patch.dict(os.environ, {"MOCAPLAB_CMU_URL": "https://example.org/cmu/subjects/"}):
    ...     download_base()
    'https://example.org/cmu/subjects'
    """
    value = os.environ.get(URL_ENV_VAR, "").strip() or DEFAULT_CMU_URL
    if "://" not in value:
        raise DataError(
            f"{URL_ENV_VAR}={value!r} is not a URL; expected the address of a folder laid out like "
            f"{DEFAULT_CMU_URL} (<SS>/<SS>.asf, <SS>/<SS_TT>.amc), e.g. 'https://example.org/cmu/subjects'"
        )
    return value.rstrip("/")


def _sha256(raw: bytes, *, normalise_newlines: bool) -> str:
    return hashlib.sha256(raw.replace(b"\r\n", b"\n") if normalise_newlines else raw).hexdigest()


def _asf_sha256(subject: str) -> str | None:
    """The registry's hash of subject ``subject``'s ASF, if one of its clips is registered."""
    rel = f"asfamc/{subject}/{subject}.asf"
    return next((str(e["asf_sha256_lf"]) for e in CLIPS.values() if e.get("asf") == rel), None)


def _read(path: Path) -> bytes:
    try:
        return path.read_bytes()
    except OSError as exc:
        raise DataError(f"{path}: could not be read ({exc.strerror or exc})") from exc


def _mirror_file(root: Path, rel: str) -> Path:
    path = root / rel
    if not path.is_file():
        raise DataError(
            f"{ENV_VAR}={root} is set but {rel} is not in it. The mirror must be laid out like "
            "the project's data folder (bvh/, asfamc/<subject>/, pair_salsa_daz/)."
        )
    return path


def _verify(path: Path, raw: bytes, expected: str, *, normalise_newlines: bool) -> None:
    got = _sha256(raw, normalise_newlines=normalise_newlines)
    if got != expected:
        raise DataError(
            f"{path}: sha256 {got} does not match the registry's {expected}; the file is damaged or not the CMU "
            "clip (replace it with a good copy)"
        )


def _warn_unverified(trial: str, files: list[str]) -> None:
    # stacklevel=1: the warning's place is this line, so Python's default
    # filter shows it once per trial and process (not once per calling cell)
    warnings.warn(
        f"CMU trial {trial} is not in mocaplab's registry: {' and '.join(files)} "
        f"{'was' if len(files) == 1 else 'were'} checked only by parsing, not against a known sha256 "
        "(the registry's clips, data.clips(), are verified)",
        UnverifiedDataWarning,
        stacklevel=1,
    )


def cmu(trial: str, *, source: Literal["auto", "bvh", "asfamc"] = "auto") -> Motion:
    """Load a CMU trial as a :class:`~mocaplab.motion.Motion` in metres.

    Parameters
    ----------
    trial : str
        CMU trial id ``"SS_TT"``, e.g. ``"16_15"``: a registry clip (see
        :func:`clips`) or any other trial of the database (see the module
        notes and :func:`parse_trial`).
    source : {"auto", "bvh", "asfamc"}
        ``"auto"``: with a mirror, a registry clip's BVH, another trial's BVH
        if the mirror has it, else its ASF/AMC; without one, download the
        ASF/AMC.

    Returns
    -------
    Motion
        Named ``trial``.  Registry clips get the registry's frame rate and
        unit; other trials CMU's 120 fps and the ASF unit (a mirror BVH of
        another trial: the CMU unit, 1/0.45 inch, and its header's rate).

    Raises
    ------
    ValueError
        For a malformed trial id or ``source``.
    DataError
        For a clip that is not in the mirror, cannot be downloaded, fails its
        hash or does not parse (see the module notes).

    Warns
    -----
    UnverifiedDataWarning
        For a trial outside the registry, once per trial and process.

    Notes
    -----
    The salsa pair (``"60_10"``, ``"61_10"``) exists in the registry only as
    BVH in the mirror (a third-party conversion with another skeleton, in
    centimetres); its header says 120 fps but the clips are 60 fps, which is
    what is used, and its artificial T-pose frame 0 is dropped.

    Examples
    --------
    >>> walk = cmu("16_15")
    >>> walk.name, walk.n_frames, walk.fps, walk.n_joints
    ('16_15', 471, 120.0, 31)
    """
    subject, trial = parse_trial(trial)
    if source not in ("auto", "bvh", "asfamc"):
        raise ValueError(f"Expected source 'auto', 'bvh' or 'asfamc', got {source!r}")
    entry = CLIPS.get(trial)
    root = _existing_mirror()
    is_pair = entry is not None and "asf" not in entry
    if source == "auto":
        if root is None:
            source = "bvh" if is_pair else "asfamc"
        elif entry is not None:
            source = "bvh"
        elif (root / "bvh" / f"{trial}.bvh").is_file():
            source = "bvh"
        elif (root / "asfamc" / subject / f"{trial}.amc").is_file():
            source = "asfamc"
        else:
            raise DataError(
                f"{ENV_VAR}={root} is set but trial {trial} is not in it: neither bvh/{trial}.bvh nor "
                f"asfamc/{subject}/{trial}.amc (with asfamc/{subject}/{subject}.asf). Add the files, or unset "
                f"{ENV_VAR} to download the trial from {download_base()}."
            )
    if source == "bvh":
        if root is None:
            raise DataError(
                f"Clip {trial} as BVH needs a local mirror: set {ENV_VAR} to a folder laid out like the "
                "project's data folder (see the README, 'Data'), or use source='asfamc' to download "
                f"the original files from {download_base()}."
            )
        return _mirror_bvh(root, trial, entry)
    if is_pair:
        raise DataError(f"Clip {trial} has no ASF/AMC files in the registry; use source='bvh' with a mirror")
    if root is not None:
        return _mirror_acclaim(root, subject, trial, entry)
    return _download_acclaim(subject, trial, entry)


def _mirror_bvh(root: Path, trial: str, entry: dict[str, object] | None) -> Motion:
    from .io import MocapFormatError, load
    from .io.bvh import load_bvh_bytes

    if entry is None:
        path = _mirror_file(root, f"bvh/{trial}.bvh")
        try:
            motion = load(path, scale=CMU_UNIT_M, name=trial)  # the mirror's bvh/ is in CMU units
        except MocapFormatError as err:
            raise DataError(f"{path}: trial {trial} in the mirror is not a readable BVH file ({err})") from err
        _warn_unverified(trial, [f"bvh/{trial}.bvh"])
        return motion
    path = _mirror_file(root, str(entry["bvh"]))
    raw = _read(path)
    _verify(path, raw, str(entry["bvh_sha256"]), normalise_newlines=False)
    motion = load_bvh_bytes(raw, str(path), scale=float(entry["scale"]), name=trial)  # type: ignore[arg-type]
    if "asf" not in entry:  # the salsa pair: drop the artificial T-pose frame
        motion = motion[1:]
    # the registry's rate: BVH headers round it (0.008333333 s) or get it wrong (salsa)
    return motion.replace(fps=float(entry["fps"]))  # type: ignore[arg-type]


def _acclaim_hashes(subject: str, entry: dict[str, object] | None) -> dict[str, str | None]:
    return {
        "asf": _asf_sha256(subject),
        "amc": None if entry is None else str(entry["amc_sha256_lf"]),
    }


def _mirror_acclaim(root: Path, subject: str, trial: str, entry: dict[str, object] | None) -> Motion:
    from .io import MocapFormatError
    from .io.asfamc import load_asf_amc_bytes

    rel = {"asf": f"asfamc/{subject}/{subject}.asf", "amc": f"asfamc/{subject}/{trial}.amc"}
    paths = {k: _mirror_file(root, r) for k, r in rel.items()}
    raws = {k: _read(p) for k, p in paths.items()}
    expected = _acclaim_hashes(subject, entry)
    for k, digest in expected.items():
        if digest is not None:
            _verify(paths[k], raws[k], digest, normalise_newlines=True)
    fps = CMU_FPS if entry is None else float(entry["fps"])  # type: ignore[arg-type]
    try:
        motion = load_asf_amc_bytes(raws["asf"], str(paths["asf"]), raws["amc"], str(paths["amc"]), name=trial, fps=fps)
    except MocapFormatError as err:
        raise DataError(f"{err.path}: trial {trial} in the mirror does not parse ({err})") from err
    unverified = [rel[k] for k, digest in expected.items() if digest is None]
    if unverified:
        _warn_unverified(trial, unverified)
    return motion


def _cache_dir(subject: str) -> Path:
    import pooch

    return Path(os.environ.get(CACHE_ENV_VAR) or pooch.os_cache("mocaplab")) / subject


def _progressbar() -> bool:
    """Whether pooch can show a progress bar: it needs ``tqdm``, an optional package."""
    return importlib.util.find_spec("tqdm") is not None


class _Capped:
    """The file object a download writes to: stops it past :data:`MAX_DOWNLOAD_BYTES`, keeps its bytes."""

    def __init__(self, fh: IO[bytes], url: str) -> None:
        self._fh = fh
        self._url = url
        self._size = 0
        self.chunks: list[bytes] = []

    def write(self, chunk: bytes) -> int:
        self._size += len(chunk)
        if self._size > MAX_DOWNLOAD_BYTES:
            raise DataError(
                f"{self._url} sent more than MAX_DOWNLOAD_BYTES = {MAX_DOWNLOAD_BYTES} bytes "
                f"({MAX_DOWNLOAD_BYTES / 2**20:g} MiB), far more than a motion capture file: the download was "
                "stopped and nothing was kept. Check the address (a server answering with something else), or "
                "raise mocaplab.data.MAX_DOWNLOAD_BYTES for a genuinely larger file."
            )
        self.chunks.append(chunk)
        return self._fh.write(chunk)

    def flush(self) -> None:
        self._fh.flush()


def _download(url: str, target: Path, *, progressbar: bool = False, check: Callable[[bytes], None] | None = None) -> None:
    """Download ``url`` to ``target``: whole or not at all, at most :data:`MAX_DOWNLOAD_BYTES`.

    The bytes go to a temporary file beside ``target`` (:func:`atomic_write`);
    ``check(raw)`` may raise to reject them, which leaves ``target`` as it was.
    """
    import pooch

    target.parent.mkdir(parents=True, exist_ok=True)
    with atomic_write(target) as fh:
        out = _Capped(fh, url)
        pooch.HTTPDownloader(progressbar=progressbar, timeout=60)(url, out, None)
        if check is not None:
            check(b"".join(out.chunks))


def _retrieve(url: str, folder: Path, trial: str) -> Path:
    """The cached copy of ``url`` in ``folder``, downloaded first if it is not there."""
    from pooch.utils import unique_file_name

    path = folder / unique_file_name(url)  # pooch's cache names: caches filled by pooch.retrieve stay valid
    if path.is_file():
        return path
    try:
        _download(url, path, progressbar=_progressbar())
    except DataError:
        raise
    except Exception as exc:
        known = (
            "" if trial in CLIPS else f" Is {trial} a CMU trial? The trials of a subject are listed on the CMU site."
        )
        raise DataError(
            f"Could not download {url} ({exc}).{known} Without a network, set {ENV_VAR} to a local "
            f"mirror of the clips (see the README, 'Data'); to use another server, set {URL_ENV_VAR}."
        ) from exc
    return path


def _remove(path: Path) -> str:
    """Delete a cached file; says how that went, for error messages."""
    try:
        path.unlink()
    except FileNotFoundError:
        return "removed"
    except OSError as exc:
        return f"could not be removed ({exc.strerror or exc}): delete it by hand"
    return "removed"


def _download_acclaim(subject: str, trial: str, entry: dict[str, object] | None) -> Motion:
    try:
        import pooch  # noqa: F401
    except ImportError:  # pragma: no cover - pooch is a declared dependency
        raise DataError("Downloading CMU clips needs the 'pooch' package: pip install pooch") from None
    from .io import MocapFormatError
    from .io.asfamc import load_asf_amc_bytes

    base = download_base()
    urls = {"asf": f"{base}/{subject}/{subject}.asf", "amc": f"{base}/{subject}/{trial}.amc"}
    names = {"asf": f"{subject}.asf", "amc": f"{trial}.amc"}
    expected = _acclaim_hashes(subject, entry)
    fps = CMU_FPS if entry is None else float(entry["fps"])  # type: ignore[arg-type]
    folder = _cache_dir(subject)
    fetched_again: set[str] = set()
    while True:
        paths = {k: _retrieve(url, folder, trial) for k, url in urls.items()}
        raws = {k: _read(p) for k, p in paths.items()}
        problem: tuple[str, str] | None = None
        for k, digest in expected.items():
            if digest is None:
                continue
            got = _sha256(raws[k], normalise_newlines=True)
            if got != digest:
                problem = (k, f"its sha256 (of the text with LF line endings) is {got}, not the registry's {digest}")
                break
        if problem is None:
            try:
                motion = load_asf_amc_bytes(
                    raws["asf"], str(paths["asf"]), raws["amc"], str(paths["amc"]), name=trial, fps=fps
                )
            except MocapFormatError as err:
                k = "asf" if err.path == str(paths["asf"]) else "amc"
                problem = (k, f"it does not parse ({err})")
            else:
                unverified = [names[k] for k, digest in expected.items() if digest is None]
                if unverified:
                    _warn_unverified(trial, unverified)
                return motion
        k, why = problem
        removed = _remove(paths[k])
        if k in fetched_again:
            raise DataError(
                f"{paths[k]}: {names[k]} downloaded from {urls[k]} failed its check: {why}. The cached copy failed "
                f"first, was removed and downloaded again, and the new copy fails too; it was {removed}. The server "
                f"holds a damaged or different file: check {URL_ENV_VAR} (now {base!r}) or try again later."
            )
        fetched_again.add(k)


# ----------------------------------------------------------- a classroom mirror


def lesson_clips() -> list[str]:
    """The trials the lessons use: the registry (:func:`clips`), the one list of them.

    ``tests/test_data.py`` scans the lesson notebooks for trial ids and
    checks that every one is in the registry.

    Returns
    -------
    list of str

    Examples
    --------
    >>> lesson_clips() == clips()
    True
    """
    return clips()


def _mirror_files(trials: list[str]) -> list[tuple[str, str, str | None, bool]]:
    """The files of ``trials`` in a mirror: ``(trial, rel, sha256, newlines_normalised)``, each file once.

    A registry clip has its BVH and (CMU clips) its ASF/AMC pair, all with
    the registry's sha256; another trial its ASF/AMC pair, the ASF with the
    registry's hash when its subject has a registry clip, else None (checked
    by parsing).
    """
    files: dict[str, tuple[str, str, str | None, bool]] = {}
    for trial in trials:
        subject, trial = parse_trial(trial)
        entry = CLIPS.get(trial)
        if entry is not None:
            files.setdefault(str(entry["bvh"]), (trial, str(entry["bvh"]), str(entry["bvh_sha256"]), False))
        if entry is None or "asf" in entry:
            expected = _acclaim_hashes(subject, entry)
            for k, rel in (("asf", f"asfamc/{subject}/{subject}.asf"), ("amc", f"asfamc/{subject}/{trial}.amc")):
                files.setdefault(rel, (trial, rel, expected[k], True))
    return list(files.values())


def _file_problem(root: Path, trial: str, rel: str, digest: str | None, lf: bool) -> str | None:
    """What is wrong with ``root/rel`` (None when it is there and verified)."""
    path = root / rel
    if not path.is_file():
        return "missing"
    try:
        raw = path.read_bytes()
    except OSError as exc:
        return f"cannot be read ({exc.strerror or exc})"
    return _bytes_problem(root, trial, rel, raw, digest, lf)


def _bytes_problem(root: Path, trial: str, rel: str, raw: bytes, digest: str | None, lf: bool) -> str | None:
    """What is wrong with ``raw`` as the mirror's ``rel`` (None when verified); an AMC is parsed with ``root``'s ASF."""
    path = root / rel
    if digest is not None:
        got = _sha256(raw, normalise_newlines=lf)
        return None if got == digest else f"sha256 {got} is not the registry's {digest}"
    if rel.endswith(".asf"):
        return None  # checked with each of its trials' AMC below
    subject = rel.split("/")[1]
    asf = root / f"asfamc/{subject}/{subject}.asf"
    if not asf.is_file():
        return f"cannot be checked: asfamc/{subject}/{subject}.asf is missing"
    from .io import MocapFormatError
    from .io.asfamc import load_asf_amc_bytes

    try:
        load_asf_amc_bytes(asf.read_bytes(), str(asf), raw, str(path), name=trial, fps=CMU_FPS)
    except (MocapFormatError, OSError) as err:
        return f"does not parse ({err})"
    return None


def check_mirror(dest: str | os.PathLike[str], trials: list[str] | None = None) -> dict[str, str]:
    """Verify a mirror folder: the files of ``trials`` (default :func:`lesson_clips`) that are missing or bad.

    Parameters
    ----------
    dest : path
        A folder laid out for ``MOCAPLAB_DATA_DIR``.
    trials : list of str, optional
        Trial ids (registry clips are checked by sha256, other trials by
        parsing their ASF/AMC pair).

    Returns
    -------
    dict of str to str
        Each missing or bad file (relative to ``dest``) and what is wrong;
        empty for a good mirror.

    Examples
    --------
    >>> import tempfile
    >>> with tempfile.TemporaryDirectory() as empty:
    ...     sorted(check_mirror(empty, ["02_01"]))
    ['asfamc/02/02.asf', 'asfamc/02/02_01.amc', 'bvh/02_01.bvh']
    """
    root = Path(dest)
    problems = {}
    for trial, rel, digest, lf in _mirror_files(lesson_clips() if trials is None else list(trials)):
        problem = _file_problem(root, trial, rel, digest, lf)
        if problem is not None:
            problems[rel] = problem
    return problems


def mirror_url() -> str | None:
    """A web folder holding a whole mirror (``MOCAPLAB_MIRROR_URL``), or None (no trailing ``/``).

    Returns
    -------
    str or None

    Examples
    --------
    >>> import os
    >>> from unittest import mock
    >>> with mock.patch.dict(os.environ, {"MOCAPLAB_MIRROR_URL": "https://example.org/mocap/"}):
    ...     mirror_url()
    'https://example.org/mocap'
    """
    value = os.environ.get(MIRROR_URL_ENV_VAR, "").strip()
    return value.rstrip("/") or None


def _source_url(rel: str, base: str | None) -> str | None:
    """Where a mirror file is fetched from: ``base/rel``; without ``base``, an Acclaim file from the CMU layout."""
    if base is not None:
        return f"{base}/{rel}"
    if rel.startswith("asfamc/"):
        _, subject, name = rel.split("/")
        return f"{download_base()}/{subject}/{name}"
    return None  # BVH files are not on the CMU site


def _local_folder(base: str | None) -> Path | None:
    """The folder a mirror source names when it is local (a path or a ``file://`` URL), else None.

    Raises
    ------
    DataError
        When it names a local folder that does not exist.
    """
    if base is None:
        return None
    if base.startswith("file://"):
        from urllib.parse import unquote, urlparse
        from urllib.request import url2pathname

        folder = Path(url2pathname(unquote(urlparse(base).path)))
    elif "://" in base:
        return None
    else:
        folder = Path(base).expanduser()
    if not folder.is_dir():
        raise DataError(
            f"--url {base!r} names a local folder that does not exist; expected a folder laid out like a mirror "
            "(bvh/, asfamc/<subject>/, pair_salsa_daz/) or a web address (http:// or https://)"
        )
    return folder


def _copy_local(source: Path, target: Path, *, check: Callable[[bytes], None]) -> None:
    """Copy ``source`` to ``target`` like :func:`_download` does: checked first, then written whole or not at all."""
    raw = _read(source)
    check(raw)
    target.parent.mkdir(parents=True, exist_ok=True)
    with atomic_write(target) as fh:
        fh.write(raw)


class _Rejected(Exception):
    """A downloaded mirror file failed its check (the message says how); the download is discarded."""


def fetch_mirror(
    dest: str | os.PathLike[str],
    trials: list[str] | None = None,
    *,
    url: str | None = None,
    progress: bool = True,
) -> dict[str, str]:
    """Download the files of ``trials`` (default :func:`lesson_clips`) into a mirror folder ``dest``.

    The folder is laid out for ``MOCAPLAB_DATA_DIR`` (``bvh/<SS_TT>.bvh``,
    ``asfamc/<SS>/<SS>.asf``, ``asfamc/<SS>/<SS_TT>.amc``,
    ``pair_salsa_daz/<SS_TT>.bvh``).  Resumable: a file already there and
    verified is not downloaded again.  Each file is downloaded (with pooch,
    at most :data:`MAX_DOWNLOAD_BYTES`) to a temporary file beside its name,
    verified like :func:`check_mirror` does, synced to disk and only then
    renamed into place (:func:`mocaplab._atomic.atomic_write`), so an
    interrupted or damaged download never counts and a good file already
    there is never lost.  Temporary files left by an interrupted run are
    removed (do not run two fetches into one folder at once).

    Parameters
    ----------
    dest : path
        The mirror folder (created if needed).
    trials : list of str, optional
        Trial ids; default the lessons' clips.
    url : str, optional
        A web folder holding a mirror of the same layout (a course server),
        or a local folder (a path or a ``file://`` URL: a USB stick, a shared
        drive); default ``MOCAPLAB_MIRROR_URL``.  Without one, the ASF/AMC files come
        from ``MOCAPLAB_CMU_URL`` (default the CMU site), which has no BVH
        files: those are then reported as not fetched.
    progress : bool
        Show a progress bar (tqdm, on stderr) over the files.

    Returns
    -------
    dict of str to str
        Each file that could not be fetched or verified and why; empty when
        the mirror is complete.

    Raises
    ------
    DataError
        When ``url`` names a local folder that does not exist.

    Examples
    --------
    Copy one clip from a local mirror (here the one ``MOCAPLAB_DATA_DIR``
    names) into a new folder:

    >>> import os, tempfile
    >>> with tempfile.TemporaryDirectory() as dest:
    ...     problems = fetch_mirror(dest, ["16_15"], url=str(mirror_dir()), progress=False)
    ...     problems, sorted(os.listdir(dest)), check_mirror(dest, ["16_15"])
    ({}, ['asfamc', 'bvh'], {})
    """
    from tqdm.auto import tqdm

    root = Path(dest)
    base = (url.rstrip("/") or None) if url is not None else mirror_url()
    local = _local_folder(base)
    files = _mirror_files(lesson_clips() if trials is None else list(trials))
    problems: dict[str, str] = {}
    bar = tqdm(total=len(files), unit="file", desc="mocaplab data", disable=not progress)
    try:
        for trial, rel, digest, lf in files:
            bar.set_postfix_str(rel, refresh=False)
            if _file_problem(root, trial, rel, digest, lf) is None:
                bar.update(1)
                continue
            source = str(local / rel) if local is not None else _source_url(rel, base)
            if source is None:
                problems[rel] = f"not on the CMU site; give a course server holding a mirror ({MIRROR_URL_ENV_VAR})"
                bar.update(1)
                continue
            target = root / rel
            for stale in [*stale_temporaries(target), str(target) + ".part"]:  # .part: left by earlier versions
                Path(stale).unlink(missing_ok=True)

            def check(raw: bytes, trial: str = trial, rel: str = rel, digest: str | None = digest, lf: bool = lf):
                problem = _bytes_problem(root, trial, rel, raw, digest, lf)
                if problem is not None:
                    raise _Rejected(problem)

            try:
                if local is None:
                    _download(source, target, check=check)
                elif not Path(source).is_file():
                    problems[rel] = f"not in {local}"
                else:
                    _copy_local(Path(source), target, check=check)
            except _Rejected as rejected:
                problems[rel] = f"{'downloaded' if local is None else 'copied'} from {source}, but it {rejected}"
            except Exception as exc:  # noqa: BLE001 - reported per file
                problems[rel] = f"could not {'download' if local is None else 'copy'} {source} ({exc})"
            bar.update(1)
    finally:
        bar.close()
    return problems


def main(argv: list[str] | None = None) -> int:
    """``python -m mocaplab.data fetch|check``: build or verify a classroom mirror (exit code 0 when complete)."""
    import argparse

    parser = argparse.ArgumentParser(
        prog="python -m mocaplab.data",
        description="Download the CMU clips the lessons use into a folder for MOCAPLAB_DATA_DIR, or verify one.",
    )
    sub = parser.add_subparsers(dest="command", required=True)
    for name, text in (("fetch", "download into DEST (resumable)"), ("check", "verify the files in DEST")):
        p = sub.add_parser(name, help=text, description=text)
        p.add_argument("dest", metavar="DEST", help="the mirror folder")
        p.add_argument("trials", nargs="*", metavar="TRIAL", help="CMU trial ids such as 16_15 (default: --lessons)")
        p.add_argument("--lessons", action="store_true", help="every clip the lessons use (the default)")
        if name == "fetch":
            p.add_argument(
                "--url",
                help=f"a web folder or a local folder holding a mirror of the same layout (default "
                f"${MIRROR_URL_ENV_VAR}; without one, "
                f"ASF/AMC files from ${URL_ENV_VAR} or the CMU site)",
            )
            p.add_argument("--no-progress", action="store_true", help="no progress bar")
    args = parser.parse_args(argv)
    trials = list(args.trials)
    if args.lessons or not trials:
        trials = [*lesson_clips(), *(t for t in trials if t not in CLIPS)]
    try:
        if args.command == "fetch":
            problems = fetch_mirror(args.dest, trials, url=args.url, progress=not args.no_progress)
        else:
            problems = check_mirror(args.dest, trials)
    except (ValueError, DataError) as err:
        print(f"error: {err}", file=sys.stderr)
        return 2
    n = len(_mirror_files(trials))
    if problems:
        for rel, why in problems.items():
            print(f"{'missing' if why == 'missing' else 'bad'}: {rel}: {why}")
        print(f"{len(problems)} of {n} files missing or bad in {args.dest}")
        return 1
    print(f"ok: {n} files of {len(trials)} trials verified in {args.dest}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
