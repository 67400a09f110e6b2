"""Stepper calibration of PLUS's TRUS-on-stepper recordings (iCal), against PLUS's regression baseline.

Run: ``.venv/bin/python benchmarks/trus_stepper.py`` (needs the folder ``plus_trus_stepper`` of PLUS's
public test data, PlusToolkit/PlusLibData, under ``BRACHYCAL_REFERENCE``). Runs ``brachycal stepper
calibrate``'s library path on the three single-axis recordings and prints, each with its SD:

- the pixel spacing and the centre of rotation beside PLUS's baseline
  (``USTC_3NWires_StepperCalibrationResultBaseline.xml``; goals: spacing within 1 %, centre within
  2 px), and the least-squares residual statistics beside PLUS's (mm²);
- the rotation axis (its tilt: not determined by a rotation at one probe position) and encoder;
- the probe and template translation axes in PLUS's form ``(x, y, 1)`` beside the values the device
  set stores (``StepperCalibration``): those are from an older calibration session of that stepper,
  not a baseline of these recordings;
- CPU time (one thread), seconds.

The spacing and centre figures are recorded in ``benchmarks/results.json``.
"""

from __future__ import annotations

import os
import sys
import time
from pathlib import Path

import numpy as np
from timing import record

from brachycal.calibration.phantom.stepper import relative_axis
from brachycal.calibration.phantom.stepper_file import calibrate_stepper_files
from brachycal.data.formats.plus_files import parse_xml

DATA = Path(os.environ.get("BRACHYCAL_REFERENCE", Path(__file__).resolve().parents[2] / "shared" / "reference"))
FOLDER = DATA / "plus_trus_stepper"
CONFIG = FOLDER / "PlusDeviceSet_iCal_SonixTouch_BlackTargetGuideStepper_1.1.xml"
BASELINE = FOLDER / "USTC_3NWires_StepperCalibrationResultBaseline.xml"
RECORDINGS = [
    FOLDER / f"USTC_3NWires_{name}.igs.mha" for name in ("ProbeRotation", "ProbeTranslation", "TemplateTranslation")
]


def _numbers(text: str | None) -> np.ndarray:
    return np.array((text or "").split(), dtype=float)


def main() -> int:
    if not CONFIG.exists():
        print(f"skipped: {FOLDER} is not there (PLUS's public test data)", file=sys.stderr)
        return 1
    baseline = parse_xml(BASELINE)
    plus_spacing = baseline.find("SpacingCalibrationResult")
    plus_centre = baseline.find("CenterOfRotationCalibrationResult")
    stored = parse_xml(CONFIG).find(".//StepperCalibration")
    assert plus_spacing is not None and plus_centre is not None and stored is not None
    start = time.process_time()  # CPU time: the 2-core machine is shared, wall time says little
    result = calibrate_stepper_files(CONFIG, *RECORDINGS)
    seconds = time.process_time() - start
    for r in result.recordings.values():
        print(f"{Path(r.path).name}: {len(r.frames)} of {r.total} frames segmented")

    s, s_sd = result.spacing.value * 1e3, result.spacing_sd * 1e3
    ps = _numbers(plus_spacing.get("Spacing"))
    c, c_sd = result.rotation.centre_px, result.rotation.centre_sd_px
    pc = _numbers(plus_centre.get("CenterOfRotationPx"))
    print("\n| quantity | brachycal (± SD) | PLUS baseline | difference |\n|---|---|---|---|")
    for k, axis in enumerate("uv"):
        print(
            f"| spacing {axis}, mm/px | {s[k]:.6f} ± {s_sd[k]:.6f} | {ps[k]:.6f} | {100 * (s[k] / ps[k] - 1):+.4f} % |"
        )
    for k, axis in enumerate("uv"):
        print(f"| centre {axis}, px | {c[k]:.3f} ± {c_sd[k]:.3f} | {pc[k]:.3f} | {c[k] - pc[k]:+.3f} px |")
    for label, fit, plus in (("spacing", result.spacing, plus_spacing), ("centre", result.rotation.fit, plus_centre)):
        mean, sd = fit.residual_mean * 1e6, fit.residual_sd * 1e6
        print(
            f"| {label} residuals mean, SD, mm² | {mean:.4f}, {sd:.4f} | "
            f"{float(plus.get('ErrorMean', 'nan')):.4f}, {float(plus.get('ErrorStdev', 'nan')):.4f} | |"
        )
    all_s = result.spacing_all.value * 1e3
    print(f"\nspacing from all three recordings: {all_s[0]:.6f} x {all_s[1]:.6f} mm/px (cross-check)")
    rot = result.rotation
    print(f"rotation axis tilt: {'not determined: ' + rot.tilt_note if rot.tilt is None else rot.tilt}")
    e = result.encoder
    print(
        f"rotation encoder: PLUS scale {-e.scale:.5f} ± {e.scale_sd:.5f} (device set: "
        f"{stored.get('ProbeRotationEncoderScale')}), offset {np.degrees(e.offset_rad):.3f} ± "
        f"{np.degrees(e.offset_sd_rad):.3f}°"
    )
    print(
        f"\ntranslation axes, PLUS's form (x, y, 1); device set's values from an older session ({stored.get('Date')}):"
    )
    print("| axis | brachycal x ± SD | brachycal y ± SD | older session x, y | angle to wires |\n|---|---|---|---|---|")
    for label, axis, attribute in (
        ("probe", result.probe_axis, "ProbeTranslationAxisOrientation"),
        ("template", result.template_axis, "TemplateTranslationAxisOrientation"),
    ):
        o, sd = axis.plus_orientation, axis.slope_sd
        old = _numbers(stored.get(attribute))
        print(
            f"| {label} | {o[0]:+.6f} ± {sd[0]:.6f} | {o[1]:+.6f} ± {sd[1]:.6f} | "
            f"{old[0]:+.6f}, {old[1]:+.6f} | {axis.angle_deg:.3f}° |"
        )
    rel, rel_sd = relative_axis(result.probe_axis, result.template_axis)
    old_rel = _numbers(stored.get("ProbeTranslationAxisOrientation")) + _numbers(
        stored.get("TemplateTranslationAxisOrientation")
    )
    print(
        f"| template relative to probe | {-rel[0]:+.6f} ± {rel_sd[0]:.6f} | {rel[1]:+.6f} ± {rel_sd[1]:.6f} | "
        f"{old_rel[0]:+.6f}, {old_rel[1]:+.6f} | {np.degrees(np.arctan(np.hypot(*rel))):.3f}° |"
    )
    print(f"\nCPU time: {seconds:.1f} s")

    spacing_pct = float(np.max(np.abs(s / ps - 1)) * 100)
    record(
        "trus stepper: pixel spacing vs PLUS's baseline, largest relative difference",
        spacing_pct,
        "%",
        goal="<= 1 %",
        met=spacing_pct <= 1.0,
    )
    centre_px = float(np.linalg.norm(c - pc))
    record(
        "trus stepper: centre of rotation vs PLUS's baseline, distance",
        centre_px,
        "px",
        goal="<= 2 px",
        met=centre_px <= 2.0,
    )
    return 0


if __name__ == "__main__":
    sys.exit(main())
