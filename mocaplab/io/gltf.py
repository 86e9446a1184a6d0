"""glTF 2.0 (``.gltf`` and ``.glb``): a skin's joints and one animation, read and written.

:func:`load_gltf` reads the joints of a skin and samples one animation of
them; :func:`save_gltf` writes a Motion as a joint hierarchy with a skin and
one animation, which Blender, three.js and game engines play.  Both use
pygltflib for the file's structure (JSON, GLB chunks, data URIs); the
sampling is numpy.

Reading
-------
* **Skeleton.** The joints of the first skin (or ``skin=``, an index or a
  name); a joint's parent is its nearest ancestor node that is a joint, and
  nodes above the root joint move the skeleton too.  Joints are in
  depth-first order of the node tree and keep their names (a node without a
  name is ``joint<index>``).
* **Animation.** The first animation (or ``animation=``), its rotation,
  translation and scale channels on those nodes (morph weights are ignored),
  with ``LINEAR`` (spherical for rotations), ``STEP`` and ``CUBICSPLINE``
  samplers as the specification defines them (cubic Hermite with the
  in/out tangents scaled by the key interval; rotations normalised).  It is
  sampled from its first key time to its last at ``fps``; glTF stores no
  frame rate, so by default the rate is that of the keys of the densest
  channel (over its whole span when they are evenly spaced, else one over
  the median interval), snapped to an integer or NTSC rate within
  :data:`KEY_RATE_TOLERANCE` (key times are float32).
* glTF is metres and Y up by definition, so nothing is converted.
* Accessors of float, or of normalised integers (rotations may be stored so),
  are read; every accessor, buffer view and buffer is checked against the
  bytes present before it is viewed, so no count in the JSON can make the
  reader allocate beyond the file.  External buffers are read from files
  beside the ``.gltf`` (relative paths only).

Every problem raises :class:`~mocaplab.io.MocapFormatError` naming the file.

Writing
-------
:func:`save_gltf` writes one node per joint (rest translation = the joint's
offset, no rest rotation), a skin over them with inverse bind matrices, and
one animation: a ``LINEAR`` rotation channel per joint, a translation channel
for the root (and for every joint when the motion has animated
translations), at the motion's frame times.  Values are float32 (as glTF
requires), so a round trip gives world positions within 1e-5 m.  The file is
written atomically (:func:`mocaplab._atomic.atomic_write`).
"""

from __future__ import annotations

import base64
import json
import math
import os
from collections.abc import Sequence
from os import PathLike
from typing import Any

import numpy as np
from numpy.typing import NDArray

from .. import quat
from .._atomic import atomic_write
from ..motion import FPS_RANGE, Motion
from ._hierarchy import motion_from_transforms
from .bvh import as_path, read_bytes
from .errors import MocapFormatError

__all__ = ["load_gltf", "save_gltf", "DEFAULT_FPS", "KEY_RATE_TOLERANCE"]

#: Frame rate of a clip whose keys have no regular spacing to take the rate from.
DEFAULT_FPS = 30.0

#: Relative distance within which the rate of the keys is snapped to an
#: integer or NTSC rate: key times are float32, so 120 fps keys read as
#: 120.0001 fps, and sampling at that rate would drift off the keys.
KEY_RATE_TOLERANCE = 1e-4

_GLB_MAGIC = b"glTF"
_COMPONENTS = {"SCALAR": 1, "VEC2": 2, "VEC3": 3, "VEC4": 4, "MAT4": 16}
# componentType -> (dtype, divisor for normalised integers)
_DTYPES: dict[int, tuple[np.dtype[Any], float | None]] = {
    5126: (np.dtype("<f4"), None),
    5120: (np.dtype("i1"), 127.0),
    5121: (np.dtype("u1"), 255.0),
    5122: (np.dtype("<i2"), 32767.0),
    5123: (np.dtype("<u2"), 65535.0),
    5125: (np.dtype("<u4"), None),
}
_PATHS = {"translation": (0, 3), "rotation": (3, 7), "scale": (7, 10)}


