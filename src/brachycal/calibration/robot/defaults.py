"""The robot-identification protocols' defaults, apart from their fits: what a command's options and
help need without loading the fits (:mod:`~brachycal.calibration.robot.touches`,
:mod:`~brachycal.calibration.robot.tracker` give them under their own names too)."""

from __future__ import annotations

import numpy as np

from brachycal.calibration.robot_accuracy import RobotAccuracy

#: Default prior of the corrections: a collaborative arm off its URDF by tenths of a millimetre
#: and a tenth of a degree per joint origin (the twin's 0.03 mm / 0.003° is a well-built arm's
#: and would force a real arm's millimetres of error into the tip). State the arm's own figures
#: when known, or let the training touches choose (``prior="evidence"``).
TOUCHES_ACCURACY = RobotAccuracy(
    translation_sd_m=3e-4,
    rotation_sd_rad=float(np.radians(0.1)),
    source="touches default: a collaborative arm, 0.3 mm / 0.1 deg per joint origin",
)

#: The models, from the smallest: the URDF as it is, joint zeros, every joint-origin component.
TRACKER_MODELS = ("frames", "offsets", "joints")
#: Default prior of the corrections: an industrial arm off its URDF by ~1 mm / 0.1° per joint
#: origin (the twin's default 0.03 mm / 0.003° is a well-built arm's and would hold real errors in
#: the frames). It matters: held out, FIGAROH's UR10 does best at 0.3 mm / 0.03° (2.24 mm per
#: coordinate; 2.28 mm at the default) and its TIAGo at 3 mm / 0.3° (2.16 mm; 2.42 mm at the
#: default): state the arm's own figures when known.
TRACKER_ACCURACY = RobotAccuracy(
    translation_sd_m=1e-3,
    rotation_sd_rad=float(np.radians(0.1)),
    source="tracker default: an industrial arm, 1 mm / 0.1 deg per joint origin",
)
#: How the corrections' prior is set: the stated accuracy, or chosen by the postures' evidence.
TRACKER_PRIORS = ("stated", "evidence")
