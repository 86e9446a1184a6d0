"""The ufbx side of :func:`mocaplab.io.load_fbx`, run in a child process.

Run as ``python path/to/_ufbx_worker.py``: it reads a pickled request
(the file's bytes and the options) on standard input and writes a pickled
answer on standard output, then leaves with :func:`os._exit` so that no ufbx
object is ever released.

Why a child process: in ufbx 0.0.5 every scene element (node, bone, stack,
curve, ...) that the bindings hand out is a *borrowed* reference that Python
counts as owned (``Element_from`` returns the scene's cached wrapper without
``Py_NewRef``).  Dropping a wrapper frees it while the scene still points at
it, and the next access, or the scene's own release, crashes the interpreter.
Here every element handed out gets the reference it lacks (:func:`_own`),
the garbage collector is off, and the process ends without releasing
anything, so a crash in the bindings can never take the user's Python down;
the parent turns a dead worker into a :class:`~mocaplab.io.MocapFormatError`.

Answer: ``("ok", payload)`` or ``("error", expected, got)``; the payload holds
plain numbers, lists and bytes only (see :func:`_read`): the worker imports
neither numpy nor mocaplab, so it starts fast.
"""

from __future__ import annotations

import ctypes
import gc
import math
import os
import pickle
import sys
from array import array
from typing import Any


class _Refused(Exception):
    def __init__(self, expected: str, got: str):
        super().__init__(expected, got)
        self.expected, self.got = expected, got


def _own(obj: Any) -> Any:
    """``obj`` with the reference the bindings did not give (elements only; see the module notes)."""
    import ufbx

    if isinstance(obj, ufbx.Element):
        ctypes.pythonapi.Py_IncRef(ctypes.py_object(obj))
    return obj


def _scene(raw: bytes, path: str) -> Any:
    import ufbx

    try:
        return ufbx.load_memory(
            raw,
            file_format=ufbx.FileFormat.FBX,
            ignore_geometry=True,
            ignore_embedded=True,
            target_axes=ufbx.axes_right_handed_y_up,
            filename=path,
        )
    except ufbx.TruncatedFileError:
        raise _Refused("a complete FBX file", "a truncated file") from None
    except ufbx.UnsupportedVersionError as exc:
        raise _Refused("an FBX version ufbx reads (6.1 to 7.7)", str(exc)) from None
    except ufbx.UfbxError as exc:
        raise _Refused("a readable FBX file", f"a corrupt file ({exc})") from None


