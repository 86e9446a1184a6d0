"""glTF 2.0: save_gltf/load_gltf round trips, hand-built STEP/LINEAR/CUBICSPLINE samplers, bad files, Blender."""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

import mocaplab as ml
from mocaplab import quat
from mocaplab.io import MocapFormatError, load_gltf, save_gltf

g = pytest.importorskip("pygltflib")


@pytest.fixture(scope="module")
def walk(mocap_dir: Path) -> ml.Motion:
    return ml.load(mocap_dir / "bvh" / "16_15.bvh", scale=0.0254 / 0.45)


@pytest.mark.parametrize("ext", ["glb", "gltf", "GLB"])
def test_round_trip(walk: ml.Motion, tmp_path: Path, ext: str) -> None:
    path = tmp_path / f"walk.{ext}"
    save_gltf(walk, path)
    back = ml.load(path)
    assert back.skeleton.names == walk.skeleton.names and back.n_frames == walk.n_frames
    assert back.fps == 120.0  # from the key spacing, snapped by load
    error = np.abs(back.global_positions() - walk.global_positions()).max()
    assert error < 1e-5  # float32 in the file; measured 5e-7 m
    assert dict(back.skeleton.roles) == dict(walk.skeleton.roles)


def test_long_clip_keeps_every_frame_on_its_key(mocap_dir: Path, tmp_path: Path) -> None:
    """float32 key times read as 120.0001 fps; the rate is snapped, so frame 1503 still falls on its key."""
    hops = ml.load(mocap_dir / "bvh" / "49_03.bvh", scale=0.0254 / 0.45)
    save_gltf(hops, tmp_path / "hops.glb")
    back = load_gltf(tmp_path / "hops.glb")
    assert back.fps == 120.0 and back.n_frames == hops.n_frames == 1504
    assert np.abs(back.global_positions() - hops.global_positions()).max() < 1e-5  # measured 1.4e-6 m


def test_round_trip_with_animated_translations(walk: ml.Motion, tmp_path: Path) -> None:
    clip = walk[:40]
    stretch = np.repeat(clip.skeleton.offsets[None], clip.n_frames, axis=0)
    stretch[:, 1:] *= 1.0 + 0.2 * np.sin(np.linspace(0, 3, clip.n_frames))[:, None, None]
    moving = clip.replace(translations=stretch)
    save_gltf(moving, tmp_path / "s.glb")
    back = load_gltf(tmp_path / "s.glb")
    assert back.translations is not None
    assert np.abs(back.global_positions() - moving.global_positions()).max() < 1e-4


def test_export_is_atomic(walk: ml.Motion, tmp_path: Path) -> None:
    path = tmp_path / "walk.glb"
    path.write_bytes(b"old")
    with pytest.raises(ValueError, match=r"end in \.glb or \.gltf"):
        save_gltf(walk, tmp_path / "walk.fbx")
    save_gltf(walk[:5], path)
    assert path.read_bytes()[:4] == b"glTF"
    assert [p.name for p in tmp_path.iterdir()] == ["walk.glb"]  # no temporary file left