# ------------------------------------------------------------------ reading
def load_gltf(
    path: str | bytes | PathLike[str],
    *,
    animation: str | int | None = None,
    skin: str | int | None = None,
    fps: float | None = None,
    name: str | None = None,
) -> Motion:
    """Read a skin's joints and one animation of a glTF 2.0 file into a Motion.

    Parameters
    ----------
    path : str or path-like
        A ``.gltf`` (JSON) or ``.glb`` (binary) file.
    animation : str or int, optional
        The animation to read, by name or index; default the first.
    skin : str or int, optional
        The skin whose joints form the skeleton, by name or index; default the first.
    fps : float, optional
        Frames per second to sample at; default the rate of the keys.
    name : str, optional
        Label for the motion (default: the file stem).

    Returns
    -------
    Motion
        ``rotations`` shape (F, J, 4), ``root_positions`` shape (F, 3) in metres, Y up.

    Raises
    ------
    MocapFormatError
        For any problem with the file, naming it.
    ValueError
        For an ``fps`` outside :data:`~mocaplab.motion.FPS_RANGE`.

    Examples
    --------
    A round trip through a binary glTF file:

    >>> import tempfile
    >>> from pathlib import Path
    >>> import numpy as np
    >>> from mocaplab.data import cmu
    >>> walk = cmu("16_15")
    >>> with tempfile.TemporaryDirectory() as folder:
    ...     save_gltf(walk, Path(folder) / "walk.glb")
    ...     back = load_gltf(Path(folder) / "walk.glb")
    >>> back.n_frames, back.fps, bool(np.abs(back.global_positions() - walk.global_positions()).max() < 1e-5)
    (471, 120.0, True)
    """
    file = as_path(path)
    if fps is not None and not (isinstance(fps, (int, float, np.number)) and FPS_RANGE[0] <= fps <= FPS_RANGE[1]):
        raise ValueError(f"Expected `fps` from {FPS_RANGE[0]:g} to {FPS_RANGE[1]:g} frames per second, got {fps!r}")
    doc, blob = _document(file, read_bytes(file, "a glTF file"))
    reader = _Reader(file, doc, blob)
    nodes = reader.list("nodes")
    order, parents, joints = _skeleton(reader, nodes, skin)
    channels = _channels(reader, order, animation)
    times, rate = _frame_times(file, channels, fps)
    rest = np.array([_rest_trs(reader, nodes[k], k) for k in order])
    local = np.repeat(rest[None], len(times), axis=0)
    position = {k: i for i, k in enumerate(order)}
    for node, path_name, key_times, values, interp in channels:
        lo, hi = _PATHS[path_name]
        local[:, position[node], lo:hi] = _sample(key_times, values, interp, times, rotation=path_name == "rotation")
    names = [str(nodes[order[k]].get("name") or f"joint{order[k]}") for k in joints]
    return motion_from_transforms(file, local, rest[None], parents, joints=joints, names=names, fps=rate, name=name)


