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

from .motion import Motion, Skeleton, concatenate

__version__ = "0.1.0"

__all__ = ["Motion", "Skeleton", "concatenate", "load", "load_bvh", "save_bvh", "cmu", "refine", "__version__"]


def __getattr__(name: str):
    # light lazy entry points, so `import mocaplab` stays cheap
    if name in ("load", "load_bvh", "save_bvh", "load_asf_amc"):
        from . import io

        return getattr(io, name)
    if name == "cmu":
        from .data import cmu

        return cmu
    if name == "refine":
        from .refinement import refine

        return refine
    raise AttributeError(f"module 'mocaplab' has no attribute {name!r}")