# ------------------------------------------------------------ hand-built file
def _hand_built(tmp_path: Path, *, translation_interp: str, rotation_interp: str) -> Path:
    """Root -> arm (0, 1, 0) -> tip (0, 1, 0). Root translation keys at 0 and 1 s; arm rotation keys at 0, 0.5, 1 s."""
    blob = bytearray()
    views, accessors = [], []

    def add(values, kind):
        data = np.asarray(values, dtype="<f4")
        views.append(g.BufferView(buffer=0, byteOffset=len(blob), byteLength=data.nbytes))
        blob.extend(data.tobytes())
        accessors.append(g.Accessor(bufferView=len(views) - 1, componentType=g.FLOAT, count=len(data), type=kind))
        return len(accessors) - 1

    t2, t3 = add([0.0, 1.0], "SCALAR"), add([0.0, 0.5, 1.0], "SCALAR")
    if translation_interp == "CUBICSPLINE":  # (in-tangent, value, out-tangent) per key
        moves = add([[0, 0, 0], [0, 0, 0], [2, 0, 0], [0, 0, 0], [1, 0, 0], [0, 0, 0]], "VEC3")
    else:
        moves = add([[0, 0, 0], [1, 0, 0]], "VEC3")
    z = [quat.from_axis_angle([0, 0, 1], np.radians(a)) for a in (0, 90, 180)]
    turns = add(z, "VEC4")
    doc = g.GLTF2(
        asset=g.Asset(version="2.0"),
        nodes=[
            g.Node(name="root", children=[1]),
            g.Node(name="arm", translation=[0, 1, 0], children=[2]),
            g.Node(name="tip", translation=[0, 1, 0]),
        ],
        skins=[g.Skin(joints=[0, 1, 2])],
        animations=[
            g.Animation(
                samplers=[
                    g.AnimationSampler(input=t2, output=moves, interpolation=translation_interp),
                    g.AnimationSampler(input=t3, output=turns, interpolation=rotation_interp),
                ],
                channels=[
                    g.AnimationChannel(sampler=0, target=g.AnimationChannelTarget(node=0, path="translation")),
                    g.AnimationChannel(sampler=1, target=g.AnimationChannelTarget(node=1, path="rotation")),
                ],
            )
        ],
        accessors=accessors,
        bufferViews=views,
        buffers=[g.Buffer(byteLength=len(blob))],
    )
    doc.set_binary_blob(bytes(blob))
    path = tmp_path / f"{translation_interp}_{rotation_interp}.glb"
    path.write_bytes(b"".join(doc.save_to_bytes()))
    return path


def test_step_and_cubic_spline_samplers(tmp_path: Path) -> None:
    m = load_gltf(_hand_built(tmp_path, translation_interp="CUBICSPLINE", rotation_interp="STEP"), fps=4)
    assert m.n_frames == 5 and m.skeleton.names == ("root", "arm", "tip")
    s = np.linspace(0, 1, 5)
    # Hermite with v0 = 0, out-tangent 2, v1 = 1, in-tangent 0, interval 1 s: x = 2 s - s^2
    assert np.allclose(m.root_positions[:, 0], 2 * s - s * s, atol=1e-6)
    # STEP holds each key until the next: 0, 0, 90, 90, 180 degrees about Z
    tip = m.global_positions()[:, 2] - m.global_positions()[:, 1]
    assert np.allclose(tip, [[0, 1, 0], [0, 1, 0], [-1, 0, 0], [-1, 0, 0], [0, -1, 0]], atol=1e-6)


def test_linear_samplers(tmp_path: Path) -> None:
    m = load_gltf(_hand_built(tmp_path, translation_interp="LINEAR", rotation_interp="LINEAR"), fps=8)
    assert np.allclose(m.root_positions[:, 0], np.linspace(0, 1, 9), atol=1e-6)
    tip = m.global_positions()[:, 2] - m.global_positions()[:, 1]
    angle = np.radians(np.linspace(0, 180, 9))  # spherical: evenly in angle, not in chord
    assert np.allclose(tip, np.stack([-np.sin(angle), np.cos(angle), 0 * angle], axis=1), atol=1e-6)


def test_default_rate_is_the_key_rate(tmp_path: Path) -> None:
    m = load_gltf(_hand_built(tmp_path, translation_interp="LINEAR", rotation_interp="LINEAR"))
    assert m.fps == 2.0 and m.n_frames == 3  # keys 0.5 s apart (the densest sampler)


