"""The CMU clip registry, the local mirror, hash checks and error messages."""

from __future__ import annotations

import functools
import hashlib
import importlib.machinery
import os
import re
import shutil
import sys
import threading
import types
import warnings
from http.server import SimpleHTTPRequestHandler, ThreadingHTTPServer
from pathlib import Path

import numpy as np
import pytest

from mocaplab import data
from mocaplab.io import load_asf_amc, load_bvh

CMU_UNIT = 0.0254 / 0.45


def copy_into(mirror: Path, root: Path, rel: str, transform=None) -> Path:
    """Copy one mirror file into a temporary mirror (optionally changing its bytes)."""
    dst = root / rel
    dst.parent.mkdir(parents=True, exist_ok=True)
    raw = (mirror / rel).read_bytes()
    dst.write_bytes(transform(raw) if transform else raw)
    return dst


def test_registry_lists_the_clips():
    clips = data.clips()
    for trial in ("16_15", "02_01", "16_35", "49_03", "02_06", "05_02", "60_10", "61_10"):
        assert trial in clips
    entry = data.describe("49_03")
    assert entry["frames"] == 1504 and entry["fps"] == 120.0
    assert entry["scale"] == pytest.approx(CMU_UNIT)
    assert entry["bvh"] == "bvh/49_03.bvh" and len(str(entry["bvh_sha256"])) == 64
    assert str(entry["asf_url"]).startswith("http://mocap.cs.cmu.edu/")
    assert data.describe("60_10")["fps"] == 60.0 and "asf" not in data.describe("60_10")
    entry["frames"] = -1  # describe returns a copy
    assert data.describe("49_03")["frames"] == 1504


def test_describe_knows_only_the_registry():
    with pytest.raises(KeyError, match=r"CMU clip '35_01' is not in the registry; registry clips are \['16_15'"):
        data.describe("35_01")


def test_bad_source(mocap_dir):
    with pytest.raises(ValueError, match="Expected source 'auto', 'bvh' or 'asfamc', got 'c3d'"):
        data.cmu("16_15", source="c3d")  # type: ignore[arg-type]


def test_acknowledgment():
    assert "mocap.cs.cmu.edu" in data.ACKNOWLEDGMENT and "NSF EIA-0196217" in data.ACKNOWLEDGMENT


def test_cmu_returns_metres_and_registry_fps(mocap_dir, cmu):
    m = cmu("16_15")
    entry = data.describe("16_15")
    assert m.name == "16_15" and m.fps == 120.0 and m.n_frames == entry["frames"]
    raw = load_bvh(mocap_dir / "bvh" / "16_15.bvh", scale=1.0)
    assert np.allclose(m.skeleton.offsets, raw.skeleton.offsets * CMU_UNIT)
    assert np.allclose(m.root_positions, raw.root_positions * CMU_UNIT)
    # a person in metres: head 1.4-2.0 m above the lowest toe
    pos = m.global_positions()
    head = pos[:, m.skeleton.index("Head")]
    toe = pos[:, [m.skeleton.index("LeftToeBase"), m.skeleton.index("RightToeBase")], 1].min()
    assert 1.4 < np.median(head[:, 1] - toe) < 2.0
    assert m.skeleton.names[:3] == ("Hips", "LHipJoint", "LeftUpLeg") and m.n_joints == 31


def test_salsa_drops_frame_zero_and_runs_at_60_fps(mocap_dir, cmu):
    m = cmu("60_10")
    raw = load_bvh(mocap_dir / "pair_salsa_daz" / "60_10.bvh", scale=0.01)
    assert m.fps == 60.0 and raw.fps == pytest.approx(120.0, rel=1e-4)
    assert m.n_frames == raw.n_frames - 1
    assert np.allclose(m.rotations, raw.rotations[1:]) and np.allclose(m.root_positions, raw.root_positions[1:])
    assert m.n_joints == 43


def test_cmu_from_asfamc_agrees_with_bvh(mocap_dir, cmu):
    acclaim = data.cmu("16_35", source="asfamc")
    bvh = cmu("16_35")
    assert acclaim.skeleton.names[:3] == ("root", "lhipjoint", "lfemur")
    assert np.abs(acclaim.global_positions() - bvh.global_positions()).max() < 1e-3
    with pytest.raises(data.DataError, match="Clip 60_10 has no ASF/AMC files in the registry"):
        data.cmu("60_10", source="asfamc")


def test_tampered_mirror_file_is_rejected(mocap_dir, tmp_path, monkeypatch):
    def flip_one_digit(raw: bytes) -> bytes:
        i = raw.rindex(b"1")
        return raw[:i] + b"2" + raw[i + 1 :]

    copy_into(mocap_dir, tmp_path, "bvh/16_35.bvh", flip_one_digit)
    monkeypatch.setenv(data.ENV_VAR, str(tmp_path))
    with pytest.raises(data.DataError, match=r"16_35.bvh: sha256 [0-9a-f]{64} does not match the registry's"):
        data.cmu("16_35")


