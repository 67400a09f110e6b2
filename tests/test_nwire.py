"""N-wire calibration: PLUS file readers, exact synthetic case, PLUS's own result on its real data."""

from __future__ import annotations

import dataclasses
import json
from pathlib import Path

import numpy as np
import pytest
from conftest import reference
from scipy.spatial.transform import Rotation

from brachycal import InputError
from brachycal.calibration.phantom.hand_eye import hand_eye
from brachycal.calibration.phantom.nwire import (
    best_fraction,
    calibrate_nwire,
    fit_affine,
    reprojection_errors,
    rotation_difference_deg,
    wire_errors_2d,
    wire_point_pairs,
)
from brachycal.cli.main import main
from brachycal.data.formats.metaimage import read_sequence_header
from brachycal.data.formats.plus_files import (
    read_plus_config,
    read_segmented_frames,
    sequence_transform,
)
from brachycal.se3 import inverse, make_transform
from brachycal.studies.nwire_twin import NWireSimConfig, simulate_nwire


def plus(name: str) -> Path:
    """A file of PLUS's fCal 3-N-wire recording (outside data: skips the test where it is absent)."""
    return reference("plus_fcal_nwire", name)


CONFIG = "PlusDeviceSet_fCal_Sim_SpatialCalibration_2.0.xml"
FRAMES = "fCal_3NWires_segmented_frames.xml"
SEQUENCE = "fCal_Test_Validation_3NWires_fCal2.0.igs.mha"

# PLUS's regression baseline for this recording (PlusLibData TestImages/
# FreehandCalibration3NWires_fCal2.0.results.xml): Image->Probe (mm), validation 3D error as PLUS
# reports it (mean and SD of the best 95 %), and per-wire validation 2D error means (px).
PLUS_IMAGE_TO_PROBE_MM = np.array(
    [
        [-0.000519165, 0.0744587, 0.000837223, 11.2137],
        [-0.0803067, -6.68987e-005, 0.00174527, 48.4162],
        [0.00181709, -0.000804192, 0.0773718, -0.398993],
        [0, 0, 0, 1],
    ]
)
PLUS_VALIDATION_MEAN_MM, PLUS_VALIDATION_SD_MM = 0.539932, 0.223536
PLUS_WIRE_2D_MEAN_PX = {
    "7:G1_g1": (3.766, 0.508),
    "8:L1_h1": (-2.249, -0.484),
    "9:M1_m1": (-3.844, 2.315),
    "4:G3_g3": (5.614, -4.501),
    "5:H3_l3": (1.393, 0.350),
    "6:M3_m3": (-1.423, 4.196),
    "1:H5_h5": (1.057, -0.302),
    "2:L5_i5": (-2.485, -0.656),
    "3:M5_m5": (-2.285, -1.343),
}


@pytest.fixture(scope="module")
def real():
    config = read_plus_config(plus(CONFIG))
    calibration, validation = read_segmented_frames(plus(FRAMES))
    return config, calibration, validation


def test_readers(real):
    config, calibration, validation = real
    assert len(config.patterns) == 3 and [w.name for w in config.patterns[0]] == ["7:G1_g1", "8:L1_h1", "9:M1_m1"]
    assert np.allclose(config.patterns[0][1].front_m, [0.055, 0.0, 0.020])
    assert ("Phantom", "Reference") in config.transforms and config.approximate_spacing_m == pytest.approx(0.078e-3)
    assert len(calibration) == 190 and sum(f.ok for f in calibration) == 184
    assert len(validation) == 103 and all(f.ok for f in validation)
    header, frames = read_sequence_header(plus(SEQUENCE))
    assert header["DimSize"].split() == ["820", "616", "103"] and len(frames) == 103
    for k in (0, 50, 102):  # the sequence header carries the same tracker readings as the XML
        T = sequence_transform(frames[k], "ProbeToTrackerTransform", plus(SEQUENCE), k)
        assert np.allclose(T, validation[k].T_tracker_probe, atol=1e-12)


