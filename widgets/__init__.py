"""Interactive views for JupyterLab (installed as ``mocaplab.widgets``).

Widgets are thin: each builds controls and forwards every event in one line
to an editor object of the core.  Tests drive them headless.
"""
