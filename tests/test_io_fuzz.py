"""Property test: mutated real files raise MocapFormatError or load; nothing else escapes.

Thousands of mutations of a short real clip (the first frames of CMU 16_35,
as BVH and as ASF/AMC): byte flips, deleted, duplicated and swapped lines,
replaced tokens, truncations and inserted garbage, one to three at a time.
Whatever the reader makes of them, the only exception allowed out of
``load_bvh`` and ``load_asf_amc`` is :class:`MocapFormatError`; a file that
still parses must give a valid, finite Motion.  Examples are derandomised, so
every run checks the same few thousand files.
"""

from __future__ import annotations

import warnings
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from mocaplab import quat
from mocaplab.io import MocapFormatError, load_asf_amc, load_bvh, save_bvh
from mocaplab.io.bvh import FPS_RANGE
from mocaplab.motion import Motion, Skeleton

CLIP = "16_35"
BVH_FRAMES = 40
AMC_FRAMES = 8

TOKENS = [
    b"", b"0", b"-0", b"1", b"-1", b"2.5e-3", b"1e308", b"-1e308", b"1e400", b"5e-324", b"nan", b"inf", b"-inf",
    b"NaN", b"abc", b"1,5", b"1_0", b"0x1F", b"+", b"-", b".", b"e5", b"{", b"}", b"{{", b"ROOT", b"JOINT",
    b"End", b"Site", b"OFFSET", b"CHANNELS", b"MOTION", b"HIERARCHY", b"Frames:", b"Frame", b"Time:",
    b"Xrotation", b"Yposition", b"Wrotation", b"7", b"999999999999", b"-3", b"root", b"lfemur", b"begin",
    b"end", b"dof", b"rx", b"tx", b"l", b"axis", b"XYZ", b"XXY", b"direction", b"length", b":root",
    b":bonedata", b":hierarchy", b":units", b":FULLY-SPECIFIED", b":RADIANS", b"angle", b"rad", b"order",
    b"\t", b"\r", b"\x00", b"\xff", b"\xc3\xa9", b"#", b"(", b")",
    b"1" + b"0" * 20, b"9" * 5000,  # beyond int64, beyond Python's int() digit limit
]

SETTINGS = {
    "deadline": None,
    "derandomize": True,
    "database": None,
    "suppress_health_check": [HealthCheck.too_slow, HealthCheck.data_too_large],
}


def _short_bvh(text: str, frames: int) -> bytes:
    lines = text.split("\n")
    m = lines.index("MOTION")
    head = lines[: m + 1] + [f"Frames: {frames}", lines[m + 2]]
    return ("\n".join(head + lines[m + 3 : m + 3 + frames]) + "\n").encode()


def _short_amc(text: str, frames: int) -> bytes:
    lines = text.replace("\r\n", "\n").split("\n")
    out, count = [], 0
    for line in lines:
        if line.strip().isdigit():
            count += 1
            if count > frames:
                break
        out.append(line)
    return ("\n".join(out) + "\n").encode()


@pytest.fixture(scope="module")
def corpus(tmp_path_factory, mocap_dir):
    """A short real BVH, ASF and AMC (bytes) and a folder to write mutants to."""
    folder = tmp_path_factory.mktemp("fuzz")
    bvh = _short_bvh((mocap_dir / "bvh" / f"{CLIP}.bvh").read_text(), BVH_FRAMES)
    asf = (mocap_dir / "asfamc" / "16" / "16.asf").read_bytes()
    amc = _short_amc((mocap_dir / "asfamc" / "16" / f"{CLIP}.amc").read_text(), AMC_FRAMES)
    (folder / "clip.asf").write_bytes(asf)
    (folder / "clip.amc").write_bytes(amc)
    (folder / "clip.bvh").write_bytes(bvh)
    # the unmutated files load
    load_bvh(folder / "clip.bvh", scale=0.05)
    load_asf_amc(folder / "clip.asf", folder / "clip.amc")
    return {"dir": folder, "bvh": bvh, "asf": asf, "amc": amc}


# ------------------------------------------------------------ mutations

