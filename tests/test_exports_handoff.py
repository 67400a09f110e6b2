"""Exports that work where they land: a self-contained folder (meshes copied), a ROS 2 package,
YAML that another reader reads as numbers, PLUS's ImageToProbe convention, corrections applied
once, and one default method for locate and export."""

from __future__ import annotations

import ast
import csv
import io
import json
import os
import re
import shutil
import xml.etree.ElementTree as ET
from contextlib import redirect_stdout
from pathlib import Path

import numpy as np
import pinocchio as pin
import pytest
import yaml  # PyYAML: a reader that is not ours (YAML 1.1, as ROS 1's rosparam)
import yourdfpy
from conftest import ROOT, reference
from hostile import Case, check_refusal

from brachycal.calibration import Calibration, ImageCalibration, read_result
from brachycal.cli.main import main
from brachycal.data.formats.plus_files import read_coordinate_definitions
from brachycal.export import read_itk_transform, write_exports
from brachycal.export.formats import image_to_probe_mm
from brachycal.model import Robot
from brachycal.model.description import load_description
from brachycal.se3 import make_transform

TWIN = ROOT / "examples" / "twin_session"
UV = (540.0, 300.0)


def run(argv: list[str]) -> str:
    out = io.StringIO()
    with redirect_stdout(out):
        assert main([str(a) for a in argv]) == 0
    return out.getvalue()


@pytest.fixture(scope="module")
def results(tmp_path_factory) -> dict[str, Path]:
    """A sequential result and a whole-chain result with joint offsets, of the twin's session, and
    one configuration of the probe arm (the joint log's last row)."""
    folder = tmp_path_factory.mktemp("results")
    run(["calibrate", TWIN, "--out", folder / "sequential.json", "--quiet"])
    run(["calibrate", TWIN, "--solve", "chain", "--joint-offsets", "--out", folder / "offsets.json", "--quiet"])
    rows = list(csv.reader((ROOT / "examples" / "joint_log.csv").open()))
    with (folder / "joints.csv").open("w", newline="") as f:
        csv.writer(f).writerows([rows[0], rows[-1]])
    return {
        "sequential": folder / "sequential.json",
        "offsets": folder / "offsets.json",
        "joints": folder / "joints.csv",
    }


def located(result: Path, joints: Path, *extra: object) -> np.ndarray:
    """``(3,)`` the point (metres, base_link) ``brachycal locate`` prints for pixel UV."""
    text = run(["locate", result, joints, "--uv", f"{UV[0]},{UV[1]}", *extra])
    return np.array(text.splitlines()[1].split(",")[1:], dtype=float)


def mesh_files(urdf: Path) -> list[str]:
    return [m.get("filename", "") for m in ET.parse(urdf).getroot().iter("mesh")]


# --- a self-contained folder ---------------------------------------------------------------------


def test_a_copied_export_folder_loads_from_another_directory(results, tmp_path, monkeypatch):
    run(["export", results["sequential"], "--out", tmp_path / "x"])
    copy = tmp_path / "elsewhere" / "deeper" / "x"
    shutil.copytree(tmp_path / "x", copy)
    shutil.rmtree(tmp_path / "x")  # nothing may point back at the first folder (nor into the install)
    monkeypatch.chdir(tmp_path / "elsewhere")
    urdf = copy / "sda10f_calibrated.urdf"
    names = mesh_files(urdf)
    assert names and all(n.startswith("meshes/") for n in names)
    # Only the meshes the URDF names are copied, each once.
    assert {p.relative_to(copy).as_posix() for p in (copy / "meshes").rglob("*") if p.is_file()} == set(names)

    model, collision, visual = pin.buildModelsFromUrdf(str(urdf), package_dirs=[str(copy)])
    assert model.nq == 15 and collision.ngeoms == visual.ngeoms == len(names) / 2
    loaded = yourdfpy.URDF.load(
        str(urdf), load_meshes=True, build_collision_scene_graph=True, load_collision_meshes=True
    )
    assert loaded.num_actuated_joints == 15
    assert len(loaded.scene.geometry) > 0 and len(loaded.collision_scene.geometry) > 0
    # plan builds its collision model (MuJoCo, Coal) from the copied meshes.
    run(["plan", "--urdf", urdf, "--points", "2", "--out", tmp_path / "plan.csv", "--quiet"])
    assert (tmp_path / "plan.csv").is_file()


