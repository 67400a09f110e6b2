"""What every ``robot identify`` protocol shares: its two outputs, the prior and the identifiability
in short printed after its figures."""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from pathlib import Path

    from brachycal.calibration.robot.identifiability import Identifiability
    from brachycal.calibration.robot_accuracy import RobotAccuracy
    from brachycal.io import OutputSet


def claim_outputs(outputs: OutputSet, out: Path) -> tuple[Path, Path]:
    """``out/robot.urdf`` (the identified robot) and ``out/identification.json``, claimed in ``outputs``."""
    urdf_path = outputs.claim(out / "robot.urdf", make_parents=True, label="--out robot.urdf")
    json_path = outputs.claim(out / "identification.json", make_parents=True, label="--out identification.json")
    return urdf_path, json_path


def print_prior(accuracy: RobotAccuracy) -> None:
    """The corrections' prior per joint origin (mm, deg; the axis tilt's when it has its own) and its source."""
    tilt = f", axis tilt {math.degrees(accuracy.tilt_sd_rad):.3g} deg" if accuracy.tilt_sd_rad is not None else ""
    print(
        f"prior per joint origin: {accuracy.translation_sd_m * 1e3:.3g} mm, "
        f"{math.degrees(accuracy.rotation_sd_rad):.3g} deg{tilt} ({accuracy.source or 'as stated'})"
    )


def print_identifiability(identifiability: Identifiability, joint_names: tuple[str, ...]) -> None:
    """The identifiability report in short: the counts, then per reason how many corrections and of
    which joints (the full list is in identification.json)."""
    print(identifiability.summary(joint_names)[0])
    joints: dict[str, list[str]] = {}
    for key, why in identifiability.reasons.items():
        joint = key.rsplit(".", 1)[0]
        names = joints.setdefault(why, [])
        if joint not in names:
            names.append(joint)
    for why, names in joints.items():
        count = sum(1 for w in identifiability.reasons.values() if w == why)
        shown = ", ".join(names[:4]) + (f" and {len(names) - 4} more" if len(names) > 4 else "")
        print(f"  not identified ({count}): {why} [{shown}]")
