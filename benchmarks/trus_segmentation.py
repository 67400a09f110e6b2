"""N-wire segmentation of PLUS's TRUS-on-stepper recordings (iCal), against PLUS's own segmentation.

Run: ``.venv/bin/python benchmarks/trus_segmentation.py`` (needs ``../shared/reference/plus_trus_stepper``,
PLUS's public test data from PlusToolkit/PlusLibData, or ``BRACHYCAL_REFERENCE``). Segments every
frame of the five USTC sequences (820×616, 8-bit) with the device set's settings, the poses being
the stepper's (``ProbeToStepperHome``, ``TemplateToStepperHome``), and prints per sequence:

- frames; frames PLUS segmented (its ``UsTemplateCalibration_3NWires.results.xml`` holds the two
  random-motion sequences only: ``—`` for the single-axis ones); of those, the frames brachycal
  segments too (goal ≥ 95 %); frames brachycal segments in all;
- the distance of brachycal's wire points to PLUS's on the frames both segmented: median, 95th
  percentile (goal ≤ 1 px) and largest, pixels;
- CPU time (one thread), seconds.

The two random-motion figures are recorded in ``benchmarks/results.json``.
"""

from __future__ import annotations

import os
import sys
import time
from pathlib import Path

import numpy as np
from timing import record

from brachycal.data.formats.metaimage import read_image_sequence
from brachycal.data.formats.plus_files import read_plus_config, read_pose_streams, read_segmented_frames
from brachycal.data.formats.plus_segmentation import read_segmentation_parameters
from brachycal.imaging.nwire_segmentation import segment_sequence

DATA = Path(os.environ.get("BRACHYCAL_REFERENCE", Path(__file__).resolve().parents[2] / "shared" / "reference"))
FOLDER = DATA / "plus_trus_stepper"
CONFIG = FOLDER / "PlusDeviceSet_iCal_SonixTouch_BlackTargetGuideStepper_1.1.xml"
PLUS_RESULTS = FOLDER / "UsTemplateCalibration_3NWires.results.xml"
#: sequence → which frame set of PLUS's results holds its frames (None: PLUS's results do not).
SEQUENCES = {
    "RandomStepperMotionCalibration": 0,
    "RandomStepperMotionValidation": 1,
    "ProbeRotation": None,
    "ProbeTranslation": None,
    "TemplateTranslation": None,
}


def main() -> int:
    if not CONFIG.exists():
        print(f"skipped: {FOLDER} is not there (PLUS's public test data)", file=sys.stderr)
        return 1
    config = read_plus_config(CONFIG, require_registration=False)
    params = read_segmentation_parameters(CONFIG)
    poses = read_pose_streams(CONFIG)
    plus_sets = read_segmented_frames(PLUS_RESULTS, poses=poses.fields)
    print(f"poses: {poses.probe}, {poses.reference} ({poses.source})")
    header = f"{'sequence':32s} {'frames':>6s} {'PLUS':>5s} {'both':>5s} {'ours':>5s}"
    print(f"{header} {'median px':>10s} {'p95 px':>8s} {'max px':>8s} {'CPU s':>6s}")
    for name, which in SEQUENCES.items():
        path = FOLDER / f"USTC_3NWires_{name}.igs.mha"
        sequence = read_image_sequence(path)
        start = time.process_time()  # CPU time: the machine is shared, wall time says little
        ours = segment_sequence(sequence, config, params, source=path, poses=poses, require_poses=True)
        seconds = time.process_time() - start
        if which is None:
            none = "—"
            print(f"{name:32s} {len(sequence):6d} {none:>5s} {none:>5s} {ours.found:5d}", end="")
            print(f" {none:>10s} {none:>8s} {none:>8s} {seconds:6.1f}")
            continue
        plus = plus_sets[which]
        if len(plus) != len(sequence):
            print(f"{name}: PLUS's results hold {len(plus)} frames, the sequence {len(sequence)}", file=sys.stderr)
            return 1
        plus_ok = [k for k, frame in enumerate(plus) if frame.ok]
        both = [k for k in plus_ok if ours.frames[k].ok]
        d = np.array(
            [
                float(np.linalg.norm(ours.frames[k].points_px[wire] - uv))
                for k in both
                for wire, uv in plus[k].points_px.items()
            ]
        )
        median, p95, largest = float(np.median(d)), float(np.percentile(d, 95)), float(d.max())
        print(
            f"{name:32s} {len(sequence):6d} {len(plus_ok):5d} {len(both):5d} {ours.found:5d} "
            f"{median:10.4f} {p95:8.4f} {largest:8.4f} {seconds:6.1f}"
        )
        fraction = 100.0 * len(both) / len(plus_ok)
        record(f"TRUS segmentation {name}: PLUS's frames found", fraction, "%", goal=">= 95 %", met=fraction >= 95.0)
        record(f"TRUS segmentation {name}: point distance to PLUS, p95", p95, "px", goal="<= 1 px", met=p95 <= 1.0)
    return 0


if __name__ == "__main__":
    sys.exit(main())