def test_a_urdf_whose_meshes_are_missing_is_refused_by_plan_in_one_line(results, tmp_path):
    run(["export", results["sequential"], "--out", tmp_path / "x"])
    shutil.rmtree(tmp_path / "x" / "meshes")
    case = Case(
        "plan-urdf-without-its-meshes",
        ["plan", "--urdf", "{tmp}/x/sda10f_calibrated.urdf", "--points", "2", "--out", "{tmp}/p.csv"],
        ("mesh",),
    )
    check_refusal(case, tmp_path)


@pytest.mark.parametrize("name", ["baxter", "ur5_pair"])
def test_robots_from_descriptions_export_self_contained(name, tmp_path):
    # Baxter's COLLADA meshes live in example-robot-data's share folder, the UR5 cell's URDF is
    # built: both folders must load on their own once copied.
    robot = load_description(name).robot
    _, T_needle = robot.tool_transform("needle_tip")
    _, T_probe = robot.tool_transform("probe_tip")
    _, T_image = robot.tool_transform("us_image")
    image = ImageCalibration("kabsch", T_image, np.array([0.19e-3, 0.19e-3]))
    write_exports(robot, Calibration(T_needle, T_probe, image), tmp_path / "x")
    copy = tmp_path / "copy"
    shutil.copytree(tmp_path / "x", copy)
    shutil.rmtree(tmp_path / "x")
    urdf = copy / f"{name}_calibrated.urdf"
    names = mesh_files(urdf)
    assert names and all(n.startswith("meshes/") and (copy / n).is_file() for n in names)
    model, collision, visual = pin.buildModelsFromUrdf(str(urdf), package_dirs=[str(copy)])
    assert model.nq == robot.model.nq and collision.ngeoms > 0 and visual.ngeoms > 0
    assert yourdfpy.URDF.load(str(urdf), load_meshes=True).num_actuated_joints == robot.model.nq
    # The copy's kinematics are the robot's (the tool frames included), to 1e-12 m.
    again = Robot.load(urdf)
    q = robot.neutral()
    for frame in ("needle_tip", "probe_tip", "us_image"):
        assert np.abs(again.fk(frame, q) - robot.fk(frame, q)).max() < 1e-12


# --- the ROS 2 package ---------------------------------------------------------------------------


