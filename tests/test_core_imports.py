"""The core imports only numpy, scipy and the standard library.

Every module under ``mocaplab`` except the drawing module and the widgets is
imported in a fresh interpreter; none of the UI or heavy optional packages
may end up in ``sys.modules``.
"""

from __future__ import annotations

import json
import subprocess
import sys

FORBIDDEN = ["matplotlib", "ipywidgets", "pyvista", "vtk", "IPython", "pandas", "trame"]

SCRIPT = r"""
import importlib, json, pkgutil, sys
import mocaplab

skipped = ("mocaplab.plot", "mocaplab.widgets")
names = []
for info in pkgutil.walk_packages(mocaplab.__path__, "mocaplab.", onerror=lambda name: None):
    if info.name == skipped[0] or info.name.startswith(skipped[1]):
        continue
    importlib.import_module(info.name)
    names.append(info.name)
# lazily exported names must not pull anything in either
import mocaplab.io
mocaplab.io.load_asf_amc
loaded = sorted({m.split(".")[0] for m in sys.modules})
print(json.dumps({"modules": names, "loaded": loaded}))
"""


def test_core_modules_import_no_ui_or_heavy_packages():
    out = subprocess.run([sys.executable, "-c", SCRIPT], capture_output=True, text=True, timeout=300)
    assert out.returncode == 0, out.stderr
    report = json.loads(out.stdout.strip().splitlines()[-1])
    modules, loaded = report["modules"], set(report["loaded"])
    for expected in ("mocaplab.motion", "mocaplab.quat", "mocaplab.kinematics", "mocaplab.io.bvh", "mocaplab.io.asfamc", "mocaplab.data"):
        assert expected in modules
    bad = sorted(loaded.intersection(FORBIDDEN))
    assert not bad, f"core modules imported {bad}"


API_SCRIPT = r"""
import json
import mocaplab
reached = {name: type(getattr(mocaplab, name)).__name__ for name in ("io", "editing", "physics", "staggered", "contacts", "data", "roles")}
print(json.dumps({"dir": dir(mocaplab), "all": mocaplab.__all__, "reached": reached}))
"""


def test_the_api_is_discoverable_from_a_plain_import():
    out = subprocess.run([sys.executable, "-c", API_SCRIPT], capture_output=True, text=True, timeout=300)
    assert out.returncode == 0, out.stderr
    report = json.loads(out.stdout.strip().splitlines()[-1])
    entry = ["load", "save_bvh", "cmu", "edit", "SceneEditor", "refine", "touch_up", "extract"]
    assert set(entry) <= set(report["all"]) and set(entry) <= set(report["dir"])
    assert all(kind == "module" for kind in report["reached"].values()), report["reached"]
    assert "annotations" not in report["dir"] and not any(n.startswith("_") and n != "__version__" for n in report["dir"])
    import mocaplab

    for name in entry:
        assert callable(getattr(mocaplab, name)), name