# ------------------------------------------------------------------ bad files
def test_bad_files(walk: ml.Motion, tmp_path: Path) -> None:
    path = tmp_path / "x.glb"
    path.write_bytes(b"HIERARCHY\n")
    with pytest.raises(MocapFormatError, match=r"x\.glb: expected a glTF file .*HIERARCHY"):
        load_gltf(path)
    save_gltf(walk[:10], path)
    raw = path.read_bytes()
    path.write_bytes(raw[: len(raw) // 2])
    with pytest.raises(MocapFormatError, match="truncated"):
        load_gltf(path)
    doc = json.loads(raw[20 : 20 + int.from_bytes(raw[12:16], "little")])
    doc["accessors"][5]["count"] = 2**40  # a count the buffer cannot hold
    bad = tmp_path / "bad.gltf"
    doc["buffers"][0]["uri"] = "data:application/octet-stream;base64,AAAA"
    doc["buffers"][0]["byteLength"] = 3
    bad.write_text(json.dumps(doc))
    with pytest.raises(MocapFormatError, match=r"bad\.gltf: expected accessor \d+ .*within its bufferView"):
        load_gltf(bad)
    for key in ("skins", "animations"):
        broken = dict(doc)
        broken.pop(key)
        (tmp_path / "b.gltf").write_text(json.dumps(broken))
        with pytest.raises(MocapFormatError, match=rf"b\.gltf: expected .*\('{key}'\), got none"):
            load_gltf(tmp_path / "b.gltf")


# --------------------------------------------------------------------- Blender
_BLENDER_SCRIPT = """
import bpy, json, sys
bpy.context.scene.render.fps = {fps}
bpy.ops.import_scene.gltf(filepath={path!r})
arm = next(o for o in bpy.context.scene.objects if o.type == "ARMATURE")
start = int(min(fc.range()[0] for fc in arm.animation_data.action.fcurves))
out = {{}}
for f in range({frames}):
    bpy.context.scene.frame_set(start + f)
    for b in arm.pose.bones:
        out.setdefault(b.name, []).append(list(arm.matrix_world @ b.head))
json.dump(out, open({out!r}, "w"))
"""


@pytest.mark.skipif(shutil.which("blender") is None, reason="Blender is not installed (Debian package 'blender')")
def test_blender_reads_the_export(walk: ml.Motion, tmp_path: Path) -> None:
    """Blender's own glTF importer plays the exported GLB: its bone heads are our joints within 1 mm."""
    clip = walk[:60]
    path, out = tmp_path / "walk.glb", tmp_path / "heads.json"
    save_gltf(clip, path)
    script = _BLENDER_SCRIPT.format(fps=int(clip.fps), path=str(path), frames=clip.n_frames, out=str(out))
    # Blender finds its Python's library from the first python3 on PATH: keep the test runner's interpreter off it
    ours = {os.path.realpath(os.path.dirname(x)) for x in (sys.executable, os.path.realpath(sys.executable))}
    ours |= {os.path.realpath(os.path.join(prefix, "bin")) for prefix in (sys.prefix, sys.base_prefix)}
    path_var = os.pathsep.join(p for p in os.environ.get("PATH", "").split(os.pathsep) if os.path.realpath(p) not in ours)
    done = subprocess.run(
        ["blender", "-b", "--factory-startup", "--python-expr", script],
        capture_output=True,
        text=True,
        timeout=300,
        env=dict(os.environ, PATH=path_var),
    )
    assert out.exists(), done.stdout[-2000:] + done.stderr[-2000:]
    heads = json.loads(out.read_text())
    positions = clip.global_positions()
    # Blender is Z up: glTF (x, y, z) is Blender (x, -z, y)
    errors = []
    for j, joint in enumerate(clip.skeleton.names):
        b = np.array(heads[joint])
        ours = np.stack([positions[:, j, 0], -positions[:, j, 2], positions[:, j, 1]], axis=1)
        errors.append(np.abs(b - ours).max())
    print(f"Blender vs mocaplab: max joint error {max(errors) * 1000:.4f} mm")
    assert max(errors) < 1e-3