def test_ros_package_is_a_description_package_with_a_launch_file(results, tmp_path):
    run(["export", results["sequential"], "--out", tmp_path / "x", "--ros-package", "sda10f_calibration"])
    package = tmp_path / "x" / "sda10f_calibration"

    xml = ET.parse(package / "package.xml").getroot()
    assert xml.tag == "package" and xml.get("format") == "3"
    for required in ("name", "version", "description", "maintainer", "license"):
        assert (xml.findtext(required) or "").strip(), required
    assert xml.findtext("name") == "sda10f_calibration"
    assert xml.find("maintainer").get("email")
    assert xml.findtext("buildtool_depend") == "ament_cmake"
    assert xml.findtext("export/build_type") == "ament_cmake"
    assert {"robot_state_publisher", "tf2_ros"} <= {e.text for e in xml.findall("exec_depend")}

    cmake = (package / "CMakeLists.txt").read_text()
    assert "project(sda10f_calibration" in cmake and "ament_package()" in cmake
    install = re.search(r"install\(DIRECTORY ([^)]*) DESTINATION share/\$\{PROJECT_NAME\}\)", cmake)
    assert install is not None and install.group(1).split() == ["urdf", "meshes", "launch", "config"]
    assert all((package / folder).is_dir() for folder in install.group(1).split())

    launch = (package / "launch" / "sda10f_calibration.launch.py").read_text()
    tree = ast.parse(launch)
    assert "generate_launch_description" in {f.name for f in tree.body if isinstance(f, ast.FunctionDef)}
    strings = {n.value for n in ast.walk(tree) if isinstance(n, ast.Constant) and isinstance(n.value, str)}
    assert {"robot_state_publisher", "static_transform_publisher", "sda10f_calibrated.urdf"} <= strings
    stored = read_result(results["sequential"])
    for parent, child in (
        ("arm_right_link_tool0", "needle_tip"),
        ("arm_left_link_tool0", "probe_tip"),
        ("probe_tip", "us_image"),
    ):
        assert f"{parent}_to_{child}" in strings and parent in strings and child in strings
    # The needle's publisher carries the result's translation, in ROS 2's named arguments.
    call = next(
        n
        for n in ast.walk(tree)
        if isinstance(n, ast.Call)
        and any(
            k.arg == "name" and k.value.value == "arm_right_link_tool0_to_needle_tip"
            for k in n.keywords
            if isinstance(k.value, ast.Constant)
        )
    )
    arguments = ast.literal_eval(next(k.value for k in call.keywords if k.arg == "arguments"))
    xyz = [float(arguments[arguments.index(f"--{a}") + 1]) for a in "xyz"]
    assert np.abs(np.array(xyz) - stored.T_ER_Ntip[:3, 3]).max() < 1e-15  # repr: exact

    urdf = package / "urdf" / "sda10f_calibrated.urdf"
    names = mesh_files(urdf)
    assert names and all(n.startswith("package://sda10f_calibration/meshes/") for n in names)
    # package:// resolved against the package's parent folder, as a ROS workspace's share does.
    _, collision, _ = pin.buildModelsFromUrdf(str(urdf), package_dirs=[str(tmp_path / "x")])
    assert collision.ngeoms == len(names) / 2
    parent = str(tmp_path / "x")
    loaded = yourdfpy.URDF.load(
        str(urdf),
        load_meshes=True,
        filename_handler=lambda fname: os.path.join(parent, yourdfpy.filename_handler_ignore_directive(fname)),
    )
    assert len(loaded.scene.geometry) > 0


# --- YAML read by PyYAML ------------------------------------------------------------------------


def test_static_transforms_yaml_reads_as_numbers_in_pyyaml(results, tmp_path):
    run(["export", results["sequential"], "--out", tmp_path / "x"])
    data = yaml.safe_load((tmp_path / "x" / "static_transforms.yaml").read_text())
    stored = read_result(results["sequential"])
    image = stored.image[stored.best_method()]
    spacing = data["us_image_spacing_m"]
    assert all(type(v) is float for v in spacing)
    assert np.abs(np.array(spacing) - image.spacing_m).max() < 1e-15  # repr round trip: exact
    expected = {
        ("arm_right_link_tool0", "needle_tip"): stored.T_ER_Ntip,
        ("arm_left_link_tool0", "probe_tip"): stored.T_EL_Ptip,
        ("probe_tip", "us_image"): image.T_Ptip_I,
    }
    assert {(t["parent"], t["child"]) for t in data["transforms"]} == set(expected)
    from scipy.spatial.transform import Rotation

    for item in data["transforms"]:
        numbers = [*item["translation"], *item["rotation"]]
        assert all(type(v) is float for v in numbers)
        T = make_transform(Rotation.from_quat(item["rotation"]).as_matrix(), item["translation"])
        # Quaternion -> matrix costs a few ulp: 1e-12 guards a transform that is really the result's.
        assert np.abs(T - expected[item["parent"], item["child"]]).max() < 1e-12
        ros2, ros1 = item["ros2"].split(), item["ros1"].split()
        assert ros2[:4] == ["ros2", "run", "tf2_ros", "static_transform_publisher"]
        assert ros2[ros2.index("--frame-id") + 1] == item["parent"]
        assert ros2[ros2.index("--child-frame-id") + 1] == item["child"]
        # ROS 1's order: x y z qx qy qz qw frame_id child_frame_id.
        assert ros1[:3] == ["rosrun", "tf2_ros", "static_transform_publisher"]
        assert [float(v) for v in ros1[3:10]] == numbers and ros1[10:] == [item["parent"], item["child"]]


