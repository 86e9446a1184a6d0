"""Discrete motion editing during interactive manipulation (Kim et al. 2009, section 5).

While the user drags constraints, Laplacian path editing
(:mod:`~mocaplab.editing.scene`) deforms the paths continuously; discrete
editing lets the *structure* of a motion change too: steps are added when a
walk is stretched, an idle stretch is duplicated when it is slowed down.

The package, one concern per module (imports point one way:
``editor -> evaluation, pruning -> transformations``, all of them onto the
continuous modules of :mod:`mocaplab.editing`, none back):

:mod:`~mocaplab.editing.discrete.transformations`
    Motion-graph nodes per character (:class:`Track`), the four kinds of
    :class:`Transformation` (section 5.1, Figure 7), applying one with
    blended seams (:func:`apply_transformation`), enumerating them
    (:func:`enumerate_transformations`), constraints following their frames
    (:func:`map_constraint`).
:mod:`~mocaplab.editing.discrete.pruning`
    The four pruning rules of section 5.2 (:func:`prune`,
    :func:`pruning_violations`, :class:`Locality` with :class:`Box` and
    :class:`Disk` regions).
:mod:`~mocaplab.editing.discrete.evaluation`
    Equation 10 for every candidate on subsampled paths, in one batch whose
    cost grows linearly with the characters and with the clip length
    (:class:`~mocaplab.editing.discrete.evaluation.SubsampledScene`).
:mod:`~mocaplab.editing.discrete.editor`
    Algorithm 1 (:class:`DiscreteEditor`, :class:`DiscreteOptions`): a
    continuous :class:`~mocaplab.editing.scene.SceneEditor` of the current
    transformed scene, the greedy update and its history.

Examples
--------
>>> from mocaplab import data
>>> from mocaplab.editing import DiscreteEditor, PinPosition
>>> walk = data.cmu("16_15").resample(30); p = walk.root_positions[:, [0, 2]]
>>> ed = DiscreteEditor([walk], [PinPosition(0, 0, p[0], hard=True), PinPosition(0, len(p) - 1, p[-1], hard=True)])
>>> res = ed.drag(1, p[0] + 1.5 * (p[-1] - p[0]))
>>> [str(t) for t in res.transformations]
['character 0: duplicate frames 65..100 (1.20 s)']
"""

from __future__ import annotations

from .editor import DiscreteEditor, DiscreteOptions, Step, Timing
from .evaluation import SubsampledScene
from .pruning import Box, Disk, Locality, protected_frames, prune, pruning_violations
from .transformations import (
    TYPES,
    GraphArrays,
    Track,
    Transformation,
    apply_transformation,
    enumerate_transformations,
    map_constraint,
)

__all__ = [
    "TYPES",
    "Transformation",
    "GraphArrays",
    "Track",
    "apply_transformation",
    "enumerate_transformations",
    "map_constraint",
    "Box",
    "Disk",
    "Locality",
    "protected_frames",
    "prune",
    "pruning_violations",
    "SubsampledScene",
    "DiscreteOptions",
    "DiscreteEditor",
    "Step",
    "Timing",
]