def _document(path: str, raw: bytes) -> tuple[dict[str, Any], bytes | None]:
    """The JSON document and the GLB binary chunk (None for ``.gltf``)."""
    if raw.startswith(_GLB_MAGIC):
        if len(raw) < 20:
            raise MocapFormatError(path, 0, "a GLB header of 12 bytes and a JSON chunk", f"{len(raw)} bytes (truncated)")
        version, length = np.frombuffer(raw, "<u4", 2, 4)
        if version != 2:
            raise MocapFormatError(path, 0, "glTF version 2", f"version {version}")
        if length > len(raw):
            raise MocapFormatError(path, 0, f"a GLB file of {length:,} bytes (its header)", f"{len(raw):,} bytes (truncated)")
        chunks: dict[int, bytes] = {}
        at = 12
        while at + 8 <= length:
            size, kind = (int(v) for v in np.frombuffer(raw, "<u4", 2, at))
            if at + 8 + size > length:
                raise MocapFormatError(path, 0, f"a GLB chunk of {size:,} bytes at byte {at:,}", "a truncated file")
            chunks.setdefault(kind, raw[at + 8 : at + 8 + size])
            at += 8 + size
        text = chunks.get(0x4E4F534A)
        if text is None:
            raise MocapFormatError(path, 0, "a JSON chunk in the GLB file", "none")
        blob = chunks.get(0x004E4942)
    else:
        text, blob = raw, None
    try:
        doc = json.loads(text.decode("utf-8-sig"))
    except (UnicodeDecodeError, ValueError) as exc:
        got = f"bytes starting {raw[:16]!r}" if not raw.lstrip().startswith(b"{") else f"invalid JSON ({exc})"
        raise MocapFormatError(path, 0, "a glTF file (JSON, or binary GLB starting 'glTF')", got) from None
    if not isinstance(doc, dict) or not isinstance(doc.get("asset"), dict):
        raise MocapFormatError(path, 0, "a glTF document (a JSON object with an 'asset')", type(doc).__name__)
    version = str(doc["asset"].get("version", ""))
    if not version.startswith("2."):
        raise MocapFormatError(path, 0, "glTF version 2.x ('asset.version')", repr(version))
    return doc, blob


class _Reader:
    """Checked access to a glTF document's arrays, buffers and accessors."""

    def __init__(self, path: str, doc: dict[str, Any], blob: bytes | None):
        self.path, self.doc, self.blob = path, doc, blob
        self._buffers: dict[int, bytes] = {}

    def fail(self, expected: str, got: str) -> MocapFormatError:
        return MocapFormatError(self.path, 0, expected, got)

    def list(self, key: str) -> list[dict[str, Any]]:
        items = self.doc.get(key, [])
        if not isinstance(items, list) or not all(isinstance(i, dict) for i in items):
            raise self.fail(f"'{key}' to be a list of objects", type(items).__name__)
        return items

    def item(self, key: str, index: Any, where: str) -> dict[str, Any]:
        items = self.list(key)
        if isinstance(index, bool) or not isinstance(index, int) or not 0 <= index < len(items):
            raise self.fail(f"{where} to be an index into '{key}' (0 to {len(items) - 1})", repr(index))
        return items[index]

    def buffer(self, index: int) -> bytes:
        if index not in self._buffers:
            buf = self.item("buffers", index, "a bufferView's 'buffer'")
            uri = buf.get("uri")
            if uri is None:
                if self.blob is None:
                    raise self.fail(f"buffer {index} in the GLB binary chunk", "no binary chunk")
                data = self.blob
            elif isinstance(uri, str) and uri.startswith("data:"):
                try:
                    data = base64.b64decode(uri.split(",", 1)[1], validate=True)
                except (IndexError, ValueError):
                    raise self.fail(f"buffer {index} as a base64 data URI", f"{uri[:40]!r}") from None
            elif isinstance(uri, str) and not os.path.isabs(uri) and ".." not in uri.split("/"):
                data = read_bytes(os.path.join(os.path.dirname(self.path), uri), "a glTF buffer file")
            else:
                raise self.fail(f"buffer {index} as a data URI or a file beside the .gltf", repr(uri))
            length = buf.get("byteLength")
            if not isinstance(length, int) or length > len(data):
                raise self.fail(f"buffer {index} of byteLength {length!r}", f"{len(data):,} bytes (truncated)")
            self._buffers[index] = data
        return self._buffers[index]

    def accessor(self, index: Any, where: str) -> NDArray[np.float64]:
        """The accessor's elements as floats, shape (count, components); normalised integers divided out."""
        acc = self.item("accessors", index, where)
        kind, ctype, count = acc.get("type"), acc.get("componentType"), acc.get("count")
        if kind not in _COMPONENTS or ctype not in _DTYPES or not isinstance(count, int) or count < 1:
            raise self.fail(
                f"accessor {index} with a type, a float or integer componentType and a count >= 1",
                f"type {kind!r}, componentType {ctype!r}, count {count!r}",
            )
        if "bufferView" not in acc:
            raise self.fail(f"accessor {index} with a bufferView (sparse accessors are not read)", "none")
        view = self.item("bufferViews", acc["bufferView"], f"accessor {index}'s 'bufferView'")
        data = self.buffer(view.get("buffer"))  # type: ignore[arg-type]  # checked by item()
        dtype, norm = _DTYPES[ctype]
        width = _COMPONENTS[kind] * dtype.itemsize
        stride = view.get("byteStride") or width
        start = int(view.get("byteOffset", 0)) + int(acc.get("byteOffset", 0))
        view_end = int(view.get("byteOffset", 0)) + int(view.get("byteLength", 0))
        need = start + (count - 1) * stride + width
        if stride < width or need > min(view_end, len(data)) or start < 0:
            raise self.fail(
                f"accessor {index} ({count:,} x {kind}) within its bufferView and buffer",
                f"{need:,} bytes needed, {min(view_end, len(data)):,} present",
            )
        rows = np.lib.stride_tricks.as_strided(
            np.frombuffer(data, dtype=np.uint8, count=need - start, offset=start),
            shape=(count, width),
            strides=(stride, 1),
        )
        values = np.ascontiguousarray(rows).view(dtype).reshape(count, _COMPONENTS[kind]).astype(float)
        if norm is not None and ctype != 5125:
            values = np.maximum(values / norm, -1.0)
        if not np.all(np.isfinite(values)):
            raise self.fail(f"finite values in accessor {index}", "NaN or inf")
        return values


