"""Nothing lost: every file mocaplab writes appears whole or not at all (issue 27, item 1).

The writers (``save_bvh``, the download cache, the classroom mirror) share
``mocaplab._atomic.atomic_write``.  The failures are real ones, in child
processes: a file-size limit (``RLIMIT_FSIZE``, the portable stand-in for a
full disk) and a ``SIGKILL`` in the middle of an export.
"""

from __future__ import annotations

import contextlib
import os
import signal
import stat
import subprocess
import sys
import textwrap
import threading
import time
from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer
from pathlib import Path

import numpy as np
import pytest

from mocaplab import data
from mocaplab._atomic import TEMP_SUFFIX, atomic_write, stale_temporaries
from mocaplab.io import load_bvh, save_bvh

DATA = Path(__file__).parent / "data"
posix_only = pytest.mark.skipif(os.name != "posix", reason="resource limits and signals are POSIX")

# the child's motion: tests/data/chain3.bvh stretched to `frames` frames of varied poses
CHILD_MOTION = """
import numpy as np
from scipy.spatial.transform import Rotation
from mocaplab.io import load_bvh
base = load_bvh({chain!r}, scale=0.01)
n = {frames}
rng = np.random.default_rng(0)
rot = Rotation.from_rotvec(rng.normal(0, 0.5, (n * 3, 3))).as_quat(scalar_first=True).reshape(n, 3, 4)
motion = base.replace(rotations=rot, root_positions=rng.normal(0, 1, (n, 3)))
"""


def leftovers(folder: Path, keep: set[str]) -> list[str]:
    return sorted(p.name for p in folder.iterdir() if p.name not in keep)


def good_file(tmp_path: Path) -> tuple[Path, bytes]:
    """An existing, complete export that a failed export must leave alone."""
    path = tmp_path / "walk.bvh"
    save_bvh(load_bvh(DATA / "chain3.bvh", scale=0.01), path)
    return path, path.read_bytes()


def run_child(code: str, **kwargs) -> subprocess.CompletedProcess:
    return subprocess.run(
        [sys.executable, "-c", textwrap.dedent(code)], capture_output=True, text=True, timeout=120, **kwargs
    )


@posix_only
def test_a_full_disk_leaves_the_old_export_and_no_temporary_file(tmp_path):
    path, old = good_file(tmp_path)
    code = CHILD_MOTION.format(chain=str(DATA / "chain3.bvh"), frames=2000) + textwrap.dedent(
        f"""
        import resource, signal
        from mocaplab.io import save_bvh
        signal.signal(signal.SIGXFSZ, signal.SIG_IGN)  # a write past the limit fails with EFBIG instead
        resource.setrlimit(resource.RLIMIT_FSIZE, (32_768, 32_768))
        try:
            save_bvh(motion, {str(path)!r})
        except OSError as exc:
            print("errno", exc.errno)
        else:
            print("written")
        """
    )
    done = run_child(code)
    assert done.returncode == 0, done.stderr
    assert done.stdout.split() == ["errno", str(__import__("errno").EFBIG)]
    assert path.read_bytes() == old
    assert leftovers(tmp_path, {"walk.bvh"}) == []


@posix_only
def test_a_full_disk_on_a_new_name_leaves_nothing(tmp_path):
    code = CHILD_MOTION.format(chain=str(DATA / "chain3.bvh"), frames=2000) + textwrap.dedent(
        f"""
        import resource, signal
        from mocaplab.io import save_bvh
        signal.signal(signal.SIGXFSZ, signal.SIG_IGN)
        resource.setrlimit(resource.RLIMIT_FSIZE, (32_768, 32_768))
        try:
            save_bvh(motion, {str(tmp_path / "new.bvh")!r})
        except OSError:
            print("failed")
        """
    )
    done = run_child(code)
    assert done.stdout.strip() == "failed", done.stderr
    assert leftovers(tmp_path, set()) == []