def test_unsafe_and_malformed_xml_is_refused(tmp_path):
    bomb = tmp_path / "bomb.xml"
    bomb.write_text(
        '<?xml version="1.0"?><!DOCTYPE l [<!ENTITY a "aaaaaaaaaa"><!ENTITY b "&a;&a;&a;&a;">]>'
        "<PlusConfiguration>&b;</PlusConfiguration>"
    )
    with pytest.raises(InputError, match="refused unsafe XML"):
        read_plus_config(bomb)
    broken = tmp_path / "broken.xml"
    broken.write_text("<PlusConfiguration><Pattern")
    with pytest.raises(InputError, match=r"broken\.xml: not valid XML"):
        read_plus_config(broken)
    empty = tmp_path / "empty.xml"
    empty.write_text("<PlusConfiguration/>")
    with pytest.raises(InputError, match="no N-wire patterns"):
        read_plus_config(empty)
    bad = tmp_path / "frames.xml"
    bad.write_text(
        plus(FRAMES).read_text().replace('Name="ProbeToTrackerTransform" Value="0.239045', 'Name="X" Value="0')
    )
    with pytest.raises(InputError, match=r"ValidationData Frame 0.*missing ProbeToTrackerTransform"):
        read_segmented_frames(bad)


def test_middle_wire_points_match_plus(real):
    config, calibration, _ = real
    _, p_probe, _ = wire_point_pairs(config, calibration)
    plus = np.concatenate([f.plus_middle_probe_m for f in calibration if f.ok])
    assert p_probe.shape == plus.shape == (552, 3)
    assert np.abs(p_probe - plus).max() < 1e-6  # 0.001 mm; PLUS wrote 6 significant digits


def test_real_recording_reproduces_plus_baseline(real):
    config, calibration, validation = real
    uv, p_probe, _ = wire_point_pairs(config, calibration)
    affine, _kept = fit_affine(uv, p_probe)
    affine_mm = affine.copy()
    affine_mm[:3] *= 1e3
    assert np.abs(affine_mm - PLUS_IMAGE_TO_PROBE_MM).max() < 1e-4
    result = calibrate_nwire(uv, p_probe, config.approximate_spacing_m)
    uv_v, p_v, _ = wire_point_pairs(config, validation)
    best = best_fraction(reprojection_errors(result, uv_v, p_v, "affine"))
    assert best.mae_mm == pytest.approx(PLUS_VALIDATION_MEAN_MM, abs=1e-4)
    assert best.sd_mm == pytest.approx(PLUS_VALIDATION_SD_MM, abs=1e-4)
    for name, errors in wire_errors_2d(result, config, validation, "affine").items():
        assert np.abs(errors.mean(axis=0) - PLUS_WIRE_2D_MEAN_PX[name]).max() < 0.01, name
    # The constrained model (rotation + two spacings) lands within PLUS's own test tolerances of its matrix.
    rigid_mm = result.T_Ptip_I @ np.diag([*result.spacing_m, 1.0, 1.0])
    rigid_mm[:3] *= 1e3
    assert rotation_difference_deg(rigid_mm, PLUS_IMAGE_TO_PROBE_MM) < 0.5
    assert np.linalg.norm(rigid_mm[:3, 3] - PLUS_IMAGE_TO_PROBE_MM[:3, 3]) < 1.0
    rigid = best_fraction(reprojection_errors(result, uv_v, p_v, "rigid"))
    assert rigid.mae_mm < 0.56