def test_tampered_acclaim_file_is_rejected(mocap_dir, tmp_path, monkeypatch):
    copy_into(mocap_dir, tmp_path, "asfamc/16/16.asf", lambda raw: raw.replace(b"length 0.45", b"length 0.46"))
    copy_into(mocap_dir, tmp_path, "asfamc/16/16_35.amc")
    monkeypatch.setenv(data.ENV_VAR, str(tmp_path))
    with pytest.raises(data.DataError, match="16.asf: sha256 .* does not match"):
        data.cmu("16_35", source="asfamc")


def test_acclaim_hash_ignores_line_endings(mocap_dir, tmp_path, monkeypatch):
    """CMU serves CRLF files; the mirror may hold LF copies: both verify."""
    crlf = lambda raw: raw.replace(b"\r\n", b"\n").replace(b"\n", b"\r\n")  # noqa: E731
    copy_into(mocap_dir, tmp_path, "asfamc/16/16.asf", crlf)
    copy_into(mocap_dir, tmp_path, "asfamc/16/16_35.amc", crlf)
    monkeypatch.setenv(data.ENV_VAR, str(tmp_path))
    m = data.cmu("16_35", source="asfamc")
    assert m.n_frames == data.describe("16_35")["frames"]


def test_mirror_without_the_file(tmp_path, monkeypatch):
    monkeypatch.setenv(data.ENV_VAR, str(tmp_path))
    with pytest.raises(data.DataError, match=r"MOCAPLAB_DATA_DIR=.* is set but bvh/16_15.bvh is not in it"):
        data.cmu("16_15")


def test_a_mirror_folder_that_does_not_exist_is_named_as_such(tmp_path, monkeypatch):
    """A mistyped MOCAPLAB_DATA_DIR is reported as a missing folder, not as a mirror laid out wrongly."""
    gone = tmp_path / "does" / "not" / "exist"
    monkeypatch.setenv(data.ENV_VAR, str(gone))
    for trial, source in (("16_15", "auto"), ("16_15", "asfamc"), ("35_01", "auto")):
        with pytest.raises(data.DataError) as info:
            data.cmu(trial, source=source)
        message = str(info.value)
        assert f"MOCAPLAB_DATA_DIR={gone} is set but that folder does not exist" in message
        assert "not in it" not in message and "laid out like" not in message
    a_file = tmp_path / "mirror.txt"
    a_file.write_text("not a folder")
    monkeypatch.setenv(data.ENV_VAR, str(a_file))
    with pytest.raises(data.DataError, match="is set but that folder is a file, not a folder"):
        data.cmu("16_15")


def test_no_mirror_bvh_says_how_to_get_the_data(monkeypatch):
    monkeypatch.delenv(data.ENV_VAR, raising=False)
    assert data.mirror_dir() is None
    with pytest.raises(data.DataError, match="needs a local mirror: set MOCAPLAB_DATA_DIR") as info:
        data.cmu("16_15", source="bvh")
    assert "source='asfamc'" in str(info.value)


def test_no_mirror_and_no_network_says_how_to_get_the_data(monkeypatch, tmp_path):
    def offline(*args, **kwargs):
        raise OSError("network is unreachable")

    monkeypatch.delenv(data.ENV_VAR, raising=False)
    monkeypatch.delenv(data.URL_ENV_VAR, raising=False)
    monkeypatch.setenv(data.CACHE_ENV_VAR, str(tmp_path))
    monkeypatch.setattr(data, "_download", offline)
    with pytest.raises(data.DataError, match="Could not download http://mocap.cs.cmu.edu/subjects/16/16.asf") as info:
        data.cmu("16_15")
    assert "set MOCAPLAB_DATA_DIR to a local mirror" in str(info.value)


def test_downloaded_files_are_checked_and_read(mocap_dir, monkeypatch, tmp_path):
    """The download path (the network stubbed with mirror copies, CRLF as CMU serves them)."""

    def fake_download(url, target, **kwargs):
        rel = "asfamc/" + "/".join(url.split("/")[-2:])
        target.parent.mkdir(parents=True, exist_ok=True)
        shutil.copyfile(mocap_dir / rel, target)
        target.write_bytes(target.read_bytes().replace(b"\r\n", b"\n").replace(b"\n", b"\r\n"))

    monkeypatch.delenv(data.ENV_VAR, raising=False)
    monkeypatch.delenv(data.URL_ENV_VAR, raising=False)
    monkeypatch.setenv(data.CACHE_ENV_VAR, str(tmp_path))
    monkeypatch.setattr(data, "_download", fake_download)
    m = data.cmu("16_35")  # auto: no mirror, so the Acclaim files are fetched
    assert m.skeleton.names[0] == "root" and m.n_frames == data.describe("16_35")["frames"]


# ------------------------------------------------------ trial ids (issue 17)


@pytest.mark.parametrize(
    ("trial", "expected"),
    [
        ("02_01", ("02", "02_01")),
        ("16_15", ("16", "16_15")),
        ("127_04", ("127", "127_04")),
        ("144_01", ("144", "144_01")),
    ],
)
def test_trial_ids(trial, expected):
    assert data.parse_trial(trial) == expected