def _pick(reader: _Reader, key: str, wanted: str | int | None, what: str) -> tuple[int, dict[str, Any]]:
    items = reader.list(key)
    names = [i.get("name") for i in items]
    if not items:
        raise reader.fail(f"{what} ('{key}')", "none")
    if wanted is None:
        return 0, items[0]
    if isinstance(wanted, int) and not isinstance(wanted, bool):
        if 0 <= wanted < len(items):
            return wanted, items[wanted]
        raise reader.fail(f"a {what} index below {len(items)}", repr(wanted))
    if wanted in names:
        k = names.index(wanted)
        return k, items[k]
    raise reader.fail(f"a {what} named {wanted!r}", f"{key} {names}")


def _skeleton(
    reader: _Reader, nodes: list[dict[str, Any]], skin: str | int | None
) -> tuple[list[int], list[int], list[int]]:
    """Node indices composed (nodes above the root joint, then the skeleton depth first), their parents, the joints."""
    _, chosen = _pick(reader, "skins", skin, "skin (the skeleton's joints)")
    joints = chosen.get("joints")
    if not isinstance(joints, list) or not joints:
        raise reader.fail("a skin with a list of joints", repr(joints))
    parent = [-1] * len(nodes)
    for i, node in enumerate(nodes):
        for c in node.get("children", []):
            if isinstance(c, bool) or not isinstance(c, int) or not 0 <= c < len(nodes) or parent[c] != -1 or c == i:
                raise reader.fail(f"node {i}'s children to be other nodes, each with one parent", repr(c))
            parent[c] = i
    joint_set = set()
    for j in joints:
        reader.item("nodes", j, "a skin joint")
        joint_set.add(j)

    def joint_above(i: int) -> bool:
        p, seen = parent[i], 0
        while p >= 0:
            if p in joint_set:
                return True
            p, seen = parent[p], seen + 1
            if seen > len(nodes):
                raise reader.fail("a node tree without cycles", f"a cycle through node {i}")
        return False

    roots = [j for j in joints if not joint_above(j)]
    if len(roots) != 1:
        names = [nodes[r].get("name", r) for r in roots]
        raise reader.fail("a skin whose joints form one tree", f"{len(roots)} root joints {names}")
    above = []
    p = parent[roots[0]]
    while p >= 0:
        above.append(p)
        p = parent[p]
    above.reverse()
    below_joint = set()  # nodes with a joint among their descendants
    for j in joint_set:
        p = parent[j]
        while p >= 0 and p not in below_joint:
            below_joint.add(p)
            p = parent[p]
    order = list(above)
    stack = [roots[0]]
    while stack:
        i = stack.pop()
        if i in joint_set or i in below_joint:  # joints, and nodes between joints (folded into their motion)
            order.append(i)
        stack.extend(reversed(nodes[i].get("children", [])))
    position = {k: n for n, k in enumerate(order)}
    return order, [position.get(parent[k], -1) for k in order], [n for n, k in enumerate(order) if k in joint_set]