position = st.floats(min_value=0.0, max_value=1.0, allow_nan=False)
mutation = st.one_of(
    st.tuples(st.just("flip"), position, st.integers(0, 255)),
    st.tuples(st.just("delete_line"), position),
    st.tuples(st.just("duplicate_line"), position),
    st.tuples(st.just("swap_lines"), position, position),
    st.tuples(st.just("token"), position, st.integers(0, 12), st.sampled_from(TOKENS)),
    st.tuples(st.just("truncate"), position),
    st.tuples(st.just("insert"), position, st.binary(min_size=1, max_size=12)),
)
# where mutations land: the whole file, or its first part (the hierarchy,
# the ASF, the AMC header) where most of the structure is
mutations = st.tuples(st.sampled_from([1.0, 0.25, 0.05]), st.lists(mutation, min_size=1, max_size=3))


def mutate(data: bytes, plan: tuple[float, list[tuple]]) -> bytes:
    span, ops = plan
    for op in ops:
        kind, where = op[0], op[1]
        lines = data.split(b"\n")
        at_byte = int(where * span * len(data))
        at_line = min(int(where * span * len(lines)), max(len(lines) - 1, 0))
        if kind == "flip" and data:
            i = min(at_byte, len(data) - 1)
            data = data[:i] + bytes([op[2]]) + data[i + 1 :]
        elif kind == "delete_line" and lines:
            del lines[at_line]
            data = b"\n".join(lines)
        elif kind == "duplicate_line" and lines:
            lines.insert(at_line, lines[at_line])
            data = b"\n".join(lines)
        elif kind == "swap_lines" and lines:
            j = min(int(op[2] * span * len(lines)), len(lines) - 1)
            lines[at_line], lines[j] = lines[j], lines[at_line]
            data = b"\n".join(lines)
        elif kind == "token" and lines:
            toks = lines[at_line].split()
            if toks:
                toks[op[2] % len(toks)] = op[3]
            else:
                toks = [op[3]]
            lines[at_line] = b" ".join(toks)
            data = b"\n".join(lines)
        elif kind == "truncate":
            data = data[:at_byte]
        elif kind == "insert":
            data = data[:at_byte] + op[2] + data[at_byte:]
    return data


def check_valid(motion: Motion) -> None:
    assert isinstance(motion, Motion)
    assert motion.n_frames >= 1 and np.isfinite(motion.fps) and motion.fps > 0
    assert np.all(np.isfinite(motion.rotations)) and np.all(np.isfinite(motion.root_positions))
    assert np.allclose(np.linalg.norm(motion.rotations, axis=-1), 1.0)
    assert np.all(np.isfinite(motion.skeleton.offsets))


def try_load(fn, *args, **kwargs) -> None:
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        try:
            motion = fn(*args, **kwargs)
        except MocapFormatError as err:
            assert err.path and err.expected  # file and expectation are named
            return
    check_valid(motion)


# ---------------------------------------------------------------- tests


@settings(max_examples=1200, **SETTINGS)
@given(plan=mutations, estimate=st.booleans())
def test_mutated_bvh(corpus, plan, estimate):
    path = corpus["dir"] / "mutant.bvh"
    path.write_bytes(mutate(corpus["bvh"], plan))
    try_load(load_bvh, path, scale=None if estimate else 0.056)


@settings(max_examples=700, **SETTINGS)
@given(plan=mutations)
def test_mutated_asf(corpus, plan):
    folder: Path = corpus["dir"]
    path = folder / "mutant.asf"
    path.write_bytes(mutate(corpus["asf"], plan))
    try_load(load_asf_amc, path, folder / "clip.amc")


@settings(max_examples=700, **SETTINGS)
@given(plan=mutations)
def test_mutated_amc(corpus, plan):
    folder: Path = corpus["dir"]
    path = folder / "mutant.amc"
    path.write_bytes(mutate(corpus["amc"], plan))
    try_load(load_asf_amc, folder / "clip.asf", path)


@pytest.mark.parametrize("cut", [0, 1, 7, 100, 1000, 3000])
def test_every_prefix_kind(corpus, cut):
    """Truncations at fixed points of each file (beside the random ones)."""
    folder: Path = corpus["dir"]
    (folder / "cut.bvh").write_bytes(corpus["bvh"][:cut])
    (folder / "cut.asf").write_bytes(corpus["asf"][:cut])
    (folder / "cut.amc").write_bytes(corpus["amc"][:cut])
    try_load(load_bvh, folder / "cut.bvh", scale=0.05)
    try_load(load_asf_amc, folder / "cut.asf", folder / "clip.amc")
    try_load(load_asf_amc, folder / "clip.asf", folder / "cut.amc")