@pytest.mark.parametrize(
    ("trial", "hint"),
    [
        ("145_01", " (subject 145 is not in 1..144)"),
        ("00_01", " (subject 0 is not in 1..144)"),
        ("16_00", ""),
        ("16_100", ""),
        ("2_1", "; did you mean '02_01'?"),
        ("016_15", "; did you mean '16_15'?"),
        ("16_1", "; did you mean '16_01'?"),
        ("16-15", ""),
        ("16_15 ", ""),
        ("", ""),
        ("abc", ""),
        ("\u0661\u0666_\u0661\u0665", ""),  # Arabic-Indic digits
        ("9" * 5000 + "_01", ""),
    ],
)
def test_malformed_trial_ids(trial, hint):
    message = (
        "Expected `trial` as 'SS_TT': a CMU subject from 01 to 144 and a two-digit trial number, "
        f"as CMU names its files (e.g. '16_15', '02_01', '127_04'), got {trial!r}{hint}"
    )
    with pytest.raises(ValueError) as info:
        data.cmu(trial)
    assert str(info.value) == message


@pytest.mark.parametrize("trial", [1615, None, ("16", "15")])
def test_trial_id_must_be_a_string(trial):
    with pytest.raises(TypeError, match=f"Expected `trial` to be a str such as '16_15', got {type(trial).__name__}"):
        data.cmu(trial)  # type: ignore[arg-type]


def test_registry_addresses_follow_the_cmu_layout():
    """The download base plus <SS>/<SS>.asf and <SS>/<SS_TT>.amc gives the registry's own CMU addresses."""
    assert data.DEFAULT_CMU_URL == "http://mocap.cs.cmu.edu/subjects"
    for trial in data.clips():
        entry = data.describe(trial)
        if "asf" in entry:
            subject = trial.split("_")[0]
            assert entry["asf_url"] == f"{data.DEFAULT_CMU_URL}/{subject}/{subject}.asf"
            assert entry["amc_url"] == f"{data.DEFAULT_CMU_URL}/{subject}/{trial}.amc"
            assert entry["asf"] == f"asfamc/{subject}/{subject}.asf" and entry["amc"] == f"asfamc/{subject}/{trial}.amc"


def test_download_base(monkeypatch):
    monkeypatch.delenv(data.URL_ENV_VAR, raising=False)
    assert data.download_base() == data.DEFAULT_CMU_URL
    monkeypatch.setenv(data.URL_ENV_VAR, "https://example.org/course/cmu/")
    assert data.download_base() == "https://example.org/course/cmu"
    monkeypatch.setenv(data.URL_ENV_VAR, "example.org/cmu")
    with pytest.raises(data.DataError, match=r"MOCAPLAB_CMU_URL='example.org/cmu' is not a URL"):
        data.download_base()


# ------------------------------------------ integrity on every load (issue 17)


_opened: list[list[str]] = []  # the audit hook below records into the last list while a test watches


def _audit(event: str, args: tuple) -> None:
    if event != "open" or not _opened or not isinstance(args[0], (str, bytes, Path)):
        return
    path, mode, flags = args
    writes = any(c in mode for c in "wax+") if isinstance(mode, str) else bool(flags & (os.O_WRONLY | os.O_RDWR))
    if not writes:
        _opened[-1].append(os.fsdecode(path) if isinstance(path, bytes) else str(path))


@pytest.fixture
def opened():
    """The paths opened for reading while the fixture is active (an audit hook sees every open)."""
    if not getattr(sys, "_mocaplab_test_audit", False):
        sys.addaudithook(_audit)  # hooks cannot be removed: it records only while a list is pushed
        sys._mocaplab_test_audit = True  # type: ignore[attr-defined]
    record: list[str] = []
    _opened.append(record)
    yield record
    _opened.remove(record)


def test_each_file_is_read_once_and_checked_on_every_load(mocap_dir, tmp_path, monkeypatch, opened):
    """The bytes hashed are the bytes parsed, and a file changed after its first load is caught."""
    path = copy_into(mocap_dir, tmp_path, "bvh/16_35.bvh")
    monkeypatch.setenv(data.ENV_VAR, str(tmp_path))
    first = data.cmu("16_35")
    assert opened.count(str(path)) == 1
    data.cmu("16_35")
    assert opened.count(str(path)) == 2  # read (and hashed) again
    raw = path.read_bytes()
    i = raw.rindex(b"1")
    path.write_bytes(raw[:i] + b"2" + raw[i + 1 :])
    with pytest.raises(data.DataError, match=r"16_35.bvh: sha256 [0-9a-f]{64} does not match the registry's"):
        data.cmu("16_35")
    path.write_bytes(raw)
    assert np.array_equal(data.cmu("16_35").rotations, first.rotations)


