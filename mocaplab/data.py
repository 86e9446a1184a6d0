"""CMU Graphics Lab motion capture clips, by trial id.

>>> walk = cmu("16_15")            # doctest: +SKIP

Where the files come from
-------------------------
1. **A local mirror** named by the environment variable ``MOCAPLAB_DATA_DIR``,
   laid out like the project's data folder (``bvh/<SS_TT>.bvh``,
   ``asfamc/<SS>/<SS>.asf``, ``asfamc/<SS>/<SS_TT>.amc``,
   ``pair_salsa_daz/<SS_TT>.bvh``).  Used with no network at all.  The BVH
   files are read (fast); set ``source="asfamc"`` to read the Acclaim pair.
2. **The CMU site**, when no mirror is set: the original ASF/AMC files are
   downloaded once with :mod:`pooch` into a user cache
   (``MOCAPLAB_CACHE_DIR`` or the OS cache folder) and read from there.

Checking the bytes
------------------
Mirror BVH files are checked against the sha256 recorded in the registry.
The Acclaim files served by CMU may differ from other copies only in their
line endings (CRLF versus LF), so a downloaded or mirrored ASF/AMC file is
checked by the sha256 of its text **after converting CRLF to LF**; pooch's
own byte hash is not used for them.  A mismatch raises :class:`DataError`.

The data was obtained from mocap.cs.cmu.edu; the database was created with
funding from NSF EIA-0196217 (see :data:`ACKNOWLEDGMENT`).
"""

from __future__ import annotations

import hashlib
import os
from pathlib import Path
from typing import Literal

from ._registry import CLIPS
from .motion import Motion

__all__ = ["cmu", "clips", "describe", "mirror_dir", "DataError", "ACKNOWLEDGMENT", "ENV_VAR"]

ENV_VAR = "MOCAPLAB_DATA_DIR"
CACHE_ENV_VAR = "MOCAPLAB_CACHE_DIR"
ACKNOWLEDGMENT = (
    "The data used in this project was obtained from mocap.cs.cmu.edu. "
    "The database was created with funding from NSF EIA-0196217."
)

_verified: set[str] = set()


class DataError(RuntimeError):
    """A clip could not be found, fetched or verified."""


def clips() -> list[str]:
    """Trial ids in the registry, e.g. ``['16_15', '02_01', ...]``."""
    return list(CLIPS)


def describe(trial: str) -> dict[str, object]:
    """Registry entry of a clip (description, frames, fps, scale, files)."""
    return dict(_entry(trial))


def _entry(trial: str) -> dict[str, object]:
    try:
        return CLIPS[trial]
    except KeyError:
        raise KeyError(f"Unknown CMU clip {trial!r}; known clips are {clips()}") from None


def mirror_dir() -> Path | None:
    """The local mirror folder from ``MOCAPLAB_DATA_DIR``, or None if unset."""
    value = os.environ.get(ENV_VAR)
    return Path(value).expanduser() if value else None


def _sha256(data: bytes) -> str:
    return hashlib.sha256(data).hexdigest()


def _check(path: Path, expected: str, *, normalise_newlines: bool) -> None:
    key = f"{path}:{expected}"
    if key in _verified:
        return
    data = path.read_bytes()
    if normalise_newlines:
        data = data.replace(b"\r\n", b"\n")
    got = _sha256(data)
    if got != expected:
        raise DataError(f"{path}: sha256 {got} does not match the registry's {expected}; the file is damaged or not the CMU clip")
    _verified.add(key)


def _mirror_file(root: Path, rel: str) -> Path:
    path = root / rel
    if not path.is_file():
        raise DataError(
            f"{ENV_VAR}={root} is set but {rel} is not in it. The mirror must be laid out like "
            "the project's data folder (bvh/, asfamc/<subject>/, pair_salsa_daz/)."
        )
    return path


def _download(url: str, expected_lf: str) -> Path:
    try:
        import pooch
    except ImportError:  # pragma: no cover - pooch is a declared dependency
        raise DataError("Downloading CMU clips needs the 'pooch' package: pip install pooch") from None
    cache = os.environ.get(CACHE_ENV_VAR) or pooch.os_cache("mocaplab")
    subject = url.rstrip("/").split("/")[-2]
    try:
        fname = pooch.retrieve(url, known_hash=None, path=Path(cache) / subject, progressbar=False)
    except Exception as exc:
        raise DataError(
            f"Could not download {url} ({exc}). Without a network, set {ENV_VAR} to a local "
            "mirror of the clips (see the README, 'Data')."
        ) from exc
    path = Path(fname)
    _check(path, expected_lf, normalise_newlines=True)
    return path


def cmu(trial: str, *, source: Literal["auto", "bvh", "asfamc"] = "auto") -> Motion:
    """Load a CMU clip as a :class:`~mocaplab.motion.Motion` in metres.

    Parameters
    ----------
    trial : str
        CMU trial id ``"<subject>_<trial>"``, e.g. ``"16_15"`` (see :func:`clips`).
    source : {"auto", "bvh", "asfamc"}
        ``"auto"`` reads the mirror's BVH when a mirror is set and downloads
        the ASF/AMC otherwise.

    Notes
    -----
    Frame rate and units come from the registry (metres; 120 fps for the
    CMU clips).  The salsa pair (``"60_10"``, ``"61_10"``) exists only as BVH in the mirror
    (a third-party conversion with another skeleton, in centimetres); its
    header says 120 fps but the clips are 60 fps, which is what is used, and
    its artificial T-pose frame 0 is dropped.
    """
    entry = _entry(trial)
    root = mirror_dir()
    is_pair = "asf" not in entry
    if source == "auto":
        source = "bvh" if (root is not None or is_pair) else "asfamc"
    if source not in ("bvh", "asfamc"):
        raise ValueError(f"Expected source 'auto', 'bvh' or 'asfamc', got {source!r}")
    from . import io

    if source == "bvh":
        if root is None:
            raise DataError(
                f"Clip {trial} as BVH needs a local mirror: set {ENV_VAR} to a folder laid out like the "
                "project's data folder (see the README, 'Data'), or use source='asfamc' to download "
                "the original files from mocap.cs.cmu.edu."
            )
        path = _mirror_file(root, str(entry["bvh"]))
        _check(path, str(entry["bvh_sha256"]), normalise_newlines=False)
        motion = io.load_bvh(path, scale=float(entry["scale"]), name=trial)  # type: ignore[arg-type]
        if is_pair:
            motion = motion[1:]
        # the registry's rate: BVH headers round it (0.008333333 s) or get it wrong (salsa)
        return motion.replace(fps=float(entry["fps"]))  # type: ignore[arg-type]
    if is_pair:
        raise DataError(f"Clip {trial} has no ASF/AMC files in the registry; use source='bvh' with a mirror")
    if root is not None:
        asf = _mirror_file(root, str(entry["asf"]))
        amc = _mirror_file(root, str(entry["amc"]))
        _check(asf, str(entry["asf_sha256_lf"]), normalise_newlines=True)
        _check(amc, str(entry["amc_sha256_lf"]), normalise_newlines=True)
    else:
        asf = _download(str(entry["asf_url"]), str(entry["asf_sha256_lf"]))
        amc = _download(str(entry["amc_url"]), str(entry["amc_sha256_lf"]))
    return io.load_asf_amc(asf, amc, name=trial, fps=float(entry["fps"]))  # type: ignore[arg-type]
