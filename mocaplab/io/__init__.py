"""Reading and writing motion files (the only place Euler angles live).

* :func:`load_bvh`, :func:`save_bvh`: Biovision Hierarchy.
* :func:`load_asf_amc`: the CMU's native Acclaim skeleton/motion pair.

Every malformed file raises :class:`MocapFormatError` (a ``ValueError``).
"""

from .bvh import estimate_scale, load_bvh, save_bvh
from .errors import MocapFormatError

__all__ = ["MocapFormatError", "load_bvh", "save_bvh", "estimate_scale", "load_asf_amc"]


def __getattr__(name: str):  # pragma: no cover - thin lazy import
    if name == "load_asf_amc":
        from .asfamc import load_asf_amc

        return load_asf_amc
    raise AttributeError(name)
