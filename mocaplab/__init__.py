"""mocaplab: learn and explore human motion editing.

The core (this package, numpy + scipy only) holds the motion data model, file
I/O, kinematics, contact detection, and the editing methods of Kim et al.
2009 (synchronized multi-character editing), Shin et al. 2003 (physical
touch-up) and Coleman et al. 2008 (staggered poses).  Interactive views live
in :mod:`mocaplab.widgets`; lessons in the project's ``lessons/`` folder.

Conventions (metres, Y up, ground y = 0, quaternions ``(x, y, z, w)``) are
documented once in :mod:`mocaplab.motion`.
"""

from __future__ import annotations

import importlib
from typing import Any

from .motion import Motion, Skeleton, concatenate

__version__ = "0.1.0"

# One entry point per task, imported on first use so `import mocaplab` stays
# cheap (as scipy does): name -> (module, attribute).
_ENTRY_POINTS = {
    "load": ("mocaplab.io", "load"),
    "load_bvh": ("mocaplab.io", "load_bvh"),
    "save_bvh": ("mocaplab.io", "save_bvh"),
    "save_gltf": ("mocaplab.io", "save_gltf"),
    "load_asf_amc": ("mocaplab.io", "load_asf_amc"),
    "cmu": ("mocaplab.data", "cmu"),
    "edit": ("mocaplab.editing", "edit"),
    "SceneEditor": ("mocaplab.editing", "SceneEditor"),
    "refine": ("mocaplab.editing.refinement", "refine"),
    "touch_up": ("mocaplab.physics", "touch_up"),
    "extract": ("mocaplab.staggered", "extract"),
}
_SUBMODULES = (
    "anatomy", "contacts", "data", "displacement", "editing", "goals", "ik", "io", "kinematics", "lessons", "motion", "physics",
    "quality", "quat", "roles", "staggered", "undo",
    # the views (ipywidgets, matplotlib, pyvista): imported only when ``mocaplab.widgets`` is first used,
    # so ``import mocaplab`` never loads a UI package
    "widgets",
)

__all__ = ["Motion", "Skeleton", "concatenate", *_ENTRY_POINTS, "__version__"]


def __getattr__(name: str) -> Any:
    if name in _ENTRY_POINTS:
        module, attr = _ENTRY_POINTS[name]
        value = getattr(importlib.import_module(module), attr)
        globals()[name] = value
        return value
    if name in _SUBMODULES:
        return importlib.import_module(f"{__name__}.{name}")
    raise AttributeError(f"module 'mocaplab' has no attribute {name!r}")


def __dir__() -> list[str]:
    return sorted(set(__all__) | set(_SUBMODULES))
