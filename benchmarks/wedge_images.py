"""Multi-wedge calibration from the twin's rendered B-mode frames, beside its simulated segmentations.

Run: ``OMP_NUM_THREADS=1 .venv/bin/python benchmarks/wedge_images.py [--seeds N] [--frames F]``
(default 3 seeds, 50 frames a session; ~1 min of CPU). Per seed: the twin (``TwinConfig(seed)``),
the multi-wedge session of ``studies.phantom_twin`` with the N-wire twin's default lab
(tracker, registration, print tolerance, beam), calibrated two ways —

- **simulated**: the session's own segmentations (each line end 0.5 px SD and the leading-edge
  bias of the 0.6 mm beam: ``phantom_twin``'s path, as ``brachycal demo --table3``);
- **images**: every frame rendered (``studies.phantom_images``: speckle, PSF, 1.5 mm Gaussian
  beam, attenuation, TGC, noise, log compression) and its lines found by
  ``imaging.wedge_lines.find_wedge_lines`` (frames where not every face is found are skipped);

and both judged by the same end-to-end targeting error (50 targets; the needle's calibration the
truth and the hand–eye calibration the route's, so that only the image calibration differs).
Records in ``benchmarks/results.json``: the line ends' depth error against the true lines (RMS,
pixels), the frames skipped (%), the targeting MAE of both paths (mean over seeds, mm) and the CPU
time per frame of rendering plus segmentation.
"""

from __future__ import annotations

import argparse
import time

import numpy as np
from timing import record

from brachycal.calibration import Calibration
from brachycal.calibration.phantom.wedge import calibrate_wedge
from brachycal.calibration.result import ImageCalibration
from brachycal.model import Robot
from brachycal.se3 import inverse
from brachycal.simulation.twin import TwinConfig, simulate
from brachycal.studies.nwire_twin import T_PTIP_MARKER, NWireSimConfig
from brachycal.studies.phantom_images import rendered_wedge_observations
from brachycal.studies.phantom_twin import phantom_route, simulate_phantom
from brachycal.studies.targeting import targeting_error


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, default=3)
    parser.add_argument("--frames", type=int, default=50)
    parser.add_argument("--targets", type=int, default=50)
    args = parser.parse_args()
    robot = Robot.load()
    errors_px: list[np.ndarray] = []
    skipped = frames = 0
    mae = {"simulated": [], "images": []}
    cpu = 0.0
    for seed in range(args.seeds):
        twin = simulate(robot, TwinConfig(seed=seed))
        truth = twin.truth
        sim = NWireSimConfig(seed=seed)
        route = phantom_route(twin, "wedge", sim, frames=args.frames)
        # The same session as the route's (the same seed's streams), with its truth for the renderer.
        T_marker_image = inverse(T_PTIP_MARKER) @ truth.T_Ptip_I
        size = (int(truth.size_px[0]), int(truth.size_px[1]))
        session = simulate_phantom("wedge", T_marker_image, truth.spacing_m, size, sim, frames=args.frames)
        start = time.process_time()
        segmented = rendered_wedge_observations(session, truth.spacing_m, size)
        cpu += time.process_time() - start
        fit = calibrate_wedge(session.phantom, segmented.observations)
        errors_px.append(segmented.line_error_px.ravel())
        skipped += segmented.skipped
        frames += args.frames
        images = ImageCalibration("wedge-images", fit.T_marker_image, fit.spacing_m)
        for label, image in (("simulated", route.image), ("images", images)):
            result = targeting_error(twin, Calibration(truth.T_ER_Ntip, route.T_EL_marker, image), args.targets)
            mae[label].append(result.stats.mae_mm)
        print(
            f"seed {seed}: line error {np.sqrt(np.mean(errors_px[-1] ** 2)):.3f} px RMS, "
            f"{segmented.skipped} of {args.frames} frames skipped; targeting MAE simulated "
            f"{mae['simulated'][-1]:.3f} mm, images {mae['images'][-1]:.3f} mm",
            flush=True,
        )
    e = np.concatenate(errors_px)
    rms = float(np.sqrt(np.mean(e**2)))
    print(f"line error: RMS {rms:.3f} px, mean {e.mean():+.3f} px over {len(e)} line ends")
    record("wedge images: line end depth error vs true line, RMS", rms, "px", goal="<= 0.5 px", met=rms <= 0.5)
    percent = 100.0 * skipped / frames
    record("wedge images: frames skipped (not every face found)", percent, "%", goal="<= 5 %", met=percent <= 5.0)
    simulated, images = float(np.mean(mae["simulated"])), float(np.mean(mae["images"]))
    record(
        f"wedge images: targeting MAE from rendered frames, mean over {args.seeds} seeds",
        images,
        "mm",
        goal="within 0.3 mm of the simulated segmentation's",
        met=abs(images - simulated) <= 0.3,
        peer="simulated segmentation",
        peer_value=simulated,
    )
    per_frame = cpu / frames
    record(
        "wedge images: CPU time per 1080x720 frame, rendering and segmentation (one thread)",
        per_frame,
        "s",
        goal="<= 0.5 s",
        met=per_frame <= 0.5,
    )


if __name__ == "__main__":
    main()
