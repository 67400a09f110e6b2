"""Image → Probe of a TRUS probe on a brachytherapy stepper (PLUS's iCal recordings), beside PLUS's result.

Run: ``.venv/bin/python benchmarks/trus_probe.py`` (needs ``../shared/reference/plus_trus_stepper``,
PLUS's public test data from PlusToolkit/PlusLibData). Registers the phantom from the probe-rotation
recording as PLUS does, segments the random-stepper-motion recordings (calibration 212 frames,
validation 106) and calibrates Image → Probe with every N-wire model, twice: with the poses as
recorded (PLUS's) and rebuilt along the device set's calibrated probe translation axis. Prints
the 3D reprojection errors (best 95 %, PLUS's figure) on the calibration and validation frames
and the per-wire 2D validation errors beside PLUS's ``UsTemplateCalibration_3NWires.results.xml``,
and records in ``benchmarks/results.json``:

- the validation 3D error of the chosen model (goal ≤ PLUS's 2.153 mm);
- the validation 3D error of PLUS's own fit (affine, recorded poses) from brachycal's
  segmentation (goal within 0.05 mm of PLUS's 2.153 mm: the same method gives the same figure).
"""

from __future__ import annotations

import os
import sys
from pathlib import Path

import numpy as np
from timing import record

from brachycal.calibration.phantom.nwire import best_fraction
from brachycal.calibration.phantom.stepper_probe import calibrate_stepper_image_files
from brachycal.data.formats.plus_files import parse_xml

DATA = Path(os.environ.get("BRACHYCAL_REFERENCE", Path(__file__).resolve().parents[2] / "shared" / "reference"))
FOLDER = DATA / "plus_trus_stepper"
CONFIG = FOLDER / "PlusDeviceSet_iCal_SonixTouch_BlackTargetGuideStepper_1.1.xml"
PLUS_RESULT = FOLDER / "UsTemplateCalibration_3NWires.results.xml"
ROTATION = FOLDER / "USTC_3NWires_ProbeRotation.igs.mha"
CALIBRATION = FOLDER / "USTC_3NWires_RandomStepperMotionCalibration.igs.mha"
VALIDATION = FOLDER / "USTC_3NWires_RandomStepperMotionValidation.igs.mha"


def plus_figures() -> tuple[dict[str, float], dict[str, tuple[np.ndarray, np.ndarray]]]:
    """PLUS's 3D statistics (mm) and per-wire 2D validation mean and SD (px) from its results file."""
    root = parse_xml(PLUS_RESULT)
    stats = next(root.iter("ReprojectionError3DStatistics")).attrib
    wires = {
        w.get("Name", ""): (
            np.array(w.get("ValidationMeanPx", "").split(), dtype=float),
            np.array(w.get("ValidationStdDevPx", "").split(), dtype=float),
        )
        for w in next(root.iter("ReprojectionError2DStatistics")).iter("Wire")
    }
    return {key: float(value) for key, value in stats.items()}, wires


def main() -> int:
    if not CONFIG.exists():
        print(f"skipped: {FOLDER} is not there (PLUS's public test data)", file=sys.stderr)
        return 1
    plus, plus_wires = plus_figures()
    result = calibrate_stepper_image_files(CONFIG, ROTATION, CALIBRATION, VALIDATION)
    assert result.recorded is not None  # the device set states a tilted probe axis
    r = result.registration
    print(
        f"registration: {r.frames} rotation frames; centre of rotation {r.centre.value[0]:.3f}, "
        f"{r.centre.value[1]:.3f} px (PLUS's baseline 414.094, 22.592); spacing "
        f"{r.spacing.value[0] * 1e3:.6f} x {r.spacing.value[1] * 1e3:.6f} mm/px (0.147096 x 0.142394)"
    )
    print("3D reprojection error, best 95 %, mm (mean ± SD):")
    print(
        f"  {'PLUS (its results file)':40s} validation "
        f"{plus['ValidationMeanMm']:.3f} ± {plus['ValidationStdDevMm']:.3f}"
        f"   calibration {plus['CalibrationMeanMm']:.3f} ± {plus['CalibrationStdDevMm']:.3f}"
    )
    for label, run in (("recorded poses", result.recorded), ("poses along the calibrated axis", result.nwire)):
        for model, v in run.models.items():
            best, cal = v.validation_best95, best_fraction(v.calibration_3d)
            mark = "*" if run is result.nwire and model == run.model else " "
            print(
                f"{mark} {label + ', ' + model:40s} validation {best.mae_mm:.3f} ± {best.sd_mm:.3f}"
                f"   calibration {cal.mae_mm:.3f} ± {cal.sd_mm:.3f}"
            )
    print("per-wire 2D validation error, px (mean du, dv ± SD): PLUS | recorded poses, affine | chosen model")
    ours_plus = result.recorded.models["affine"].wires_2d
    chosen = result.nwire.models[result.nwire.model].wires_2d
    for name, (mean, sd) in plus_wires.items():
        a, b = ours_plus[name], chosen[name]
        print(
            f"  {name:6s} {mean[0]:+6.2f} {mean[1]:+6.2f} ± {sd[0]:.2f} {sd[1]:.2f} | "
            f"{a.mean_px[0]:+6.2f} {a.mean_px[1]:+6.2f} ± {a.sd_px[0]:.2f} {a.sd_px[1]:.2f} | "
            f"{b.mean_px[0]:+6.2f} {b.mean_px[1]:+6.2f} ± {b.sd_px[0]:.2f} {b.sd_px[1]:.2f}"
        )
    plus_mm = plus["ValidationMeanMm"]
    same = result.recorded.models["affine"].validation_best95.mae_mm
    record(
        "trus probe: validation 3D error (best 95 %), PLUS's fit from brachycal's segmentation",
        same,
        "mm",
        goal=f"within 0.05 mm of PLUS's {plus_mm:.3f}",
        met=abs(same - plus_mm) <= 0.05,
        peer="PLUS iCal",
        peer_value=plus_mm,
    )
    best = result.nwire.models[result.nwire.model].validation_best95.mae_mm
    record(
        f"trus probe: validation 3D error (best 95 %), {result.nwire.model} with poses along the calibrated axis",
        best,
        "mm",
        goal=f"<= PLUS's {plus_mm:.3f}",
        met=best <= plus_mm,
        peer="PLUS iCal",
        peer_value=plus_mm,
    )
    return 0


if __name__ == "__main__":
    sys.exit(main())
