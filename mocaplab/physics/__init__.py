"""Physical touch-up of human motions (Shin, Kovar and Gleicher 2003).

=============================  ===============================================
:class:`Body`                  point masses per link (de Leva 1996 table)
:func:`standing_pose`          the pose a body is measured in when the rest
                               pose does not stand (:class:`RestPoseWarning`)
:func:`center_of_mass`         equation 1
:func:`angular_momentum`       equation 2 (and :func:`linear_momentum`)
:func:`balance`                ZMP (equation 4), support polygons, distances
:func:`fit_masses`             mass estimation from reference clips (s3.2)
:func:`touch_up`               the touch-up (s3.3, s3.4) -> TouchUpHistory
:func:`start`, :func:`step`    the same, one adjustment at a time
:func:`ground_reach`           which frames out of balance an adjustment
                               balances exactly, which take the closest
                               approach (:class:`GroundReach`)
:class:`TouchUpSession`        stateful stepper behind the widget
:class:`TouchUpWarning`        suspicious input (long flights, sliding feet)
:func:`flight_measures`        per flight: fitted gravity, angular-momentum
                               spread (:class:`FlightMeasure`)
=============================  ===============================================
"""

from __future__ import annotations

from ..anatomy import RestPoseWarning, standing_pose
from .body import (
    DE_LEVA_GYRATION_MALE,
    DE_LEVA_MALE,
    GRAVITY,
    Body,
    LinkSpec,
    angular_momentum,
    center_of_mass,
    linear_momentum,
    link_positions,
    smoothed_derivatives,
)
from .flight import FlightMeasure, flight_measures
from .masses import MassFit, fit_masses
from .schedule import (
    FLIGHT_SCHEDULE,
    GROUND_SCHEDULE,
    Adjustment,
    LinkSets,
    default_schedule,
    flight_stages,
    link_sets,
    preset_mask,
)
from .state import TouchUpState, TouchUpWarning, start, step
from .touchup import GroundReach, TouchUpHistory, TouchUpSession, ground_reach, touch_up
from .zmp import Balance, balance, polygon_distance, signed_distance, support_polygon, zmp_distance, zmp_from_links

__all__ = [
    "DE_LEVA_GYRATION_MALE",
    "DE_LEVA_MALE",
    "GRAVITY",
    "Body",
    "LinkSpec",
    "RestPoseWarning",
    "angular_momentum",
    "center_of_mass",
    "link_positions",
    "linear_momentum",
    "smoothed_derivatives",
    "standing_pose",
    "MassFit",
    "fit_masses",
    "Adjustment",
    "FlightMeasure",
    "FLIGHT_SCHEDULE",
    "GROUND_SCHEDULE",
    "GroundReach",
    "LinkSets",
    "TouchUpHistory",
    "TouchUpSession",
    "TouchUpState",
    "TouchUpWarning",
    "default_schedule",
    "flight_measures",
    "flight_stages",
    "ground_reach",
    "link_sets",
    "preset_mask",
    "start",
    "step",
    "touch_up",
    "Balance",
    "balance",
    "polygon_distance",
    "signed_distance",
    "support_polygon",
    "zmp_distance",
    "zmp_from_links",
]
