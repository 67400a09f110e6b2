"""The ``brachycal-pivot/1`` and ``brachycal-nwire/1`` files: written by the library, read back intact.

Each format has one home (``calibration.pivot_file``, ``calibration.nwire_file``): the command
line only calls it. A round trip must give back the estimate that was written, and the readers
refuse what is not their format, naming the file and the key.
"""

from __future__ import annotations

import hashlib
import json

import numpy as np
import pytest
from conftest import reference
from scipy.spatial.transform import Rotation

from brachycal.calibration import (
    calibrate_nwire_files,
    calibrate_pivot_files,
    read_nwire,
    read_pivot,
    write_nwire,
    write_pivot,
)
from brachycal.data.pose_list import COLUMNS
from brachycal.errors import InputError
from brachycal.se3 import make_transform

P_TOOL_TIP = np.array([0.01, -0.02, 0.25])  # metres, in the tool (marker) frame
P_PIVOT = np.array([0.6, 0.1, 0.9])  # metres, in the reference frame


def pose_list(path, n: int = 12) -> None:
    """Exact poses of a tool turned about its fixed tip (tip at P_TOOL_TIP, pivot at P_PIVOT)."""
    rows = [",".join(["key", *COLUMNS])]
    for k in range(n):
        R = Rotation.from_euler("xyz", [25 * np.sin(k), 25 * np.cos(1.3 * k), 10 * k], degrees=True).as_matrix()
        T = make_transform(R, P_PIVOT - R @ P_TOOL_TIP)
        rows.append(",".join([f"pose{k}", *(repr(float(x)) for x in T.ravel())]))
    path.write_text("\n".join(rows) + "\n")


def test_pivot_file_round_trip(tmp_path):
    poses = tmp_path / "poses.csv"
    pose_list(poses)
    calibration = calibrate_pivot_files(poses, "algebraic", "m")
    # Noise-free poses: the estimate is the truth up to the least-squares solve's rounding (1e-12 m
    # is a thousand times that, and a million times below any real tip error).
    assert np.abs(calibration.result.p_marker_tip - P_TOOL_TIP).max() < 1e-12
    assert np.abs(calibration.result.p_ref_pivot - P_PIVOT).max() < 1e-12
    assert calibration.inputs == {"poses.csv": hashlib.sha256(poses.read_bytes()).hexdigest()}
    assert calibration.pose_names[0] == "pose0" and calibration.outliers == []

    out = tmp_path / "pivot.json"
    write_pivot(calibration, out)
    stored = read_pivot(out)
    # JSON keeps every float exactly (Python writes the shortest text that reads back the same number).
    np.testing.assert_array_equal(stored.p_tool_tip, calibration.result.p_marker_tip)
    np.testing.assert_array_equal(stored.p_reference_pivot, calibration.result.p_ref_pivot)
    assert stored.units == "m" and stored.raw == calibration.to_json()
    assert stored.raw["format"] == "brachycal-pivot/1" and stored.raw["n_poses"] == 12


def test_pivot_reader_refuses_other_files(tmp_path):
    wrong = tmp_path / "wrong.json"
    wrong.write_text(json.dumps({"format": "brachycal-result/1"}))
    with pytest.raises(InputError, match=r"wrong\.json, key 'format': format is 'brachycal-result/1'"):
        read_pivot(wrong)
    poses = tmp_path / "poses.csv"
    pose_list(poses)
    payload = calibrate_pivot_files(poses).to_json()
    payload["tip_in_tool"] = [0.0, None, 1.0]
    broken = tmp_path / "broken.json"
    broken.write_text(json.dumps(payload))
    with pytest.raises(InputError, match=r"broken\.json, column 'tip_in_tool\[1\]': must be a number, got null"):
        read_pivot(broken)


@pytest.mark.parametrize(("units", "scale", "other"), [("m", 1e3, "mm"), ("mm", 1e-3, "m")])
def test_pivot_reader_refuses_a_tip_in_the_other_unit(tmp_path, units, scale, other):
    """A pivot whose lengths are in the other unit than its ``units`` says: the tip is then as far
    from the tool's origin as no tool is long (the same rule as the pivot's own pose list)."""
    poses = tmp_path / "poses.csv"
    pose_list(poses)
    payload = calibrate_pivot_files(poses, "algebraic", "m").to_json()
    payload["units"] = units
    if units == "mm":
        payload["tip_in_tool"] = [1e3 * v for v in payload["tip_in_tool"]]
        payload["pivot_in_reference"] = [1e3 * v for v in payload["pivot_in_reference"]]
    accepted = tmp_path / "ok.json"
    accepted.write_text(json.dumps(payload))
    assert read_pivot(accepted).units == units
    payload["tip_in_tool"] = [scale * v for v in payload["tip_in_tool"]]
    broken = tmp_path / "broken.json"
    broken.write_text(json.dumps(payload))
    with pytest.raises(InputError, match=rf"broken\.json, column 'tip_in_tool': .*is it in {other}\?"):
        read_pivot(broken)


def test_nwire_file_round_trip(tmp_path):
    folder = reference("plus_fcal_nwire")
    config = folder / "PlusDeviceSet_fCal_Sim_SpatialCalibration_2.0.xml"
    frames = folder / "fCal_3NWires_segmented_frames.xml"
    run = calibrate_nwire_files(config, frames)
    # PLUS's own figure for this recording (its regression baseline, best 95 %), to its 3 decimals.
    assert round(run.models["affine"].validation_best95.mae_mm, 3) == 0.540
    assert set(run.inputs) == {config.name, frames.name}

    out = tmp_path / "nwire.json"
    write_nwire(run, out)
    stored = read_nwire(out)
    # JSON keeps every float exactly; the spacing and the affine matrix are stored in millimetres,
    # so reading them back may differ by an ulp (1e-19 m/px and 1e-15 m guard that, nothing coarser).
    np.testing.assert_array_equal(stored.T_Ptip_I, run.calibration.T_Ptip_I)
    assert np.abs(stored.spacing_m - run.calibration.spacing_m).max() < 1e-19
    assert np.abs(stored.affine - run.calibration.affine).max() < 1e-15
    assert stored.raw == run.to_json() and stored.raw["format"] == "brachycal-nwire/1"


def test_nwire_reader_refuses_a_transform_that_is_not_rigid(tmp_path):
    payload = {
        "format": "brachycal-nwire/1",
        "T_Probe_Image": np.diag([2.0, 1.0, 1.0, 1.0]).tolist(),  # scaled: not a pose
        "spacing_mm": [0.08, 0.07],
        "affine_mm": np.eye(4).tolist(),
    }
    path = tmp_path / "scaled.json"
    path.write_text(json.dumps(payload))
    with pytest.raises(InputError, match=r"scaled\.json, column 'T_Probe_Image': 4x4 matrix is not a rigid transform"):
        read_nwire(path)