def _rest_trs(reader: _Reader, node: dict[str, Any], index: int) -> list[float]:
    """A node's rest ``(t, q, s)`` from its TRS properties or its matrix."""
    if "matrix" in node:
        m = np.asarray(node["matrix"], dtype=float)
        if m.shape != (16,) or not np.all(np.isfinite(m)):
            raise reader.fail(f"node {index}'s matrix as 16 numbers", repr(node["matrix"])[:60])
        m = m.reshape(4, 4).T  # column-major
        scale = np.linalg.norm(m[:3, :3], axis=0)
        if np.any(scale < 1e-12) or np.linalg.det(m[:3, :3]) < 0:
            raise reader.fail(f"node {index}'s matrix to be a rotation with positive scale", "a degenerate or mirrored one")
        return [*m[:3, 3], *quat.from_matrix(m[:3, :3] / scale), *scale]
    out: list[float] = []
    for key, default in (("translation", [0.0, 0.0, 0.0]), ("rotation", [0.0, 0.0, 0.0, 1.0]), ("scale", [1.0] * 3)):
        value = node.get(key, default)
        if not isinstance(value, list) or len(value) != len(default) or not all(
            isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v) for v in value
        ):
            raise reader.fail(f"node {index}'s {key} as {len(default)} numbers", repr(value)[:60])
        out.extend(float(v) for v in value)
    return out


def _channels(
    reader: _Reader, order: Sequence[int], animation: str | int | None
) -> list[tuple[int, str, NDArray[np.float64], NDArray[np.float64], str]]:
    """``(node, path, key times, values, interpolation)`` of the animation's channels on the composed nodes."""
    k, anim = _pick(reader, "animations", animation, "animation")
    samplers = anim.get("samplers", [])
    wanted = set(order)
    out = []
    for c, channel in enumerate(anim.get("channels", [])):
        target = channel.get("target", {}) if isinstance(channel, dict) else {}
        node, path_name = target.get("node"), target.get("path")
        if path_name not in _PATHS or node not in wanted:
            continue
        s = channel.get("sampler")
        if isinstance(s, bool) or not isinstance(s, int) or not 0 <= s < len(samplers):
            raise reader.fail(f"channel {c} of animation {k} to name one of its {len(samplers)} samplers", repr(s))
        sampler = samplers[s]
        interp = sampler.get("interpolation", "LINEAR")
        if interp not in ("LINEAR", "STEP", "CUBICSPLINE"):
            raise reader.fail("interpolation LINEAR, STEP or CUBICSPLINE", repr(interp))
        times = reader.accessor(sampler.get("input"), f"sampler {s}'s 'input'")[:, 0]
        values = reader.accessor(sampler.get("output"), f"sampler {s}'s 'output'")
        width = 4 if path_name == "rotation" else 3
        per_key = 3 if interp == "CUBICSPLINE" else 1
        if values.shape != (per_key * len(times), width) or np.any(np.diff(times) <= 0):
            raise reader.fail(
                f"sampler {s} with increasing key times and {per_key} x {width} values per key ({len(times)} keys)",
                f"{values.shape[0]} values of {values.shape[1]}",
            )
        out.append((node, path_name, times, values, interp))
    if not out:
        raise reader.fail(f"rotation or translation channels on the skin's joints in animation {k}", "none")
    return out