def test_yaml_floats_without_a_dot_would_be_strings_to_pyyaml():
    # Why the writer forces a dot: YAML 1.1 reads 1e-05 as a string, 1.0e-05 as a float.
    from brachycal.export.formats import _yaml_text

    text = _yaml_text({"v": [1e-05, 2e20, 0.00019]}, "")
    assert yaml.safe_load(text) == {"v": [1e-05, 2e20, 0.00019]}
    assert yaml.safe_load("v: [1e-05]") == {"v": ["1e-05"]}


# --- PLUS's ImageToProbe ------------------------------------------------------------------------


def is_plus_image_to_probe(M: np.ndarray, rtol: float) -> bool:
    """PLUS's rule (vtkPlusProbeCalibrationAlgo): column 3 is x × y normalised, times the mean of
    the lengths of columns 1 and 2."""
    x, y, z = M[:3, 0], M[:3, 1], M[:3, 2]
    normal = np.cross(x, y) / np.linalg.norm(np.cross(x, y))
    expected = normal * (np.linalg.norm(x) + np.linalg.norm(y)) / 2
    return bool(np.linalg.norm(z - expected) <= rtol * np.linalg.norm(expected))


def test_image_to_probe_third_column_is_the_mean_spacing_as_plus_writes_it(results, tmp_path):
    # PLUS's own fCal results follow the rule to their printed precision (6 digits: 1e-4).
    for name in ("OPEA_OptimizationMethod_Calibration.results.xml", "OPEI_OptimizationMethod_Calibration.results.xml"):
        plus = read_coordinate_definitions(reference("plus_nwire_variants", name))
        assert is_plus_image_to_probe(plus["Image", "Probe"], rtol=1e-4)
    run(["export", results["sequential"], "--out", tmp_path / "x", "--method", "scaled_uv"])
    image = read_result(results["sequential"]).image["scaled_uv"]
    mm = image_to_probe_mm(image)
    assert is_plus_image_to_probe(mm, rtol=1e-12)  # ours exactly, up to rounding
    assert np.isclose(np.linalg.norm(mm[:3, 2]), 1e3 * image.spacing_m.mean(), rtol=1e-12)
    written = read_coordinate_definitions(tmp_path / "x" / "PlusCoordinateDefinitions.xml")["Image", "Probe"]
    assert np.abs(written - mm).max() < 1e-6  # 9 significant digits in the XML
    assert np.abs(read_itk_transform(tmp_path / "x" / "ImageToProbe.tfm") - mm).max() < 1e-9
    # A pixel (z = 0) lands where the calibration puts it: the third column moves no pixel.
    u, v = UV
    p_mm = 1e3 * (image.T_Ptip_I @ [u * image.spacing_m[0], v * image.spacing_m[1], 0.0, 1.0])[:3]
    assert np.abs((mm @ [u, v, 0.0, 1.0])[:3] - p_mm).max() < 1e-9


# --- corrections exactly once --------------------------------------------------------------------


def without_stored_origins(result: Path, out: Path) -> Path:
    """The result as files written before joint offsets were stored as corrected origins."""
    raw = json.loads(result.read_text())
    del raw["chain"]["robot_joint_origins"]
    out.write_text(json.dumps(raw))
    return out


def test_joint_offsets_are_applied_once_through_an_exported_urdf(results, tmp_path, robot):
    old = without_stored_origins(results["offsets"], tmp_path / "old.json")
    run(["export", old, "--out", tmp_path / "x"])
    urdf = tmp_path / "x" / "sda10f_calibrated.urdf"
    record = Robot.load(urdf).export_records[-1]
    stored = read_result(old)
    assert record["result_sha256"] == stored.sha256 and "joint_offsets" in record["carries"].split()
    direct = located(old, results["joints"])
    again = located(old, results["joints"], "--urdf", urdf)
    # locate prints nanometres: the same point, not the offsets applied a second time.
    assert np.abs(again - direct).max() <= 2e-9
    # What a second application would have done (0.14 mm on this robot): far above that tolerance.
    q = np.loadtxt(results["joints"], delimiter=",", skiprows=1)[1:]
    once = robot.with_joint_offsets(stored.joint_offsets_rad)
    twice = once.with_joint_offsets(stored.joint_offsets_rad)
    assert np.linalg.norm(twice.fk("arm_left_link_tool0", q)[:3, 3] - once.fk("arm_left_link_tool0", q)[:3, 3]) > 5e-5
    # Results that store the corrected origins were already safe; they stay so.
    assert np.abs(located(results["offsets"], results["joints"]) - direct).max() <= 2e-9