def test_acclaim_files_changed_after_a_first_load_are_caught(mocap_dir, tmp_path, monkeypatch, opened):
    asf = copy_into(mocap_dir, tmp_path, "asfamc/16/16.asf")
    amc = copy_into(mocap_dir, tmp_path, "asfamc/16/16_35.amc")
    monkeypatch.setenv(data.ENV_VAR, str(tmp_path))
    data.cmu("16_35", source="asfamc")
    assert (opened.count(str(asf)), opened.count(str(amc))) == (1, 1)
    amc.write_bytes(amc.read_bytes().replace(b"root ", b"root 1", 1))
    with pytest.raises(data.DataError, match=r"16_35.amc: sha256 .* does not match the registry's"):
        data.cmu("16_35", source="asfamc")


# --------------------------------------------- the whole database (issue 17)


class _Server(types.SimpleNamespace):
    """A web server on 127.0.0.1 serving ``root`` laid out like the CMU site."""

    def put(self, mocap_dir: Path, rel: str, as_name: str | None = None, transform=None) -> Path:
        """Copy a mirror file (``asfamc/<SS>/<file>``) into the served folder, optionally renamed or changed."""
        src = mocap_dir / rel
        name = as_name or src.name
        subject = name.split(".")[0].split("_")[0]
        dst = self.root / subject / name
        dst.parent.mkdir(parents=True, exist_ok=True)
        raw = src.read_bytes()
        dst.write_bytes(transform(raw) if transform else raw)
        return dst

    def requests(self, name: str) -> int:
        return sum(p.endswith("/" + name) for p in self.log)


@pytest.fixture
def server(tmp_path, monkeypatch):
    """``MOCAPLAB_CMU_URL`` pointing at a local HTTP server in a thread; no mirror; a fresh cache."""
    root = tmp_path / "www" / "subjects"
    root.mkdir(parents=True)
    log: list[str] = []

    class Handler(SimpleHTTPRequestHandler):
        def do_GET(self):  # noqa: N802 - http.server's name
            log.append(self.path)
            super().do_GET()

        def log_message(self, format, *args):  # noqa: A002 - http.server's signature
            pass

    httpd = ThreadingHTTPServer(("127.0.0.1", 0), functools.partial(Handler, directory=str(tmp_path / "www")))
    thread = threading.Thread(target=httpd.serve_forever, kwargs={"poll_interval": 0.05}, daemon=True)
    thread.start()
    url = f"http://127.0.0.1:{httpd.server_address[1]}/subjects"
    monkeypatch.delenv(data.ENV_VAR, raising=False)
    monkeypatch.setenv(data.URL_ENV_VAR, url)
    monkeypatch.setenv(data.CACHE_ENV_VAR, str(tmp_path / "cache"))
    monkeypatch.setenv("NO_PROXY", "127.0.0.1")
    monkeypatch.setenv("no_proxy", "127.0.0.1")
    try:
        yield _Server(root=root, url=url, log=log, cache=tmp_path / "cache")
    finally:
        httpd.shutdown()
        httpd.server_close()
        thread.join(timeout=10)


def crlf(raw: bytes) -> bytes:
    return raw.replace(b"\r\n", b"\n").replace(b"\n", b"\r\n")


def damage(raw: bytes) -> bytes:
    return raw.replace(b"root ", b"root 1", 1)


def cached(server: _Server, name: str) -> Path:
    (path,) = [p for p in server.cache.rglob("*") if p.name.endswith("-" + name)]
    return path


def unverified_warnings(caught) -> list[str]:
    return [str(w.message) for w in caught if issubclass(w.category, data.UnverifiedDataWarning)]


def test_registry_clip_from_a_course_server(mocap_dir, server):
    """End to end over HTTP: fetched once into the cache, hash-verified, the same motion as the local files."""
    server.put(mocap_dir, "asfamc/16/16.asf", transform=crlf)  # CMU serves CRLF
    server.put(mocap_dir, "asfamc/16/16_35.amc", transform=crlf)
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # no unverified warning for a registry clip
        m = data.cmu("16_35")
    ref = load_asf_amc(mocap_dir / "asfamc/16/16.asf", mocap_dir / "asfamc/16/16_35.amc")
    assert m.name == "16_35" and m.n_frames == data.describe("16_35")["frames"] and m.fps == 120.0
    assert np.array_equal(m.global_positions(), ref.global_positions())
    assert (server.requests("16.asf"), server.requests("16_35.amc")) == (1, 1)
    assert cached(server, "16_35.amc").parent == server.cache / "16"
    data.cmu("16_35")  # from the cache, checked again
    assert (server.requests("16.asf"), server.requests("16_35.amc")) == (1, 1)


