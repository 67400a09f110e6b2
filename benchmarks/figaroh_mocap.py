"""Robot identification from a tracker on FIGAROH's real robots, beside FIGAROH's own figures.

Run: ``.venv/bin/python benchmarks/figaroh_mocap.py`` (outside data: ``BRACHYCAL_REFERENCE``/``figaroh_mocap``;
FIGAROH itself, when a Python with ``figaroh`` installed is given as ``FIGAROH_PYTHON``, runs live
through ``figaroh_peer.py``; otherwise its published figures are printed, labelled so).

Per robot, per model (frames only: the URDF as it is; joint zeros; the joints' base set, MAP with
the default stated accuracy; the same without a prior, as FIGAROH fits): the marker position's
leave-one-out error per coordinate (each posture predicted by a fit without it; the headline) and
the training error, in mm; orientation in degrees for the 6-D UR10; then the model the supported-
model rule returns and why; the same with the prior chosen by the evidence (``prior="evidence"``: per
model the SDs the postures make most likely, on all postures for the training figure and inside
each leave-one-out fold from its own postures for the held-out one); the joints model under other
stated accuracies (the prior matters: the default is not the best for either robot, and which is
best differs between them).

- UR10: 23 postures, the flange's 6-D pose (``ur10_columns.toml``).
- TIAGo: 34 postures, torso lift and 7 arm joints, the first hand marker's 3-D position from a
  Qualisys system (``tiago_columns.toml``).
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

from brachycal.calibration.robot.tracker import (
    TRACKER_ACCURACY,
    TrackerData,
    fit_tracker,
    identify_from_tracker,
    leave_one_out,
    tracker_data,
)
from brachycal.calibration.robot_accuracy import RobotAccuracy
from brachycal.data.formats.tracker_table import read_tracker_columns, read_tracker_table
from brachycal.model.robot import Robot

HERE = Path(__file__).parent
DATA = Path(os.environ.get("BRACHYCAL_REFERENCE") or HERE.parents[1] / "shared" / "reference") / "figaroh_mocap"
#: Other stated accuracies of the joints model, to show how much the prior matters (mm, deg).
PRIORS = ((0.3, 0.03), (3.0, 0.3), (10.0, 1.0))
#: FIGAROH's figures from the data's README (FIGAROH 0.2.x, 32 parameters; independent checks).
PUBLISHED = {
    "ur10": "FIGAROH 0.2.x (published): 1.727 mm training (32 params), 0.313 deg; independent checks: "
    "frames 2.10 mm / 0.52 deg training, LOO frames 2.38 mm, frames + joint origins 2.35 mm",
    "tiago": "published: frames 2.29 mm training, 2.53 mm LOO; joint-origin identification 1.44 mm training, "
    "2.19 mm LOO",
}


def load(name: str) -> TrackerData:
    if name == "ur10":
        robot = Robot.load(DATA / "ur10" / "urdf" / "ur10_robot.urdf")
        table = read_tracker_table(
            DATA / "ur10" / "data" / "calibration.csv",
            read_tracker_columns(HERE / "figaroh_mocap" / "ur10_columns.toml"),
        )
        return tracker_data(robot, table, "wrist_3_link")
    robot = Robot.load(DATA / "tiago" / "urdf" / "tiago_48_schunk.urdf")
    table = read_tracker_table(
        DATA / "tiago" / "data" / "calibration" / "mocap" / "qualysis_base_hand_calibration.csv",
        read_tracker_columns(HERE / "figaroh_mocap" / "tiago_columns.toml"),
    )
    return tracker_data(robot, table, "arm_7_link")


def figaroh_live() -> dict[str, object] | None:
    """FIGAROH's UR10 calibration run by ``FIGAROH_PYTHON`` (``None`` when not given or failing)."""
    python = os.environ.get("FIGAROH_PYTHON")
    if not python:
        return None
    done = subprocess.run(
        [python, str(HERE / "figaroh_peer.py"), str(DATA)], capture_output=True, text=True, check=False, cwd="/"
    )
    lines = [line for line in done.stdout.splitlines() if line.startswith("{")]
    if done.returncode or not lines:
        print(f"  FIGAROH did not run: {done.stderr.strip().splitlines()[-1:]}")
        return None
    return json.loads(lines[-1])


def rms_mm(e: np.ndarray) -> float:
    return float(np.sqrt(np.mean(e**2)) * 1e3)


def main() -> int:
    if not DATA.is_dir():
        print(f"skipped: {DATA} is not there (FIGAROH's public data)", file=sys.stderr)
        return 1
    print(f"prior of the corrections: {TRACKER_ACCURACY.source}")
    for name in ("ur10", "tiago"):
        data = load(name)
        kind = "6-D" if data.six_d else "3-D"
        print(f"\n{name.upper()}: {len(data.Q)} postures, {kind} marker, flange {data.flange}")
        start = time.perf_counter()
        result = identify_from_tracker(data)
        for line in result.summary():
            print("  " + line)
        lap = time.perf_counter()
        evidence = identify_from_tracker(data, prior="evidence")
        print("  prior chosen by the evidence (per model; each held-out posture's fold chose its own):")
        for line in evidence.summary():
            print("    " + line)
        print(f"    ({time.perf_counter() - lap:.0f} s)")
        plain = fit_tracker(data, "joints", None)
        e_p, e_o = leave_one_out(data, "joints", None)
        o = (
            f", orientation {np.degrees(np.sqrt(np.mean(e_o**2))):.3f} deg LOO / "
            f"{np.degrees(np.sqrt(np.mean(plain.orientation_residuals**2))):.3f} deg training"
            if e_o is not None and plain.orientation_residuals is not None
            else ""
        )
        params = (12 if data.six_d else 9) + len(plain.parameters)
        print(
            f"  joints without prior {params:3d} params: position {rms_mm(e_p):.3f} mm LOO / "
            f"{rms_mm(plain.position_residuals):.3f} mm training per coordinate{o}"
        )
        for mm, deg in PRIORS:
            stated = RobotAccuracy(mm * 1e-3, float(np.radians(deg)), source=f"{mm} mm / {deg} deg")
            e_p, _ = leave_one_out(data, "joints", stated)
            fit = fit_tracker(data, "joints", stated)
            print(
                f"  joints, prior {mm:g} mm / {deg:g} deg: position {rms_mm(e_p):.3f} mm LOO / "
                f"{rms_mm(fit.position_residuals):.3f} mm training per coordinate"
            )
        print(f"  ({time.perf_counter() - start:.0f} s)")
        live = figaroh_live() if name == "ur10" else None
        if live is not None:
            print(
                f"  FIGAROH {live['figaroh']} (live, training, its default full_params calibration): "
                f"{live['parameters']} params, position {live['position_mm_per_coordinate']:.3f} mm per coordinate, "
                f"orientation {live['orientation_deg']:.3f} deg"
            )
        print(f"  {PUBLISHED[name]}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
