"""Interactive views for JupyterLab (installed as ``mocaplab.widgets``).

Widgets are thin: each builds controls and forwards every event in one line
to an editor object of the core.  Tests drive them headless.

========================  ==============================================
``MotionViewer``          pyvista 3D skeletons with a frame slider
``PathEditor``            drag motion paths (Kim et al. 2009)
``TimeTrackEditor``       drag time handles on per-character tracks
``TouchUpStepper``        step a physical touch-up (Shin et al. 2003)
``StaggeredExplorer``     staggered poses (Coleman et al. 2008)
========================  ==============================================
"""

from __future__ import annotations

from importlib import import_module

_WHERE = {
    "MotionViewer": "viewer",
    "PathEditor": "path_editor",
    "TimeTrackEditor": "time_track",
    "TouchUpStepper": "touchup",
    "StaggeredExplorer": "staggered",
}

__all__ = list(_WHERE)


def __getattr__(name: str):
    if name in _WHERE:
        return getattr(import_module(f".{_WHERE[name]}", __name__), name)
    raise AttributeError(f"module 'mocaplab.widgets' has no attribute {name!r}")