def test_any_cmu_trial_is_downloaded_and_marked_unverified_once(mocap_dir, server):
    # copies of real files under other trial names: 16_02 (subject 16 has registry clips, so its
    # ASF is verified) and 35_01 (no registry clip of subject 35: both files only parsed)
    server.put(mocap_dir, "asfamc/16/16.asf")
    server.put(mocap_dir, "asfamc/16/16_35.amc", as_name="16_02.amc")
    server.put(mocap_dir, "asfamc/16/16.asf", as_name="35.asf")
    server.put(mocap_dir, "asfamc/16/16_35.amc", as_name="35_01.amc")
    assert "16_02" not in data.clips() and "35_01" not in data.clips()
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("default")  # Python's default: each distinct warning once
        a = data.cmu("16_02")
        b = data.cmu("35_01")
        data.cmu("16_02")
        data.cmu("35_01")
    assert unverified_warnings(caught) == [
        "CMU trial 16_02 is not in mocaplab's registry: 16_02.amc was checked only by parsing, not against a "
        "known sha256 (the registry's clips, data.clips(), are verified)",
        "CMU trial 35_01 is not in mocaplab's registry: 35.asf and 35_01.amc were checked only by parsing, not "
        "against a known sha256 (the registry's clips, data.clips(), are verified)",
    ]
    ref = load_asf_amc(mocap_dir / "asfamc/16/16.asf", mocap_dir / "asfamc/16/16_35.amc")
    for m, name in ((a, "16_02"), (b, "35_01")):
        assert m.name == name and m.fps == 120.0
        assert np.array_equal(m.global_positions(), ref.global_positions())
    assert server.requests("16.asf") == 1 and server.requests("35.asf") == 1


def test_a_corrupt_cached_file_is_removed_and_fetched_again(mocap_dir, server):
    server.put(mocap_dir, "asfamc/16/16.asf")
    server.put(mocap_dir, "asfamc/16/16_35.amc")
    server.put(mocap_dir, "asfamc/16/16_35.amc", as_name="16_02.amc")
    data.cmu("16_35")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", data.UnverifiedDataWarning)
        data.cmu("16_02")
    good = cached(server, "16_35.amc").read_bytes()
    cached(server, "16_35.amc").write_bytes(damage(good))  # a hash mismatch
    cached(server, "16_02.amc").write_bytes(b"<html>disk full</html>\n")  # does not parse
    m = data.cmu("16_35")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", data.UnverifiedDataWarning)
        other = data.cmu("16_02")
    assert cached(server, "16_35.amc").read_bytes() == good
    assert server.requests("16_35.amc") == 2 and server.requests("16_02.amc") == 2 and server.requests("16.asf") == 1
    assert m.n_frames == other.n_frames == data.describe("16_35")["frames"]


def test_a_file_damaged_on_the_server_is_a_data_error(mocap_dir, server):
    server.put(mocap_dir, "asfamc/16/16.asf")
    server.put(mocap_dir, "asfamc/16/16_35.amc", transform=damage)
    with pytest.raises(data.DataError) as info:
        data.cmu("16_35")
    message = str(info.value)
    url = f"{server.url}/16/16_35.amc"
    got = hashlib.sha256(damage((mocap_dir / "asfamc/16/16_35.amc").read_bytes())).hexdigest()
    assert message.startswith(str(server.cache / "16") + "/")
    assert message.split(": ", 1)[1] == (
        f"16_35.amc downloaded from {url} failed its check: its sha256 (of the text with LF line endings) is "
        f"{got}, not the registry's {data.describe('16_35')['amc_sha256_lf']}. The cached copy failed first, was "
        "removed and downloaded again, and the new copy fails too; it was removed. The server holds a damaged or "
        f"different file: check MOCAPLAB_CMU_URL (now {server.url!r}) or try again later."
    )
    assert server.requests("16_35.amc") == 2
    assert not list(server.cache.rglob("*16_35.amc"))  # nothing damaged left in the cache


def test_an_unparsable_download_is_a_data_error(mocap_dir, server):
    server.put(mocap_dir, "asfamc/16/16.asf", as_name="35.asf")
    (server.root / "35" / "35_01.amc").write_text("<html><body>Moved</body></html>\n")
    with pytest.raises(
        data.DataError,
        match=r"35_01.amc downloaded from .* failed its check: it does not parse \(.*35_01.amc, line 1: expected",
    ):
        data.cmu("35_01")
    assert server.requests("35_01.amc") == 2


def test_a_damaged_file_that_cannot_be_removed_says_to_delete_it(mocap_dir, server, monkeypatch):
    server.put(mocap_dir, "asfamc/16/16.asf")
    server.put(mocap_dir, "asfamc/16/16_35.amc", transform=damage)

    def refuse(self, missing_ok=False):
        raise PermissionError(13, "Permission denied")

    monkeypatch.setattr(Path, "unlink", refuse)
    with pytest.raises(data.DataError, match=r"it was could not be removed \(Permission denied\): delete it by hand"):
        data.cmu("16_35")


def test_a_trial_the_server_does_not_have(server):
    with pytest.raises(data.DataError) as info:
        data.cmu("16_99")
    assert str(info.value).startswith(f"Could not download {server.url}/16/16.asf (404 Client Error")
    assert "Is 16_99 a CMU trial?" in str(info.value)


