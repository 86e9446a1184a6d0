"""Staggered poses (Coleman et al. 2008): representation, extraction, editing.

>>> from mocaplab import cmu, staggered                   # doctest: +SKIP
>>> sm = staggered.extract(cmu("16_15"))                  # doctest: +SKIP
>>> arm = sm.skeleton.roles["left_shoulder"]              # doctest: +SKIP
>>> edited = staggered.succession(sm, 0.03, 2.0, joint=arm).evaluate()  # doctest: +SKIP

Modules, each importing only those listed before it:
:mod:`.representation` (section 3, the :class:`StaggeredMotion` container
and its evaluation), :mod:`.features` (section 4.1, locating poses and
refinements), :mod:`.noise` (section 6, filtering rotations before timing
edits), :mod:`.constraints` (the contact constraint layer of section 3 and
4.1.2), :mod:`.fit` (section 4.1.1 and Appendix A, splines and displacement
maps; :func:`extract`), :mod:`.edit` (section 5, geometric and timing edits,
functions of a :class:`StaggeredMotion`) and :mod:`.editor` (the undoable
:class:`StaggeredEditor` used by the widget).
"""

from __future__ import annotations

from ..ik import UnreachableTargetWarning
from .constraints import ConstraintLayer, constraint_joints
from .edit import (
    apply_knot_deltas,
    average_pose,
    default_joint,
    delete_pose,
    edit_pose,
    exaggerate,
    insert_pose,
    keep_knot_order,
    limb_groups,
    randomize,
    retime,
    succession,
    succession_depths,
)
from .editor import EditorParams, StaggeredEditor
from .features import NoContactsWarning, PoseAnalysis, analyze
from .fit import (
    extract,
    fit_representation,
    fit_rotation_tangents,
    fit_translation_tangents,
    gauss_newton_tangents,
    rotation_objective,
)
from .noise import jitter, orientation_filter, sharp_detail
from .representation import (
    ROOT_POSITION,
    TRANSLATION_SUFFIX,
    TRANSLATION_TOLERANCE,
    StaggeredMotion,
    StaggeredTimingWarning,
    bezier,
    compose_rotation,
    factor_rotation,
    quat_bezier,
    set_refinements,
    translation_joints,
    variable_names,
)

__all__ = [
    "ROOT_POSITION",
    "TRANSLATION_SUFFIX",
    "TRANSLATION_TOLERANCE",
    "translation_joints",
    "constraint_joints",
    "default_joint",
    "StaggeredMotion",
    "StaggeredTimingWarning",
    "PoseAnalysis",
    "NoContactsWarning",
    "ConstraintLayer",
    "UnreachableTargetWarning",
    "StaggeredEditor",
    "EditorParams",
    "analyze",
    "extract",
    "fit_representation",
    "fit_translation_tangents",
    "fit_rotation_tangents",
    "gauss_newton_tangents",
    "rotation_objective",
    "orientation_filter",
    "sharp_detail",
    "jitter",
    "bezier",
    "quat_bezier",
    "compose_rotation",
    "factor_rotation",
    "variable_names",
    "set_refinements",
    "retime",
    "succession",
    "succession_depths",
    "randomize",
    "limb_groups",
    "edit_pose",
    "exaggerate",
    "insert_pose",
    "delete_pose",
    "apply_knot_deltas",
    "average_pose",
    "keep_knot_order",
]