def test_another_results_corrected_urdf_with_offsets_only_is_refused(results, tmp_path):
    old = without_stored_origins(results["offsets"], tmp_path / "old.json")
    run(["export", old, "--out", tmp_path / "x"])
    other = tmp_path / "other.json"  # the same numbers in another file: another result (its SHA-256)
    other.write_text(json.dumps(json.loads(old.read_text()), indent=1))
    case = Case(
        "locate-offsets-on-another-results-urdf",
        ["locate", other, results["joints"], "--uv", "540,300", "--urdf", "{tmp}/x/sda10f_calibrated.urdf"],
        ("exported from another result", "old.json"),
    )
    check_refusal(case, tmp_path)


# --- one default method --------------------------------------------------------------------------


def test_locate_and_export_default_to_the_results_best_method(results, tmp_path):
    sequential = read_result(results["sequential"])
    rmse = {m: sequential.raw["loocv"][m]["rmse_mm"] for m in sequential.image}
    assert sequential.best_method() == min(rmse, key=rmse.get)
    assert read_result(results["offsets"]).best_method() == "chain"
    for result in (results["sequential"], results["offsets"]):
        stored = read_result(result)
        best = stored.best_method()
        assert np.array_equal(located(result, results["joints"]), located(result, results["joints"], "--method", best))
        run(["export", result, "--out", tmp_path / result.stem])
        assert Robot.load(tmp_path / result.stem / "sda10f_calibrated.urdf").export_records[-1]["method"] == best


def test_best_method_ties_go_to_table_ii_order_and_the_chain_comes_first(results):
    stored = read_result(results["sequential"])
    raw = json.loads(json.dumps(stored.raw))
    raw["loocv"]["horn"]["rmse_mm"] = raw["loocv"]["kabsch"]["rmse_mm"] = 0.1
    raw["loocv"]["kabsch"]["rmse_mm"] *= 1 + 1e-12  # a rounding difference: still a tie
    from dataclasses import replace

    assert replace(stored, raw=raw).best_method() == "kabsch"
    chain = ImageCalibration("chain", np.eye(4), np.array([1e-4, 1e-4]))
    assert replace(stored, image={**stored.image, "chain": chain}).best_method() == "chain"
    no_loocv = {k: v for k, v in raw.items() if k != "loocv"}
    assert replace(stored, raw=no_loocv).best_method() == "icp"  # none measured: Table II's first


def test_a_urdf_corrected_by_another_result_is_refused_unless_calibrated_on(results, tmp_path):
    # The whole chain's result corrected the robot; the sequential result was calibrated on the
    # plain URDF: its tools on the corrected robot would be a mix.
    run(["export", results["offsets"], "--out", tmp_path / "x"])
    urdf = tmp_path / "x" / "sda10f_calibrated.urdf"
    case = Case(
        "locate-uncorrected-result-on-a-corrected-urdf",
        ["locate", results["sequential"], results["joints"], "--uv", "540,300", "--urdf", urdf],
        ("exported from another result", "offsets.json", "not calibrated with those corrections"),
    )
    check_refusal(case, tmp_path / "x")
    # A result calibrated on that very URDF is its own: nothing to refuse, nothing applied.
    on_it = tmp_path / "on_it.json"
    run(["calibrate", TWIN, "--urdf", urdf, "--out", on_it, "--quiet"])
    stored = read_result(on_it)
    assert stored.software_robot(Robot.load(urdf)).urdf_xml == Robot.load(urdf).urdf_xml