def test_downloads_show_a_progress_bar_when_tqdm_is_installed(monkeypatch, tmp_path):
    calls = []

    def fake_download(url, target, *, progressbar=False, check=None):
        calls.append(progressbar)
        raise OSError("offline")

    monkeypatch.delenv(data.ENV_VAR, raising=False)
    monkeypatch.setenv(data.CACHE_ENV_VAR, str(tmp_path))
    monkeypatch.setattr(data, "_download", fake_download)
    monkeypatch.setitem(sys.modules, "tqdm", None)  # not importable
    with pytest.raises(data.DataError):
        data.cmu("16_15")
    fake = types.ModuleType("tqdm")
    fake.__spec__ = importlib.machinery.ModuleSpec("tqdm", None)
    monkeypatch.setitem(sys.modules, "tqdm", fake)
    with pytest.raises(data.DataError):
        data.cmu("16_15")
    assert calls == [False, True]


# ----------------------------------------- the mirror serves any trial it holds


def test_mirror_serves_an_unregistered_acclaim_trial(mocap_dir, tmp_path, monkeypatch):
    copy_into(mocap_dir, tmp_path, "asfamc/16/16.asf")
    shutil.copyfile(mocap_dir / "asfamc/16/16_35.amc", tmp_path / "asfamc/16/16_02.amc")
    monkeypatch.setenv(data.ENV_VAR, str(tmp_path))
    with pytest.warns(
        data.UnverifiedDataWarning,
        match="CMU trial 16_02 is not in mocaplab's registry: asfamc/16/16_02.amc was checked",
    ):
        m = data.cmu("16_02")
    assert m.name == "16_02" and m.fps == 120.0 and m.skeleton.names[0] == "root"
    assert m.n_frames == data.describe("16_35")["frames"]


def test_mirror_serves_an_unregistered_bvh_trial(mocap_dir, tmp_path, monkeypatch):
    (tmp_path / "bvh").mkdir()
    shutil.copyfile(mocap_dir / "bvh/16_35.bvh", tmp_path / "bvh/16_02.bvh")
    monkeypatch.setenv(data.ENV_VAR, str(tmp_path))
    with pytest.warns(data.UnverifiedDataWarning, match="bvh/16_02.bvh was checked only by parsing"):
        m = data.cmu("16_02")
    ref = load_bvh(mocap_dir / "bvh/16_35.bvh", scale=CMU_UNIT)
    assert m.name == "16_02" and m.fps == 120.0
    assert np.array_equal(m.global_positions(), ref.global_positions())


def test_mirror_without_an_unregistered_trial(tmp_path, monkeypatch):
    monkeypatch.setenv(data.ENV_VAR, str(tmp_path))
    monkeypatch.delenv(data.URL_ENV_VAR, raising=False)
    with pytest.raises(data.DataError) as info:
        data.cmu("35_01")
    assert str(info.value) == (
        f"MOCAPLAB_DATA_DIR={tmp_path} is set but trial 35_01 is not in it: neither bvh/35_01.bvh nor "
        "asfamc/35/35_01.amc (with asfamc/35/35.asf). Add the files, or unset MOCAPLAB_DATA_DIR to download "
        "the trial from http://mocap.cs.cmu.edu/subjects."
    )


def test_mirror_trial_that_does_not_parse(mocap_dir, tmp_path, monkeypatch):
    copy_into(mocap_dir, tmp_path, "asfamc/16/16.asf")
    (tmp_path / "asfamc/16/16_02.amc").write_text("1\nroot 0 0 0\n")
    monkeypatch.setenv(data.ENV_VAR, str(tmp_path))
    with pytest.raises(
        data.DataError,
        match=r"16_02.amc: trial 16_02 in the mirror does not parse \(.*expected 6 value\(s\) for bone 'root', got 3",
    ):
        data.cmu("16_02")
    assert (tmp_path / "asfamc/16/16_02.amc").exists()  # the mirror is never changed


# --------------------------------------------- a classroom mirror (issue 18)

LESSONS = Path(__file__).resolve().parents[1] / "lessons"
_TRIAL_LITERAL = re.compile(r"""["']([0-9]{1,3}_[0-9]{2})["']""")


def lesson_trial_ids() -> dict[str, set[str]]:
    """Every quoted CMU trial id in the code cells of ``lessons/*.ipynb``, by lesson (read at test time)."""
    import nbformat

    found: dict[str, set[str]] = {}
    for path in sorted(LESSONS.glob("*.ipynb")):
        nb = nbformat.read(path, as_version=4)
        ids = {m.group(1) for c in nb.cells if c.cell_type == "code" for m in _TRIAL_LITERAL.finditer(c.source)}
        found[path.name] = ids
    return found


def test_the_registry_covers_every_clip_the_lessons_name():
    """``fetch --lessons`` fetches the registry: every trial id a lesson names must be in it."""
    found = lesson_trial_ids()
    assert found and any(found.values()), f"no trial ids found in {LESSONS}"
    missing = {name: sorted(ids - set(data.lesson_clips())) for name, ids in found.items() if ids - set(data.clips())}
    assert not missing, f"lessons name clips that are not in the registry (mocaplab/_registry.py): {missing}"
    assert data.lesson_clips() == data.clips()


@pytest.fixture
def course(mocap_dir, server, tmp_path):
    """The server fixture also serving a whole mirror copied from the local one at ``<url>/mirror``."""
    www = server.root.parent / "mirror"
    for rel in (r for _, r, _, _ in data._mirror_files(data.lesson_clips())):
        copy_into(mocap_dir, www, rel)
    server.mirror = www
    server.mirror_url = server.url.rsplit("/", 1)[0] + "/mirror"
    return server


