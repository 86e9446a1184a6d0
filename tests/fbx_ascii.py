"""A tiny ASCII FBX 7.4 writer for tests: limb-node chains with pre-rotations, rotation orders and linear curves.

Hand-made files with hand-computable answers (the real clips come from the
CMU mirror).  KTime has 46,186,158,000 ticks per second.
"""

from __future__ import annotations

from dataclasses import dataclass, field

KTIME = 46_186_158_000


@dataclass
class Bone:
    name: str
    parent: str | None
    translation: tuple[float, float, float]
    pre_rotation: tuple[float, float, float] = (0.0, 0.0, 0.0)
    rotation: tuple[float, float, float] = (0.0, 0.0, 0.0)
    rotation_order: int = 0
    kind: str = "LimbNode"  # "Null" for a node that is not a bone
    #: axis -> [(seconds, degrees), ...], linear keys of Lcl Rotation
    keys: dict[str, list[tuple[float, float]]] = field(default_factory=dict)


def ascii_fbx(bones: list[Bone], *, unit_cm: float = 1.0, fps_mode: int = 6, take: str | None = "Take 001",
              stop: float = 1.0) -> str:
    """The text of an ASCII FBX file (``fps_mode`` 6 is 30 fps; ``take=None`` writes no animation stack)."""
    out = [
        "; FBX 7.4.0 project file",
        "FBXHeaderExtension:  {", "\tFBXHeaderVersion: 1003", "\tFBXVersion: 7400", "}",
        "GlobalSettings:  {", "\tVersion: 1000", "\tProperties70:  {",
        '\t\tP: "UpAxis", "int", "Integer", "",1', '\t\tP: "UpAxisSign", "int", "Integer", "",1',
        '\t\tP: "FrontAxis", "int", "Integer", "",2', '\t\tP: "FrontAxisSign", "int", "Integer", "",1',
        '\t\tP: "CoordAxis", "int", "Integer", "",0', '\t\tP: "CoordAxisSign", "int", "Integer", "",1',
        f'\t\tP: "UnitScaleFactor", "double", "Number", "",{unit_cm}',
        f'\t\tP: "TimeMode", "enum", "", "",{fps_mode}',
        "\t}", "}", "Objects:  {",
    ]
    ids = {b.name: 1000 + 10 * i for i, b in enumerate(bones)}
    conns = []
    for b in bones:
        i = ids[b.name]
        if b.kind == "LimbNode":
            out += [f'\tNodeAttribute: {i + 1}, "NodeAttribute::{b.name}", "LimbNode" {{', '\t\tTypeFlags: "Skeleton"', "\t}"]
            conns.append(f'\tC: "OO",{i + 1},{i}')
        props = [
            '\t\t\tP: "Lcl Translation", "Lcl Translation", "", "A",' + ",".join(map(str, b.translation)),
            '\t\t\tP: "Lcl Rotation", "Lcl Rotation", "", "A",' + ",".join(map(str, b.rotation)),
            '\t\t\tP: "PreRotation", "Vector3D", "Vector", "",' + ",".join(map(str, b.pre_rotation)),
            '\t\t\tP: "RotationActive", "bool", "", "",1',
            f'\t\t\tP: "RotationOrder", "enum", "", "",{b.rotation_order}',
        ]
        out += [f'\tModel: {i}, "Model::{b.name}", "{b.kind}" {{', "\t\tVersion: 232", "\t\tProperties70:  {", *props,
                "\t\t}", "\t}"]
        conns.append(f'\tC: "OO",{i},{ids[b.parent] if b.parent else 0}')
    if take is not None:
        out += [f'\tAnimationStack: 10, "AnimStack::{take}", "" {{', "\t\tProperties70:  {",
                '\t\t\tP: "LocalStart", "KTime", "Time", "",0', f'\t\t\tP: "LocalStop", "KTime", "Time", "",{round(stop * KTIME)}',
                "\t\t}", "\t}", '\tAnimationLayer: 20, "AnimLayer::BaseLayer", "" {', "\t}"]
        conns.append('\tC: "OO",20,10')
        for b in bones:
            if not b.keys:
                continue
            node = ids[b.name] + 2
            out += [f'\tAnimationCurveNode: {node}, "AnimCurveNode::R", "" {{', "\t\tProperties70:  {"]
            out += [f'\t\t\tP: "d|{a}", "Number", "", "A",{b.rotation[k]}' for k, a in enumerate("XYZ")]
            out += ["\t\t}", "\t}"]
            conns += [f'\tC: "OO",{node},20', f'\tC: "OP",{node},{ids[b.name]}, "Lcl Rotation"']
            for k, (axis, keys) in enumerate(sorted(b.keys.items())):
                curve = ids[b.name] + 3 + k
                times = ",".join(str(round(t * KTIME)) for t, _ in keys)
                values = ",".join(str(v) for _, v in keys)
                out += [f'\tAnimationCurve: {curve}, "AnimCurve::", "" {{', "\t\tDefault: 0", "\t\tKeyVer: 4009",
                        f"\t\tKeyTime: *{len(keys)} {{", f"\t\t\ta: {times}", "\t\t}",
                        f"\t\tKeyValueFloat: *{len(keys)} {{", f"\t\t\ta: {values}", "\t\t}",
                        "\t\tKeyAttrFlags: *1 {", "\t\t\ta: 4", "\t\t}",
                        "\t\tKeyAttrDataFloat: *4 {", "\t\t\ta: 0,0,0,0", "\t\t}",
                        "\t\tKeyAttrRefCount: *1 {", f"\t\t\ta: {len(keys)}", "\t\t}", "\t}"]
                conns.append(f'\tC: "OP",{curve},{node}, "d|{axis}"')
    out += ["}", "Connections:  {", *conns, "}", ""]
    return "\n".join(out)
