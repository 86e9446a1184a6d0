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