def fetch(*args: str) -> int:
    return data.main(["fetch", *args])


def test_fetch_lessons_builds_a_verified_mirror(course, tmp_path, monkeypatch, capsys, mocap_dir):
    dest = tmp_path / "classroom"
    assert fetch("--lessons", str(dest), "--url", course.mirror_url) == 0
    out, err = capsys.readouterr()
    n = len(data._mirror_files(data.lesson_clips()))
    assert f"ok: {n} files of {len(data.lesson_clips())} trials" in out
    assert f"{n}/{n}" in err and "mocaplab data" in err  # the progress bar
    assert len([p for p in course.log if p.startswith("/mirror/")]) == n
    files = sorted(str(p.relative_to(dest)) for p in dest.rglob("*") if p.is_file())
    assert files == sorted(r for _, r, _, _ in data._mirror_files(data.lesson_clips()))  # no .part left
    assert data.check_mirror(dest) == {}
    monkeypatch.setenv(data.ENV_VAR, str(dest))
    assert np.array_equal(
        data.cmu("16_15").root_positions, load_bvh(mocap_dir / "bvh/16_15.bvh", scale=1.0).root_positions * CMU_UNIT
    )
    assert data.cmu("60_10").fps == 60.0


@pytest.mark.parametrize("as_url", [False, True], ids=["path", "file-url"])
def test_fetch_from_a_local_folder_builds_the_same_mirror(course, tmp_path, monkeypatch, capsys, as_url):
    """``--url`` may name a local folder (a USB stick, a shared drive): no adapter errors, the same verified files."""
    source = course.mirror.as_uri() if as_url else str(course.mirror)
    dest = tmp_path / "classroom"
    trials = ["16_15", "02_01", "60_10"]
    n = len(data._mirror_files(trials))
    assert fetch(str(dest), *trials, "--url", source, "--no-progress") == 0
    out, err = capsys.readouterr()
    assert f"ok: {n} files of 3 trials verified in {dest}" in out and "error" not in err
    assert course.log == []  # nothing went through the web server
    files = sorted(str(p.relative_to(dest)) for p in dest.rglob("*") if p.is_file())
    assert files == sorted(r for _, r, _, _ in data._mirror_files(trials))
    for rel in files:
        assert (dest / rel).read_bytes() == (course.mirror / rel).read_bytes()
    # a damaged file in the source folder is rejected, a missing one is named, the rest is kept
    (dest / "bvh/16_15.bvh").unlink()
    (dest / "bvh/02_01.bvh").unlink()
    bvh = course.mirror / "bvh/16_15.bvh"
    bvh.write_bytes(bvh.read_bytes().replace(b"Hips", b"Hipz", 1))
    (course.mirror / "bvh/02_01.bvh").unlink()
    assert fetch(str(dest), *trials, "--url", source, "--no-progress") == 1
    out, _ = capsys.readouterr()
    assert f"bad: bvh/16_15.bvh: copied from {course.mirror / 'bvh/16_15.bvh'}, but it sha256 " in out
    assert f"bad: bvh/02_01.bvh: not in {course.mirror}" in out and f"2 of {n} files missing or bad" in out
    assert not (dest / "bvh/16_15.bvh").exists() and not list(dest.rglob(".*.tmp"))
    assert data.check_mirror(dest, trials) == {"bvh/16_15.bvh": "missing", "bvh/02_01.bvh": "missing"}
    # the environment variable may name a local folder too
    monkeypatch.setenv(data.MIRROR_URL_ENV_VAR, str(course.mirror))
    assert data.fetch_mirror(tmp_path / "other", ["16_35"], progress=False) == {}


def test_fetch_from_a_local_folder_that_does_not_exist(tmp_path, capsys):
    gone = tmp_path / "no-such-stick"
    assert fetch(str(tmp_path / "classroom"), "16_15", "--url", str(gone), "--no-progress") == 2
    err = capsys.readouterr().err
    assert f"--url '{gone}' names a local folder that does not exist" in err
    assert not (tmp_path / "classroom").exists()


def test_fetch_resumes(course, tmp_path, capsys):
    dest = tmp_path / "classroom"
    assert fetch(str(dest), "16_15", "02_01", "--url", course.mirror_url, "--no-progress") == 0
    assert len(course.log) == 6  # a BVH, an AMC and an ASF each
    course.log.clear()
    assert fetch(str(dest), "16_15", "02_01", "--url", course.mirror_url) == 0
    assert course.log == []  # everything there and verified: nothing downloaded
    # an interrupted download: a killed run's temporary file beside a missing one, a truncated file in place
    (dest / "bvh/16_15.bvh").rename(dest / "bvh/.16_15.bvh.0123456789ab.tmp")
    amc = dest / "asfamc/02/02_01.amc"
    amc.write_bytes(amc.read_bytes()[:1000])
    assert data.check_mirror(dest, ["16_15", "02_01"]) == {
        "bvh/16_15.bvh": "missing",
        "asfamc/02/02_01.amc": data.check_mirror(dest, ["02_01"])["asfamc/02/02_01.amc"],
    }
    assert fetch(str(dest), "16_15", "02_01", "--url", course.mirror_url) == 0
    assert sorted(course.log) == ["/mirror/asfamc/02/02_01.amc", "/mirror/bvh/16_15.bvh"]
    assert data.check_mirror(dest, ["16_15", "02_01"]) == {}
    assert not list(dest.rglob(".*.tmp")) and not list(dest.rglob("*.part")) and not list(dest.rglob("*.old"))