def test_exact_synthetic_nwire_is_recovered():
    T_marker_image = make_transform(
        Rotation.from_euler("xyz", [80, -5, 3], degrees=True).as_matrix(), [0.02, -0.01, 0.03]
    )
    spacing = np.array([0.19e-3, 0.183e-3])
    config, frames, validation = simulate_nwire(T_marker_image, spacing, (1080, 720), NWireSimConfig().without_noise())
    uv, p, _ = wire_point_pairs(config, frames)
    result = calibrate_nwire(uv, p, 0.19e-3)
    assert np.abs(result.T_Ptip_I - T_marker_image).max() < 1e-9
    assert np.abs(result.spacing_m - spacing).max() < 1e-15
    assert np.abs(result.affine[:3, :2] - T_marker_image[:3, :2] * spacing).max() < 1e-12
    uv_v, p_v, _ = wire_point_pairs(config, validation)
    assert reprojection_errors(result, uv_v, p_v).max_mm < 1e-9


def test_hand_eye_recovers_the_marker_mount():
    rng = np.random.default_rng(0)
    X = make_transform(Rotation.random(random_state=1).as_matrix(), [0.04, -0.02, 0.1])
    flange = [make_transform(Rotation.random(random_state=k + 2).as_matrix(), rng.normal(size=3)) for k in range(6)]
    A = np.array([inverse(flange[0]) @ f for f in flange[1:]])
    B = np.array([inverse(X) @ a @ X for a in A])
    assert np.abs(hand_eye(A, B) - X).max() < 1e-12
    spin = np.array([make_transform(Rotation.from_rotvec([0, 0, a]).as_matrix(), [0, 0, 0.1]) for a in (0.3, 0.5)])
    with pytest.raises(InputError, match="one axis only"):
        hand_eye(spin, spin)


def test_cli(tmp_path, capsys):
    out = tmp_path / "nwire.json"
    assert main(["nwire", str(plus(CONFIG)), str(plus(FRAMES)), "--out", str(out)]) == 0
    assert "best 95% 0.540 ± 0.224" in capsys.readouterr().out
    payload = json.loads(out.read_text())
    assert payload["errors"]["affine"]["validation_3d"]["n"] == 309
    assert np.allclose(payload["affine_spacing_mm"], [0.08033, 0.07446], atol=1e-5)
    assert main(["nwire", str(plus(FRAMES)), str(plus(FRAMES)), "--out", str(tmp_path / "x.json")]) == 2
    assert "no N-wire patterns" in capsys.readouterr().err


def test_frame_or_configuration_without_a_transform_is_refused_naming_it():
    """A segmented frame built in code without a tracker reading, or a configuration without the
    phantom registration, is one InputError naming the file and the frame — not a TypeError from
    multiplying by None (nor a KeyError)."""
    T_marker_image = make_transform(np.eye(3), [0.02, -0.01, 0.03])
    config, frames, _ = simulate_nwire(
        T_marker_image, np.array([0.19e-3, 0.19e-3]), (1080, 720), NWireSimConfig().without_noise()
    )
    calibration = calibrate_nwire(*wire_point_pairs(config, frames)[:2], 0.19e-3)
    k = next(i for i, f in enumerate(frames) if f.ok)
    for field, reading in (
        ("T_tracker_probe", "ProbeToTrackerTransform"),
        ("T_tracker_reference", "ReferenceToTrackerTransform"),
    ):
        broken = list(frames)
        broken[k] = dataclasses.replace(frames[k], source="frames.xml", label="CalibrationData Frame", **{field: None})
        where = rf"^frames\.xml, CalibrationData Frame {frames[k].index}: segmented frame has no {reading} tracker"
        with pytest.raises(InputError, match=where):
            wire_point_pairs(config, broken)
        with pytest.raises(InputError, match=where):
            wire_errors_2d(calibration, config, broken)
    unregistered = dataclasses.replace(
        config,
        source="device_set.xml",
        transforms={key: T for key, T in config.transforms.items() if key[0] != "Phantom"},
    )
    for refused in (
        lambda: wire_point_pairs(unregistered, frames),
        lambda: wire_errors_2d(calibration, unregistered, frames),
    ):
        with pytest.raises(
            InputError,
            match=r"^device_set\.xml: no Phantom->Reference transform .*: missing "
            r"PlusConfiguration/CoordinateDefinitions/Transform\[@From='Phantom'\]\[@To='Reference'\]$",
        ):
            refused()
