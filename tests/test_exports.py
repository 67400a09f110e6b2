"""Exports and reports: each file loads back, by our reader or by the target format's rules."""

from __future__ import annotations

import numpy as np
import pytest
import trimesh
import yourdfpy
from conftest import ROOT

from brachycal.calibration import calibrate
from brachycal.cli.main import main
from brachycal.data.formats.plus_files import read_coordinate_definitions
from brachycal.data.session import read_session
from brachycal.export import read_itk_transform, read_ros_static_transforms, write_exports, write_itk_transform
from brachycal.export.formats import LPS, image_to_probe_mm
from brachycal.model import Robot
from brachycal.reporting.scene import render_png, robot_scene, save_glb

TWIN = ROOT / "examples" / "twin_session"


@pytest.fixture(scope="module")
def calibrated(robot):
    session = read_session(TWIN, robot)
    return session, calibrate(session, robot)


def test_every_export_loads_back(robot, calibrated, tmp_path):
    _, result = calibrated
    calibration = result.calibration("scaled_uv")
    image = calibration.image
    files = write_exports(robot, calibration, tmp_path)
    # The URDF's meshes are copied beside it (tests/test_exports_handoff.py: the folder is self-contained).
    assert all(f.parent == tmp_path / "meshes" for f in files if f.suffix == ".stl")
    assert {f.name for f in files if f.parent == tmp_path} == {
        "sda10f_calibrated.urdf",
        "ImageToProbe.tfm",
        "ProbeToLeftFlange.tfm",
        "NeedleTipToRightFlange.tfm",
        "PlusCoordinateDefinitions.xml",
        "static_transforms.yaml",
    }
    urdf = Robot.load(tmp_path / "sda10f_calibrated.urdf")
    assert np.abs(urdf.tool_transform("needle_tip")[1] - result.T_ER_Ntip).max() < 1e-12
    assert np.abs(urdf.tool_transform("us_image")[1] - image.T_Ptip_I).max() < 1e-12
    assert yourdfpy.URDF.load(str(tmp_path / "sda10f_calibrated.urdf")).num_actuated_joints == 15
    mm = image_to_probe_mm(image)
    assert np.abs(read_itk_transform(tmp_path / "ImageToProbe.tfm") - mm).max() < 1e-9
    assert np.allclose(
        mm @ [100, 200, 0, 1],
        1e3 * (image.T_Ptip_I @ [100 * image.spacing_m[0], 200 * image.spacing_m[1], 0, 1]) * [1, 1, 1, 1e-3],
    )
    plus = read_coordinate_definitions(tmp_path / "PlusCoordinateDefinitions.xml")
    assert np.abs(plus["Image", "Probe"] - mm).max() < 1e-6
    expected = result.T_EL_Ptip.copy()
    expected[:3, 3] *= 1e3
    assert np.abs(plus["Probe", "LeftFlange"] - expected).max() < 1e-6
    ros = read_ros_static_transforms((tmp_path / "static_transforms.yaml").read_text())
    assert np.abs(ros["arm_right_link_tool0", "needle_tip"] - result.T_ER_Ntip).max() < 1e-12
    assert np.abs(ros["probe_tip", "us_image"] - image.T_Ptip_I).max() < 1e-12


def test_itk_file_follows_slicers_rules(tmp_path):
    # Slicer shows "to parent" = inverse of the file's (LPS) transform, converted to RAS.
    M = np.array([[0, -1, 0, 10.0], [1, 0, 0, -5.0], [0, 0, 1, 2.0], [0, 0, 0, 1]])
    path = write_itk_transform(M, tmp_path / "t.tfm")
    values = np.array(path.read_text().split("Parameters:")[1].split("\n")[0].split(), dtype=float)
    stored = np.eye(4)
    stored[:3, :3], stored[:3, 3] = values[:9].reshape(3, 3), values[9:12]
    assert np.allclose(np.linalg.inv(LPS @ stored @ LPS), M)
    assert np.allclose(read_itk_transform(path), M)


def test_export_and_report_cli(tmp_path, capsys):
    result = tmp_path / "r.json"
    assert main(["calibrate", str(TWIN), "--out", str(result), "--report", str(tmp_path / "report")]) == 0
    html = (tmp_path / "report" / "report.html").read_text()
    assert "TABLE I." in html and "TABLE II." in html and html.count("data:image/png;base64,") == 3
    assert "http://" not in html and "https://" not in html  # self-contained
    assert "samples.csv" in html and "session.toml" in html  # input hashes
    capsys.readouterr()
    assert main(["export", str(result), "--out", str(tmp_path / "x"), "--method", "kabsch"]) == 0
    assert capsys.readouterr().out.splitlines()[0] == "exported method: kabsch (--method)"
    assert (tmp_path / "x" / "static_transforms.yaml").exists()
    assert main(["export", str(result), "--out", str(tmp_path / "x")]) == 2  # never replaces without --force
    assert "already exists" in capsys.readouterr().err


def test_scene_has_the_robot_tools_and_image(robot, tmp_path):
    q = np.loadtxt(ROOT / "examples" / "joint_log.csv", delimiter=",", skiprows=1)[-1, 1:]
    scene = robot_scene(robot, q, points_m=[[0.8, 0.1, 1.0]])
    names = set(scene.graph.nodes_geometry)
    assert {"needle_tip_axes", "probe_tip_axes", "us_image_axes", "us_image_plane", "point_0"} <= names
    back = trimesh.load(save_glb(scene, tmp_path / "s.glb"))
    assert len(back.geometry) == len(scene.geometry)
    plane = back.geometry[next(k for k in back.geometry if "plane" in k)]
    image_corner = robot.fk("us_image", q)[:3, 3]
    assert np.min(np.linalg.norm(plane.vertices - image_corner, axis=1)) < 1e-6
    assert render_png(scene, tmp_path / "s.png").stat().st_size > 10_000


def test_the_loose_write_exports_form_still_writes_the_same_files_and_warns(robot, calibrated, tmp_path):
    _, result = calibrated
    calibration = result.calibration("kabsch")
    new = write_exports(robot, calibration, tmp_path / "new")
    with pytest.warns(DeprecationWarning, match="pass one Calibration"):
        old = write_exports(robot, result.T_ER_Ntip, result.T_EL_Ptip, result.image["kabsch"], tmp_path / "old")
    assert [p.relative_to(tmp_path / "old") for p in old] == [p.relative_to(tmp_path / "new") for p in new]
    # The PLUS file carries the time it was written; every other file is the same bytes.
    for a, b in zip(old, new, strict=True):
        if a.name != "PlusCoordinateDefinitions.xml":
            assert a.read_bytes() == b.read_bytes(), a.name