def _read(request: dict[str, Any]) -> dict[str, Any]:
    """Everything :func:`mocaplab.io.fbx.load_fbx` needs, as plain data."""
    scene = _scene(request["raw"], request["path"])
    node_list = scene.nodes
    nodes = [_own(node_list[i]) for i in range(len(node_list))]
    index = {n.element_id: i for i, n in enumerate(nodes)}
    parent = []
    bone = []
    for n in nodes:
        p = _own(n.parent)
        parent.append(-1 if p is None else index[p.element_id])
        bone.append(_own(n.bone) is not None)
    children: list[list[int]] = [[] for _ in nodes]
    for i, p in enumerate(parent):
        if p >= 0:
            children[p].append(i)

    # skeletons: bones with no bone above them
    def bone_above(i: int) -> bool:
        p = parent[i]
        while p >= 0:
            if bone[p]:
                return True
            p = parent[p]
        return False

    def depth(i: int) -> int:
        d = 0
        while parent[i] >= 0:
            i, d = parent[i], d + 1
        return d

    roots = [i for i in range(len(nodes)) if bone[i] and not bone_above(i)]
    if not roots:
        kinds = sorted({nodes[i].attrib_type.name.lower() for i in range(len(nodes)) if parent[i] >= 0})
        raise _Refused("a skeleton (bone or limb nodes)", f"none (nodes of kind {', '.join(kinds)})" if kinds else "no nodes")
    root_names = [nodes[r].name for r in roots]
    wanted = request["skeleton"]
    if wanted is not None:

        def named(r: int) -> bool:
            i = r
            while i >= 0 and parent[i] >= 0:  # the scene's own root node has no name to match
                if nodes[i].name == wanted:
                    return True
                i = parent[i]
            return False

        chosen = [r for r in roots if named(r)]
        if len(chosen) != 1:
            raise _Refused(
                f"one skeleton whose root joint (or a node above it) is named {wanted!r}",
                f"{len(chosen)} (root joints: {', '.join(map(repr, root_names))})",
            )
        root = chosen[0]
    elif len(roots) > 1:
        raise _Refused(
            "one skeleton (pass skeleton= with the name of its root joint)",
            f"{len(roots)} skeletons with root joints {', '.join(map(repr, root_names))}",
        )
    else:
        root = roots[0]

    # the nodes composed: the root's ancestors (top first), then the skeleton depth first
    chain = []
    i = parent[root]
    while i >= 0:
        chain.append(i)
        i = parent[i]
    chain.reverse()
    bone_below = [False] * len(nodes)  # a bone among the node's descendants
    for i in sorted(range(len(nodes)), key=lambda k: -depth(k)):
        if parent[i] >= 0 and (bone[i] or bone_below[i]):
            bone_below[parent[i]] = True
    below: list[int] = []
    stack = [root]
    while stack:
        i = stack.pop()
        if bone[i] or bone_below[i]:  # bones, and nodes between bones (folded into the joints' motion)
            below.append(i)
        stack.extend(reversed(children[i]))
    order = chain + below
    joints = [k for k, i in enumerate(order) if bone[i]]
    position = {n: k for k, n in enumerate(order)}

    def composed_parent(i: int) -> int:
        return position.get(parent[i], -1)

    # the take
    stacks = scene.anim_stacks
    takes = [_own(stacks[k]) for k in range(len(stacks))]
    names = [s.name for s in takes]
    if not takes:
        raise _Refused("an animation stack (take)", "none (a file without animation)")
    take = request["take"]
    if take is None:
        chosen_take = takes[0]
    elif isinstance(take, int):
        if not -len(takes) <= take < len(takes):
            raise _Refused(f"a take index below {len(takes)}", f"{take} (takes: {names})")
        chosen_take = takes[take]
    elif take in names:
        chosen_take = takes[names.index(take)]
    else:
        raise _Refused(f"an animation stack (take) named {take!r}", f"takes {names}")

    ids = {nodes[k].element_id for k in order}
    most_keys, animated = 0, False
    layers = chosen_take.layers
    for li in range(len(layers)):
        props = _own(layers[li]).anim_props
        for pi in range(len(props)):
            prop = props[pi]
            if _own(prop.element).element_id not in ids:
                continue
            curves = _own(prop.anim_value).curves
            for curve in curves:
                if curve is not None:
                    _own(curve)  # once for the tuple that holds it
                    animated = True
                    most_keys = max(most_keys, len(curve.keyframes))
    if not animated:
        raise _Refused(
            f"animation curves on the skeleton's joints in take {chosen_take.name!r}",
            "none (a file without animation of its skeleton)",
        )
    settings = scene.settings
    fps = request["fps"] if request["fps"] is not None else float(settings.frames_per_second)
    begin, end = float(chosen_take.time_begin), float(chosen_take.time_end)
    if not (math.isfinite(begin) and math.isfinite(end) and end >= begin):
        raise _Refused(f"a time span in take {chosen_take.name!r}", f"{begin} to {end} s")
    bounds = request["bounds"]
    if not bounds[0] <= fps <= bounds[1]:
        raise _Refused(f"a frame rate from {bounds[0]:g} to {bounds[1]:g} fps in GlobalSettings", f"{fps:g}")
    n = int(math.floor((end - begin) * fps + 1e-6)) + 1
    limit = max(request["unkeyed_frames"], 2 * most_keys)
    if n > limit:
        raise _Refused(
            f"a take of at most {limit:,} frames at {fps:g} fps (its curves hold {most_keys:,} keys)",
            f"{n:,} frames ({begin:g} to {end:g} s); pass a lower fps=",
        )
    import ufbx

    anim = chosen_take.anim
    composed = [nodes[k] for k in order]
    local = array("d")
    for f in range(n):
        t = begin + f / fps
        for node in composed:
            tr = ufbx.evaluate_transform(anim, node, t)
            local.extend((*tr.translation, *tr.rotation, *tr.scale))
    rest = array("d")
    for node in composed:
        tr = node.local_transform
        rest.extend((*tr.translation, *tr.rotation, *tr.scale))
    return {
        "n_frames": n,
        "rest": rest.tobytes(),
        "names": [nodes[order[k]].name for k in joints],
        "rotation_orders": [int(nodes[order[k]].rotation_order) for k in joints],
        "joints": joints,
        "parents": [composed_parent(k) for k in order],
        "inherit": [int(nodes[k].inherit_mode) for k in order],
        "local": local.tobytes(),
        "fps": float(fps),
        "unit": float(settings.unit_meters),
    }


def main() -> None:
    gc.disable()
    request = pickle.load(sys.stdin.buffer)
    try:
        answer: tuple[Any, ...] = ("ok", _read(request))
    except _Refused as exc:
        answer = ("error", exc.expected, exc.got)
    except Exception as exc:  # noqa: BLE001 - any failure of the bindings is the file's problem for the user
        answer = ("error", "a file the ufbx reader can read", f"{type(exc).__name__}: {exc}")
    out = sys.stdout.buffer
    out.write(pickle.dumps(answer, protocol=pickle.HIGHEST_PROTOCOL))
    out.flush()
    os._exit(0)


if __name__ == "__main__":
    main()