def test_fetch_rejects_a_damaged_file_and_keeps_the_rest(course, tmp_path, capsys):
    dest = tmp_path / "classroom"
    bvh = course.mirror / "bvh/16_15.bvh"
    bvh.write_bytes(bvh.read_bytes().replace(b"Hips", b"Hipz", 1))
    assert fetch(str(dest), "16_15", "--url", course.mirror_url, "--no-progress") == 1
    out, _ = capsys.readouterr()
    assert f"bad: bvh/16_15.bvh: downloaded from {course.mirror_url}/bvh/16_15.bvh, but it sha256 " in out
    assert "is not the registry's ad2832511ff79d1f" in out and "1 of 3 files missing or bad" in out
    assert not (dest / "bvh/16_15.bvh").exists() and not list(dest.rglob(".*.tmp"))
    assert data.check_mirror(dest, ["16_15"]) == {"bvh/16_15.bvh": "missing"}


def test_fetch_without_a_mirror_server_gets_the_acclaim_files_from_the_cmu_layout(course, mocap_dir, tmp_path, capsys):
    course.put(mocap_dir, "asfamc/16/16.asf", transform=crlf)  # the CMU layout at MOCAPLAB_CMU_URL, CRLF as CMU
    course.put(mocap_dir, "asfamc/16/16_15.amc", transform=crlf)
    dest = tmp_path / "classroom"
    assert fetch(str(dest), "16_15", "--no-progress") == 1
    out, _ = capsys.readouterr()
    assert "bad: bvh/16_15.bvh: not on the CMU site; give a course server holding a mirror (MOCAPLAB_MIRROR_URL)" in out
    assert sorted(course.log) == ["/subjects/16/16.asf", "/subjects/16/16_15.amc"]
    assert data.check_mirror(dest, ["16_15"]) == {"bvh/16_15.bvh": "missing"}


def test_fetch_an_unregistered_trial_checks_it_by_parsing(course, mocap_dir, tmp_path, monkeypatch):
    course.put(mocap_dir, "asfamc/16/16.asf", as_name="35.asf")
    course.put(mocap_dir, "asfamc/16/16_35.amc", as_name="35_01.amc")
    course.put(mocap_dir, "asfamc/16/16.asf", as_name="35_02.amc")  # not an AMC file
    dest = tmp_path / "classroom"
    assert data.fetch_mirror(dest, ["35_01"], progress=False) == {}
    problems = data.fetch_mirror(dest, ["35_02"], progress=False)
    assert list(problems) == ["asfamc/35/35_02.amc"] and "does not parse" in problems["asfamc/35/35_02.amc"]
    monkeypatch.setenv(data.ENV_VAR, str(dest))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", data.UnverifiedDataWarning)
        assert data.cmu("35_01").n_frames == data.describe("16_35")["frames"]


def test_check_lists_missing_and_bad_files(mocap_dir, tmp_path, capsys):
    dest = tmp_path / "mirror"
    for _, rel, _, _ in data._mirror_files(data.lesson_clips()):
        copy_into(mocap_dir, dest, rel)
    assert data.main(["check", str(dest)]) == 0
    assert "ok: 38 files of 17 trials verified" in capsys.readouterr().out
    (dest / "pair_salsa_daz/61_10.bvh").unlink()
    copy_into(mocap_dir, dest, "asfamc/16/16.asf", transform=damage)
    copy_into(mocap_dir, dest, "asfamc/02/02.asf", transform=crlf)  # line endings alone do not matter
    assert data.main(["check", "--lessons", str(dest)]) == 1
    out = capsys.readouterr().out
    assert "missing: pair_salsa_daz/61_10.bvh: missing" in out
    assert "bad: asfamc/16/16.asf: sha256 " in out and "02.asf" not in out
    assert "2 of 38 files missing or bad" in out


def test_data_command_line_errors(capsys, tmp_path):
    assert data.main(["check", str(tmp_path), "16_5"]) == 2
    assert "did you mean '16_05'?" in capsys.readouterr().err
    with pytest.raises(SystemExit):
        data.main(["unpack", str(tmp_path)])


def test_data_module_runs_as_a_command(tmp_path):
    import subprocess

    done = subprocess.run(
        [sys.executable, "-m", "mocaplab.data", "check", str(tmp_path), "16_15"], capture_output=True, text=True
    )
    assert done.returncode == 1 and "3 of 3 files missing or bad" in done.stdout
