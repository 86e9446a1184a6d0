"""The CMU clip registry, the local mirror, hash checks and error messages."""

from __future__ import annotations

import shutil
from pathlib import Path

import numpy as np
import pytest

from mocaplab import data
from mocaplab.io import load_bvh

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


def test_unknown_clip():
    with pytest.raises(KeyError, match="Unknown CMU clip '99_99'; known clips are"):
        data.cmu("99_99")


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


def test_no_mirror_bvh_says_how_to_get_the_data(monkeypatch):
    monkeypatch.delenv(data.ENV_VAR, raising=False)
    assert data.mirror_dir() is None
    with pytest.raises(data.DataError, match="needs a local mirror: set MOCAPLAB_DATA_DIR") as info:
        data.cmu("16_15", source="bvh")
    assert "source='asfamc'" in str(info.value)


def test_no_mirror_and_no_network_says_how_to_get_the_data(monkeypatch, tmp_path):
    pooch = pytest.importorskip("pooch")

    def offline(*args, **kwargs):
        raise OSError("network is unreachable")

    monkeypatch.delenv(data.ENV_VAR, raising=False)
    monkeypatch.setenv(data.CACHE_ENV_VAR, str(tmp_path))
    monkeypatch.setattr(pooch, "retrieve", offline)
    with pytest.raises(data.DataError, match="Could not download http://mocap.cs.cmu.edu/subjects/16/16.asf") as info:
        data.cmu("16_15")
    assert "set MOCAPLAB_DATA_DIR to a local mirror" in str(info.value)


def test_downloaded_files_are_checked_and_read(mocap_dir, monkeypatch, tmp_path):
    """The download path (pooch stubbed with mirror copies, CRLF as CMU serves them)."""
    pooch = pytest.importorskip("pooch")

    def fake_retrieve(url, known_hash, path, progressbar):
        rel = "asfamc/" + "/".join(url.split("/")[-2:])
        dst = Path(path) / url.split("/")[-1]
        dst.parent.mkdir(parents=True, exist_ok=True)
        shutil.copyfile(mocap_dir / rel, dst)
        dst.write_bytes(dst.read_bytes().replace(b"\r\n", b"\n").replace(b"\n", b"\r\n"))
        return str(dst)

    monkeypatch.delenv(data.ENV_VAR, raising=False)
    monkeypatch.setenv(data.CACHE_ENV_VAR, str(tmp_path))
    monkeypatch.setattr(pooch, "retrieve", fake_retrieve)
    m = data.cmu("16_35")  # auto: no mirror, so the Acclaim files are fetched
    assert m.skeleton.names[0] == "root" and m.n_frames == data.describe("16_35")["frames"]
