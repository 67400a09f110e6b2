"""N-wire segmentation of PLUS's real fCal recording, against PLUS's own segmentation of the same frames.

Run: ``.venv/bin/python benchmarks/nwire_segmentation.py`` (needs ``../shared/reference/plus_fcal_nwire``,
PLUS's public test data from PlusToolkit/PlusLibData). Segments the 190 calibration and 103
validation frames (820×616, 8-bit) with brachycal, writes them as PLUS XML, and records in
``benchmarks/results.json``:

- the fraction of the frames PLUS segmented that brachycal segments too (goal ≥ 95 %);
- the distance of brachycal's wire points to PLUS's on those frames, median and 95th percentile,
  pixels (goal 95th percentile ≤ 1 px);
- the validation 3D reprojection error (best 95 %, PLUS's figure) of ``brachycal nwire``'s affine
  model from brachycal's segmentation, beside the same from PLUS's points and PLUS's own 0.54 mm
  (goal within 0.05 mm of PLUS's);
- CPU time per frame (one thread), seconds.
"""

from __future__ import annotations

import os
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
from timing import record

from brachycal.calibration.phantom.nwire_file import calibrate_nwire_files
from brachycal.data.formats.metaimage import read_image_sequence
from brachycal.data.formats.plus_files import read_plus_config, read_segmented_frames
from brachycal.data.formats.plus_segmentation import read_segmentation_parameters
from brachycal.data.formats.plus_segmented_xml import write_segmented_frames
from brachycal.imaging.nwire_segmentation import segment_sequence

DATA = Path(os.environ.get("BRACHYCAL_REFERENCE", Path(__file__).resolve().parents[2] / "shared" / "reference"))
FOLDER = DATA / "plus_fcal_nwire"
CONFIG = FOLDER / "PlusDeviceSet_fCal_Sim_SpatialCalibration_2.0.xml"
PLUS_FRAMES = FOLDER / "fCal_3NWires_segmented_frames.xml"
SEQUENCES = {
    "calibration": FOLDER / "fCal_Test_Calibration_3NWires_fCal2.0.igs.mha",
    "validation": FOLDER / "fCal_Test_Validation_3NWires_fCal2.0.igs.mha",
}
#: PLUS's validation 3D reprojection error on this recording (best 95 %), mm: PlusLib's fCal regression baseline.
PLUS_VALIDATION_MM = 0.54


def main() -> int:
    if not CONFIG.exists():
        print(f"skipped: {FOLDER} is not there (PLUS's public test data)", file=sys.stderr)
        return 1
    config = read_plus_config(CONFIG)
    params = read_segmentation_parameters(CONFIG)
    plus = dict(zip(("calibration", "validation"), read_segmented_frames(PLUS_FRAMES), strict=True))
    ours = {}
    seconds = 0.0
    frames = 0
    for name, path in SEQUENCES.items():
        sequence = read_image_sequence(path)
        start = time.process_time()  # CPU time: the 2-core machine is shared, wall time says little
        ours[name] = segment_sequence(sequence, config, params, source=path, label=f"{name} frame")
        seconds += time.process_time() - start
        frames += len(sequence)
        print(f"{name}: {ours[name].found} of {len(sequence)} frames segmented; skipped {ours[name].skipped}")
    plus_ok = found_too = extra = 0
    distances = []
    for name in SEQUENCES:
        for theirs, mine in zip(plus[name], ours[name].frames, strict=True):
            if theirs.ok:
                plus_ok += 1
            if theirs.ok and mine.ok:
                found_too += 1
                distances += [float(np.linalg.norm(mine.points_px[w] - uv)) for w, uv in theirs.points_px.items()]
            elif mine.ok:
                extra += 1
    d = np.array(distances)
    print(f"frames PLUS segmented: {plus_ok}; brachycal too: {found_too}; brachycal only: {extra}")
    with tempfile.TemporaryDirectory() as tmp:
        xml = Path(tmp) / "frames.xml"
        write_segmented_frames(
            xml,
            ours["calibration"].frames,
            ours["validation"].frames,
            calibration_times_s=ours["calibration"].timestamps_s,
            validation_times_s=ours["validation"].timestamps_s,
        )
        run_ours = calibrate_nwire_files(CONFIG, xml)
    run_plus = calibrate_nwire_files(CONFIG, PLUS_FRAMES)
    for label, run in (("brachycal's segmentation", run_ours), ("PLUS's segmentation", run_plus)):
        for model, validation in run.models.items():
            best = validation.validation_best95
            print(f"  {label:25s} {model:6s} validation best 95 %: {best.mae_mm:.3f} ± {best.sd_mm:.3f} mm")
    ours_mm = run_ours.models["affine"].validation_best95.mae_mm
    plus_points_mm = run_plus.models["affine"].validation_best95.mae_mm
    print(f"  brachycal nwire on PLUS's own points (affine): {plus_points_mm:.3f} mm")
    fraction = 100.0 * found_too / plus_ok
    record("nwire segmentation: PLUS's frames found", fraction, "%", goal=">= 95 %", met=fraction >= 95.0)
    record(
        "nwire segmentation: point distance to PLUS, median",
        float(np.median(d)),
        "px",
        goal="(p95 <= 1 px)",
        met=bool(np.percentile(d, 95) <= 1.0),
    )
    p95 = float(np.percentile(d, 95))
    record("nwire segmentation: point distance to PLUS, p95", p95, "px", goal="<= 1 px", met=p95 <= 1.0)
    record(
        "nwire segmentation: validation 3D error (best 95 %) from brachycal's segmentation",
        ours_mm,
        "mm",
        goal=f"within 0.05 mm of PLUS's {PLUS_VALIDATION_MM}",
        met=abs(ours_mm - PLUS_VALIDATION_MM) <= 0.05,
        peer="PLUS fCal",
        peer_value=PLUS_VALIDATION_MM,
    )
    per_frame = seconds / frames
    record(
        "nwire segmentation: CPU time per 820x616 frame (one thread)",
        per_frame,
        "s",
        goal="(none; PLUS fCal budgets 70 ms)",
        met=True,
    )
    return 0


if __name__ == "__main__":
    sys.exit(main())