def _frame_times(path: str, channels: list[Any], fps: float | None) -> tuple[NDArray[np.float64], float]:
    begin = min(float(c[2][0]) for c in channels)
    end = max(float(c[2][-1]) for c in channels)
    densest = max(channels, key=lambda c: len(c[2]))[2]
    if fps is None:
        steps = np.diff(densest)
        fps = float(1.0 / np.median(steps)) if steps.size else DEFAULT_FPS
        if steps.size and np.ptp(steps) <= 1e-3 * np.median(steps):  # evenly keyed: the rate of the whole span
            fps = (len(densest) - 1) / float(densest[-1] - densest[0])
        for rate in (float(round(fps)), 24000 / 1001, 30000 / 1001, 60000 / 1001):
            if rate > 0 and abs(fps - rate) <= KEY_RATE_TOLERANCE * rate:  # float32 key times: snap, or frames drift
                fps = rate
                break
        if not FPS_RANGE[0] <= fps <= FPS_RANGE[1]:
            fps = DEFAULT_FPS
    n = int(math.floor((end - begin) * fps + 1e-3)) + 1  # key times may be float32
    most = max(len(c[2]) for c in channels)
    limit = max(100_000, 2 * most)
    if n > limit:
        raise MocapFormatError(
            path, 0, f"an animation of at most {limit:,} frames at {fps:g} fps", f"{n:,} frames; pass a lower fps="
        )
    return begin + np.arange(n) / fps, float(fps)


def _sample(
    keys: NDArray[np.float64], values: NDArray[np.float64], interp: str, times: NDArray[np.float64], *, rotation: bool
) -> NDArray[np.float64]:
    """A sampler's value at ``times`` (clamped to its keys), shape (T, width)."""
    if interp == "CUBICSPLINE":
        triples = values.reshape(len(keys), 3, -1)
        a, v, b = triples[:, 0], triples[:, 1], triples[:, 2]  # in-tangent, value, out-tangent
    else:
        v = values
    if rotation:
        v = quat.unroll(v, axis=0) if interp != "CUBICSPLINE" else v
    if len(keys) == 1:
        out = np.repeat(v[:1], len(times), axis=0)
        return quat.normalize(out) if rotation else out
    t = np.clip(times, keys[0], keys[-1])
    i = np.clip(np.searchsorted(keys, t, side="right") - 1, 0, len(keys) - 2)
    dt = keys[i + 1] - keys[i]
    s = ((t - keys[i]) / dt)[:, None]
    if interp == "STEP":
        at_end = t >= keys[-1]
        out = np.where(at_end[:, None], v[-1], v[i])
    elif interp == "LINEAR":
        if rotation:
            out = quat.slerp(v[i], v[i + 1], s[:, 0])
        else:
            out = (1 - s) * v[i] + s * v[i + 1]
    else:
        s2, s3 = s * s, s * s * s
        d = dt[:, None]
        out = (
            (2 * s3 - 3 * s2 + 1) * v[i]
            + (s3 - 2 * s2 + s) * d * b[i]
            + (-2 * s3 + 3 * s2) * v[i + 1]
            + (s3 - s2) * d * a[i + 1]
        )
    return quat.normalize(out) if rotation else out