@posix_only
def test_an_export_killed_before_it_is_complete_leaves_the_old_file(tmp_path):
    """SIGKILL once the whole text is written but not yet in place: the old export is still there, whole.

    The child stops itself at ``os.fsync`` (which an atomic writer calls after
    writing and before renaming), and is killed there.  A writer that writes
    in place has already destroyed the old file by then, or never calls
    ``fsync`` and overwrites it: either way the last assert fails.
    """
    path, old = good_file(tmp_path)
    code = CHILD_MOTION.format(chain=str(DATA / "chain3.bvh"), frames=60_000) + textwrap.dedent(
        f"""
        import os, sys, time
        from mocaplab.io import save_bvh
        def stuck(fd):
            print("writing", flush=True)
            time.sleep(600)
        os.fsync = stuck
        save_bvh(motion, {str(path)!r})
        print("returned", flush=True)
        """
    )
    child = subprocess.Popen([sys.executable, "-c", code], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        line = child.stdout.readline().strip()
        child.send_signal(signal.SIGKILL)
    finally:
        child.kill()
        child.wait(timeout=60)
    assert line == "writing", child.stderr.read()
    (temporary,) = leftovers(tmp_path, {"walk.bvh"})  # the killed export's bytes: whole, but never named
    assert temporary.startswith(".walk.bvh.") and temporary.endswith(TEMP_SUFFIX)
    assert (tmp_path / temporary).stat().st_size > 3_000_000
    assert path.read_bytes() == old


# ------------------------------------------------------------- the helper itself


def test_an_error_inside_the_block_leaves_the_file_as_it_was(tmp_path):
    path = tmp_path / "a.txt"
    path.write_bytes(b"old")
    with pytest.raises(RuntimeError, match="check failed"), atomic_write(path) as fh:
        fh.write(b"new and half")
        raise RuntimeError("check failed")
    assert path.read_bytes() == b"old"
    assert leftovers(tmp_path, {"a.txt"}) == []
    with pytest.raises(KeyboardInterrupt), atomic_write(tmp_path / "b.txt") as fh:
        fh.write(b"x")
        raise KeyboardInterrupt
    assert leftovers(tmp_path, {"a.txt"}) == []


def test_a_complete_write_replaces_the_file(tmp_path):
    path = tmp_path / "a.txt"
    path.write_bytes(b"old content, longer than the new")
    with atomic_write(path, mode="w", encoding="utf-8", newline="\n") as fh:
        fh.write("new\n")
    assert path.read_bytes() == b"new\n"
    assert leftovers(tmp_path, {"a.txt"}) == []


@posix_only
def test_permissions_are_those_of_a_plain_open_or_of_the_replaced_file(tmp_path):
    plain = tmp_path / "plain.txt"
    with open(plain, "wb") as fh:
        fh.write(b"x")
    with atomic_write(tmp_path / "new.txt") as fh:
        fh.write(b"x")
    assert stat.S_IMODE((tmp_path / "new.txt").stat().st_mode) == stat.S_IMODE(plain.stat().st_mode)
    os.chmod(plain, 0o640)
    with atomic_write(plain) as fh:
        fh.write(b"y")
    assert stat.S_IMODE(plain.stat().st_mode) == 0o640


@posix_only
def test_a_symbolic_link_is_kept_and_its_file_replaced(tmp_path):
    real = tmp_path / "real.bvh"
    real.write_bytes(b"old")
    link = tmp_path / "link.bvh"
    link.symlink_to(real)
    save_bvh(load_bvh(DATA / "chain3.bvh", scale=0.01), link)
    assert link.is_symlink() and real.read_bytes().startswith(b"HIERARCHY")


def test_bad_destinations_are_named(tmp_path):
    motion = load_bvh(DATA / "chain3.bvh", scale=0.01)
    with pytest.raises(IsADirectoryError) as info:
        save_bvh(motion, tmp_path)
    assert info.value.filename == str(tmp_path)
    missing = tmp_path / "no such folder" / "walk.bvh"
    with pytest.raises(FileNotFoundError) as info:
        save_bvh(motion, missing)
    assert info.value.filename == str(missing)
    assert leftovers(tmp_path, set()) == []
    with pytest.raises(ValueError, match="Expected `mode` 'wb' or 'w', got 'a'"), atomic_write(tmp_path / "x", mode="a"):
        pass


def test_the_exported_bytes_are_unchanged_by_the_atomic_path(tmp_path):
    """The export is the text save_bvh builds, byte for byte (LF endings, UTF-8)."""
    motion = load_bvh(DATA / "chain3.bvh", scale=0.01)
    save_bvh(motion, tmp_path / "a.bvh")
    back = load_bvh(tmp_path / "a.bvh", scale=0.01)
    assert np.allclose(back.global_positions(), motion.global_positions(), atol=1e-6)
    assert b"\r" not in (tmp_path / "a.bvh").read_bytes()


# ------------------------------------------------- downloads: the cache and the classroom mirror


class _Server:
    """A local HTTP server: ``files`` by path, ``endless`` paths that never stop sending, ``hang`` paths that
    send half their bytes and wait for ``release``."""

    def __init__(self) -> None:
        self.files: dict[str, bytes] = {}
        self.endless: set[str] = set()
        self.hang: set[str] = set()
        self.release = threading.Event()
        server = self

        class Handler(BaseHTTPRequestHandler):
            def do_GET(self):  # noqa: N802 - http.server's name
                path = self.path
                if path in server.endless:  # announces 128 MB and sends until the client hangs up
                    self.send_response(200)
                    self.send_header("Content-Length", str(2000 * 65536))
                    self.end_headers()
                    chunk = b"x" * 65536
                    with contextlib.suppress(OSError):
                        for _ in range(2000):  # bounded: 128 MB at most
                            self.wfile.write(chunk)
                    return
                if path not in server.files:
                    self.send_error(404)
                    return
                raw = server.files[path]
                self.send_response(200)
                self.send_header("Content-Length", str(len(raw)))
                self.end_headers()
                with contextlib.suppress(OSError):
                    if path in server.hang:
                        self.wfile.write(raw[: len(raw) // 2])
                        self.wfile.flush()
                        server.release.wait(60)
                        return
                    self.wfile.write(raw)

            def log_message(self, format, *args):  # noqa: A002 - http.server's signature
                pass

        self.httpd = ThreadingHTTPServer(("127.0.0.1", 0), Handler)
        self.httpd.daemon_threads = True
        self.url = f"http://127.0.0.1:{self.httpd.server_address[1]}"
        self.thread = threading.Thread(target=self.httpd.serve_forever, kwargs={"poll_interval": 0.05}, daemon=True)
        self.thread.start()

    def close(self) -> None:
        self.release.set()
        self.httpd.shutdown()
        self.httpd.server_close()
        self.thread.join(timeout=10)


@pytest.fixture
def web(monkeypatch, tmp_path):
    server = _Server()
    monkeypatch.delenv(data.ENV_VAR, raising=False)
    monkeypatch.setenv(data.URL_ENV_VAR, server.url + "/subjects")
    monkeypatch.setenv(data.CACHE_ENV_VAR, str(tmp_path / "cache"))
    monkeypatch.setenv("NO_PROXY", "127.0.0.1")
    monkeypatch.setenv("no_proxy", "127.0.0.1")
    try:
        yield server
    finally:
        server.close()


def serve_subject_16(web: _Server, mocap_dir: Path) -> None:
    for name in ("16.asf", "16_35.amc"):
        web.files[f"/subjects/16/{name}"] = (mocap_dir / "asfamc/16" / name).read_bytes()


def test_a_runaway_download_is_cut_off_and_nothing_cached(web, mocap_dir, monkeypatch, tmp_path):
    serve_subject_16(web, mocap_dir)
    web.endless.add("/subjects/16/16_35.amc")
    monkeypatch.setattr(data, "MAX_DOWNLOAD_BYTES", 1_000_000)
    with pytest.raises(data.DataError) as info:
        data.cmu("16_35")
    assert str(info.value).startswith(
        f"{web.url}/subjects/16/16_35.amc sent more than MAX_DOWNLOAD_BYTES = 1000000 bytes (0.953674 MiB)"
    )
    assert sorted(p.name for p in (tmp_path / "cache" / "16").iterdir()) == [
        next(p.name for p in (tmp_path / "cache" / "16").iterdir() if p.name.endswith("-16.asf"))
    ]  # the ASF, complete; no AMC, no temporary file
    web.endless.clear()
    assert data.cmu("16_35").n_frames == data.describe("16_35")["frames"]


def test_the_download_limit_is_checked_on_real_files(web, mocap_dir, monkeypatch):
    """The limit counts bytes: a file one byte over it is refused, one at it is taken."""
    serve_subject_16(web, mocap_dir)
    size = len(web.files["/subjects/16/16_35.amc"])
    monkeypatch.setattr(data, "MAX_DOWNLOAD_BYTES", size - 1)
    with pytest.raises(data.DataError, match="sent more than MAX_DOWNLOAD_BYTES"):
        data.cmu("16_35")
    monkeypatch.setattr(data, "MAX_DOWNLOAD_BYTES", size)
    assert data.cmu("16_35").n_frames == data.describe("16_35")["frames"]


@posix_only
def test_a_full_disk_while_caching_a_download_leaves_no_cached_file(web, mocap_dir, tmp_path):
    serve_subject_16(web, mocap_dir)
    code = """
        import resource, signal
        from mocaplab import data
        signal.signal(signal.SIGXFSZ, signal.SIG_IGN)
        resource.setrlimit(resource.RLIMIT_FSIZE, (65_536, 65_536))  # the ASF fits, the AMC does not
        try:
            data.cmu("16_35")
        except data.DataError as err:
            print(err)
        """
    done = run_child(code, env={**os.environ})
    assert done.returncode == 0, done.stderr
    assert done.stdout.startswith(f"Could not download {web.url}/subjects/16/16_35.amc ([Errno 27] File too large")
    names = sorted(p.name for p in (tmp_path / "cache" / "16").iterdir())
    assert len(names) == 1 and names[0].endswith("-16.asf")
    assert data.cmu("16_35").n_frames == data.describe("16_35")["frames"]  # the next try downloads it whole


@posix_only
def test_a_mirror_fetch_killed_mid_download_keeps_nothing_and_resumes(web, mocap_dir, tmp_path):
    """``python -m mocaplab.data fetch`` killed while a file is half downloaded; run again, it completes."""
    for rel in ("bvh/16_15.bvh", "asfamc/16/16.asf", "asfamc/16/16_15.amc"):
        web.files[f"/mirror/{rel}"] = (mocap_dir / rel).read_bytes()
    dest = tmp_path / "classroom"
    (dest / "bvh").mkdir(parents=True)
    good = dest / "bvh/16_15.bvh"
    web.hang.add("/mirror/asfamc/16/16_15.amc")
    command = [sys.executable, "-m", "mocaplab.data", "fetch", str(dest), "16_15", "--url", web.url + "/mirror"]
    child = subprocess.Popen([*command, "--no-progress"], stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    try:
        amc = dest / "asfamc/16/16_15.amc"
        for _ in range(600):  # until a quarter of the AMC (half is sent) is written to its temporary file
            partial = stale_temporaries(amc)
            if partial and os.path.getsize(partial[0]) >= len(web.files["/mirror/asfamc/16/16_15.amc"]) // 4:
                break
            assert child.poll() is None, child.stderr.read()
            time.sleep(0.05)
        else:
            pytest.fail("the fetch never reached the AMC file")
        child.send_signal(signal.SIGKILL)
    finally:
        child.kill()
        child.wait(timeout=60)
    assert good.read_bytes() == (mocap_dir / "bvh/16_15.bvh").read_bytes()  # fetched before the kill: whole
    assert not amc.exists() and len(stale_temporaries(amc)) == 1
    web.hang.clear()
    web.release.set()
    done = subprocess.run([*command, "--no-progress"], capture_output=True, text=True, timeout=120)
    assert done.returncode == 0, done.stdout + done.stderr
    assert amc.read_bytes() == (mocap_dir / "asfamc/16/16_15.amc").read_bytes()
    assert stale_temporaries(amc) == [] and sorted(p.name for p in amc.parent.iterdir()) == ["16.asf", "16_15.amc"]


def test_a_rejected_mirror_download_keeps_the_file_that_was_there(web, mocap_dir, tmp_path):
    """A file already in place that fails its check is replaced only by a copy that passes."""
    dest = tmp_path / "classroom"
    target = dest / "bvh/16_15.bvh"
    target.parent.mkdir(parents=True)
    old = (mocap_dir / "bvh/16_15.bvh").read_bytes()[:-10]  # truncated: fails its check, so it is fetched
    target.write_bytes(old)
    web.files["/mirror/bvh/16_15.bvh"] = b"<html>not found</html>\n"
    problems = data.fetch_mirror(dest, ["16_15"], url=web.url + "/mirror", progress=False)
    assert problems["bvh/16_15.bvh"].startswith(f"downloaded from {web.url}/mirror/bvh/16_15.bvh, but it sha256 ")
    assert target.read_bytes() == old and sorted(p.name for p in target.parent.iterdir()) == ["16_15.bvh"]