# ------------------------------------------------- headers and names (issue 17)


def _replace_line(data: bytes, startswith: bytes, new: bytes, nth: int = 0) -> bytes:
    lines = data.split(b"\n")
    hits = [i for i, line in enumerate(lines) if line.strip().startswith(startswith)]
    lines[hits[nth % len(hits)]] = new
    return b"\n".join(lines)


# integers as digit strings (str() of a 5000-digit int would itself hit Python's digit limit)
integers = st.one_of(st.integers(0, 10**25).map(str), st.integers(1, 6000).map(lambda n: "7" * n))


@settings(max_examples=150, **SETTINGS)
@given(value=integers, where=st.sampled_from(["Frames:", "CHANNELS"]), nth=st.integers(0, 40))
def test_bvh_header_integers_of_any_size(corpus, value, where, nth):
    """Any integer in a CHANNELS or Frames: header: MocapFormatError or a valid Motion, nothing else."""
    digits = value.encode()
    data = corpus["bvh"]
    if where == "Frames:":
        data = _replace_line(data, b"Frames:", b"Frames: " + digits)
    else:
        data = _replace_line(data, b"CHANNELS", b"CHANNELS " + digits + b" Zrotation Yrotation Xrotation", nth)
    path = corpus["dir"] / "header.bvh"
    path.write_bytes(data)
    try_load(load_bvh, path, scale=0.056)


@settings(max_examples=100, **SETTINGS)
@given(value=integers, nth=st.integers(0, AMC_FRAMES - 1))
def test_amc_frame_numbers_of_any_size(corpus, value, nth):
    lines = corpus["amc"].split(b"\n")
    frames = [i for i, line in enumerate(lines) if line.strip().isdigit()]
    lines[frames[nth]] = value.encode()
    path = corpus["dir"] / "frames.amc"
    path.write_bytes(b"\n".join(lines))
    try_load(load_asf_amc, corpus["dir"] / "clip.asf", path)


@settings(max_examples=300, **SETTINGS)
@given(frame_time=st.floats(allow_nan=True, allow_infinity=True) | st.floats(1e-6, 20.0))
def test_frame_time_gives_a_plausible_rate_or_a_format_error(corpus, frame_time):
    data = _replace_line(corpus["bvh"], b"Frame Time:", f"Frame Time: {frame_time!r}".encode())
    path = corpus["dir"] / "rate.bvh"
    path.write_bytes(data)
    try:
        motion = load_bvh(path, scale=0.056)
    except MocapFormatError as err:
        assert err.line > 0 and "Frame Time" in err.expected
        return
    assert FPS_RANGE[0] <= motion.fps <= FPS_RANGE[1]


name_chars = st.one_of(
    st.characters(),
    st.sampled_from(list(" \t\n\r\x00\x0b\x0c\x1c\x85\xa0\u2028{}#\ufeff") + ["\ud800"]),
)
names = st.one_of(
    st.text(name_chars, max_size=10),
    st.lists(st.sampled_from(["{", "}", "End", "Site", "JOINT", "ROOT", "OFFSET", "CHANNELS", "MOTION", "a", "b{"]),
             min_size=1, max_size=3).map(" ".join),
)


@settings(max_examples=400, **SETTINGS)
@given(name=names)
def test_save_bvh_writes_only_names_it_reads_back(corpus, name):
    """save_bvh either refuses a joint name (ValueError naming it) or load_bvh gives the same name back."""
    sk = Skeleton(["root", name], [-1, 0], [[0.0, 0.0, 0.0], [0.0, 0.1, 0.0]])
    motion = Motion(sk, quat.identity((1, 2)), np.zeros((1, 3)), 30.0)
    path = corpus["dir"] / "named.bvh"
    if path.exists():
        path.unlink()
    try:
        save_bvh(motion, path)
    except ValueError as err:
        assert repr(name) in str(err) and "cannot be written to a BVH file" in str(err)
        assert not path.exists()
        return
    assert load_bvh(path, scale=0.01).skeleton.names == ("root", name)
