"""Nothing lost: every file mocaplab writes appears whole or not at all (issue 27, item 1).

The writers (``save_bvh``, the download cache, the classroom mirror) share
``mocaplab._atomic.atomic_write``.  The failures are real ones, in child
processes: a file-size limit (``RLIMIT_FSIZE``, the portable stand-in for a
full disk) and a ``SIGKILL`` in the middle of an export.
"""

from __future__ import annotations

import os
import signal
import stat
import subprocess
import sys
import textwrap
from pathlib import Path

import numpy as np
import pytest

from mocaplab._atomic import TEMP_SUFFIX, atomic_write
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
