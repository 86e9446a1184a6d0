"""Reading and writing motion files (the only place Euler angles live).

* :func:`load_bvh`, :func:`save_bvh`: Biovision Hierarchy.
* :func:`load_asf_amc`: the CMU's native Acclaim skeleton/motion pair.
* :func:`load_fbx`: Autodesk FBX (binary or ASCII; skeleton and one take).
* :func:`load_gltf`, :func:`save_gltf`: glTF 2.0 (``.gltf``/``.glb``; a skin's
  joints and one animation).
* :func:`load`: any of them by extension, in metres and Y up (frame rate
  snapped, optional Z-up conversion and joint roles).

Every malformed file raises :class:`MocapFormatError` (a ``ValueError``).
"""

from .bvh import estimate_scale, load_bvh, save_bvh
from .errors import MocapFormatError

# Imported eagerly, not through __getattr__: the function has the name of its
# module, and a lazy lookup would find the submodule instead once anything had
# imported ``mocaplab.io.load`` (the import system sets the package attribute).
from .load import load

__all__ = [
    "MocapFormatError", "load", "load_bvh", "save_bvh", "estimate_scale", "load_asf_amc", "load_fbx", "load_gltf",
    "save_gltf",
]


def __getattr__(name: str):  # pragma: no cover - thin lazy import
    if name == "load_asf_amc":
        from .asfamc import load_asf_amc

        return load_asf_amc
    if name == "load_fbx":
        from .fbx import load_fbx

        return load_fbx
    if name in ("load_gltf", "save_gltf"):
        from . import gltf

        return getattr(gltf, name)
    raise AttributeError(name)
