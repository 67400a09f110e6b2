"""The whole chain's image noise along the image's axes, on twin sessions whose noise is known.

The annotation noise lies in the image plane (lateral and depth), the needle tip's distance from
the plane along its normal: the per-coordinate level of ``base_link`` pools them, the per-axis
levels must find each.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from brachycal.calibration import calibrate
from brachycal.calibration.chain import IMAGE_AXES, fit_chain
from brachycal.simulation.twin import TwinConfig, simulate

#: Known noise: 1.2 px per image axis, the tip uniformly within ±0.3 mm of the plane; nothing else.
ANNOTATION_PX = 1.2
BEAM_M = 0.6e-3
SEEDS = range(8)


@pytest.fixture(scope="module")
def fits(robot):
    out = []
    for seed in SEEDS:
        config = TwinConfig(seed=seed, annotation_sd_px=ANNOTATION_PX, beam_thickness_m=BEAM_M, sound_speed=False)
        config = replace(config, kinematic_error=False, encoder_noise=False, jog_error=False)
        twin = simulate(robot, config)
        fit = fit_chain(twin.session, robot, calibrate(twin.session, robot, ("kabsch",)), "rigid")
        out.append((fit, twin))
    return out


def test_image_noise_along_each_axis_is_the_known_noise(fits):
    # Each σ̂²/σ² is χ²_ν/ν (ν ≈ 62 per axis): its mean over the seeds has SD √(2/ν)/√(seeds); the
    # band is four of those. A pooled per-coordinate level would give 2/3 of the
    # annotation variance along the plane's axes and 1.5 times the beam's along the normal.
    ratios = {axis: [] for axis in IMAGE_AXES}
    dofs = []
    for fit, twin in fits:
        truth = dict(zip(IMAGE_AXES[:2], twin.truth.spacing_m * ANNOTATION_PX, strict=True))
        truth["normal"] = BEAM_M / np.sqrt(12.0)
        for axis in IMAGE_AXES:
            level = fit.image_axes_noise[axis]
            ratios[axis].append(level.sd_m**2 / truth[axis] ** 2)
            dofs.append(level.dof)
    n_samples = len(fits[0][1].session.uv_px)
    assert all(n_samples - 8 < d < n_samples for d in dofs)  # the leverages take a few per axis
    band = 4 * np.sqrt(2 / np.mean(dofs)) / np.sqrt(len(fits))
    for axis, values in ratios.items():
        assert abs(np.mean(values) - 1.0) < band, (axis, np.mean(values), band)


def test_the_pooled_level_is_the_mean_of_the_axes(fits):
    # The same residuals: the per-coordinate level's variance is about the mean of the three axes'.
    for fit, _ in fits:
        per_axis = np.mean([fit.image_axes_noise[a].sd_m ** 2 for a in IMAGE_AXES])
        assert fit.noise["image"].sd_m ** 2 == pytest.approx(per_axis, rel=0.05)