# ------------------------------------------------------------------ writing
def save_gltf(motion: Motion, path: str | bytes | PathLike[str], *, name: str | None = None) -> None:
    """Write a Motion as a glTF 2.0 joint hierarchy with one animation (``.glb`` binary or ``.gltf`` JSON).

    Parameters
    ----------
    motion : Motion
    path : str or path-like
        Ends in ``.glb`` (one binary file) or ``.gltf`` (JSON with the data
        embedded as a base64 URI), case-insensitive.
    name : str, optional
        The animation's name (default: the motion's name, or ``"motion"``).

    Raises
    ------
    ValueError
        For another extension.
    TypeError
        For a ``motion`` that is not a Motion, or a bad ``path`` type.
    OSError
        When the file cannot be written (an existing file is left whole).

    Examples
    --------
    >>> import tempfile
    >>> from pathlib import Path
    >>> from mocaplab.data import cmu
    >>> with tempfile.TemporaryDirectory() as folder:
    ...     save_gltf(cmu("16_15"), Path(folder) / "walk.gltf")
    ...     (Path(folder) / "walk.gltf").read_text()[:1]
    '{'
    """
    import pygltflib as g

    if not isinstance(motion, Motion):
        raise TypeError(f"Expected `motion` to be a Motion, got {type(motion).__name__}")
    file = as_path(path)
    ext = os.path.splitext(file)[1].lower()
    if ext not in (".glb", ".gltf"):
        raise ValueError(f"Expected `path` to end in .glb or .gltf (case-insensitive), got {file!r}")
    sk = motion.skeleton
    n = sk.n_joints
    blob = bytearray()
    views: list[Any] = []
    accessors: list[Any] = []

    def add(array: NDArray[Any], kind: str, *, minmax: bool = False) -> int:
        data = np.ascontiguousarray(array, dtype="<f4")
        while len(blob) % 4:
            blob.append(0)
        views.append(g.BufferView(buffer=0, byteOffset=len(blob), byteLength=data.nbytes))
        blob.extend(data.tobytes())
        rows = data.reshape(len(data), -1)
        acc = g.Accessor(bufferView=len(views) - 1, componentType=g.FLOAT, count=len(rows), type=kind)
        if minmax:
            acc.min = rows.min(axis=0).astype(float).tolist()
            acc.max = rows.max(axis=0).astype(float).tolist()
        accessors.append(acc)
        return len(accessors) - 1

    offsets = np.array(sk.offsets, dtype=float)
    offsets[0] = motion.root_positions[0]
    nodes = [g.Node(name=sk.names[j], translation=offsets[j].tolist(), children=sk.children(j) or None) for j in range(n)]
    rest_world = np.zeros((n, 3))
    for j in range(n):
        p = int(sk.parents[j])
        rest_world[j] = offsets[j] + (rest_world[p] if p >= 0 else 0.0)
    inverse_bind = np.tile(np.eye(4), (n, 1, 1))
    inverse_bind[:, 3, :3] = -rest_world  # column-major: the translation is the last column
    ibm = add(inverse_bind.reshape(n, 16), "MAT4")
    times = add(motion.times, "SCALAR", minmax=True)
    samplers, channels = [], []

    def animate(node: int, path_name: str, values: NDArray[np.float64], kind: str) -> None:
        samplers.append(g.AnimationSampler(input=times, output=add(values, kind), interpolation="LINEAR"))
        channels.append(g.AnimationChannel(sampler=len(samplers) - 1, target=g.AnimationChannelTarget(node=node, path=path_name)))

    rotations = quat.unroll(motion.rotations, axis=0)
    for j in range(n):
        animate(j, "rotation", rotations[:, j], "VEC4")
    if motion.translations is not None:
        for j in range(1, n):
            animate(j, "translation", motion.translations[:, j], "VEC3")
    animate(0, "translation", motion.root_positions, "VEC3")
    label = name if name is not None else (motion.name or "motion")
    doc = g.GLTF2(
        asset=g.Asset(version="2.0", generator="mocaplab"),
        scene=0,
        scenes=[g.Scene(nodes=[0])],
        nodes=nodes,
        skins=[g.Skin(name=sk.names[0], joints=list(range(n)), skeleton=0, inverseBindMatrices=ibm)],
        animations=[g.Animation(name=label, samplers=samplers, channels=channels)],
        accessors=accessors,
        bufferViews=views,
        buffers=[g.Buffer(byteLength=len(blob))],
    )
    if ext == ".glb":
        doc.set_binary_blob(bytes(blob))
        data = b"".join(doc.save_to_bytes())
    else:
        doc.buffers[0].uri = "data:application/octet-stream;base64," + base64.b64encode(bytes(blob)).decode("ascii")
        data = doc.to_json().encode("utf-8")
    with atomic_write(file, mode="wb") as fh:
        fh.write(data)
