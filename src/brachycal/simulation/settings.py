"""The simulation's settings that the command line needs before any simulation runs.

Option ranges, choices and defaults of ``brachycal study`` and ``brachycal design``, kept apart
from the modules that use them (which load SciPy, Pinocchio and the planner) so that parsing a
command line and ``--help`` stay fast. The simulation modules import them from here.
"""

from __future__ import annotations

import numpy as np

from brachycal.calibration.labels import METHODS

#: Speed of sound in water at 20 °C, m/s: the twin's default medium.
WATER_SOUND_SPEED_M_S = 1482.0

#: Largest annotation noise SD, pixels: at 50 px (~1 cm at 0.19 mm/px) an image no longer locates
#: the needle tip at all; a larger value is a typo.
MAX_ANNOTATION_SD_PX = 50.0
#: Largest fraction of gross annotation outliers: beyond half, no robust estimator can tell the
#: outliers from the good samples (their breakdown point is at most 50 %).
MAX_OUTLIER_RATE = 0.5
#: Speeds of sound the twin may use, m/s: the media an ultrasound image shows (fat ~1450, water
#: 1482, soft tissue 1540, muscle ~1580) lie well inside; bone and air are not imaged.
SOUND_SPEED_RANGE_M_S = (1000.0, 2000.0)

#: Named robot-error levels of the twin's physical robot: per joint, the origin's translation SD
#: per axis (m), its tilt SD per axis (rad) and the zero offset's SD (rad). Mean flange position
#: error over the 64 sample poses (twin seeds 0–5, the robot only) in brackets.
#:
#: - ``well-built`` (the default; 0.17 mm at the flanges): a carefully built and mastered arm.
#: - ``real-arm`` (0.1 mm / 0.01° per joint; 0.58 mm at the flanges): the level the project states
#:   for real arms off their URDF, matching the 0.5–1 mm absolute accuracy commonly
#:   quoted for industrial arms without kinematic calibration (the vendor states only its ±0.1 mm
#:   repeatability, which bounds what any calibration can reach).
#: - ``worn`` (0.3 mm / 0.03° per joint; 1.7 mm at the flanges): three times that, a stress level.
ROBOT_ERROR_LEVELS: dict[str, tuple[float, float, float]] = {
    "well-built": (3e-5, float(np.radians(0.003)), float(np.radians(0.003))),
    "real-arm": (1e-4, float(np.radians(0.01)), float(np.radians(0.01))),
    "worn": (3e-4, float(np.radians(0.03)), float(np.radians(0.03))),
}

#: Most simulated sessions one sweep may ask for: each takes seconds to minutes, so 10000 is days
#: of computing on a workstation; more is a typo (and its list of runs alone could fill memory).
MAX_STUDY_RUNS = 10_000

#: Methods a study can run: the sequential registrations, the whole-chain fit, and the whole-chain
#: fit with the robot identified (:mod:`brachycal.calibration.robot.identification`, its prior the
#: twin's own robot-error level: the study states the accuracy a lab would state).
STUDY_METHODS = (*METHODS, "chain", "chain+robot")
#: Torso turn of the held-out targeting configurations (see :mod:`brachycal.studies.targeting`):
#: 3°, postures the calibration never saw, reachable from every sample pose's neighbourhood.
HELD_OUT_TORSO_TURN_RAD = float(np.radians(3.0))


DESIGNS = ("grid 4x4x4", "grid 3x3x3", "random 64", "random 27", "optimal 27")
