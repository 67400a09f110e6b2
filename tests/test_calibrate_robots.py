"""Calibration on every bundled robot: the SDA10F, Baxter and the two-UR5 cell.

On each robot, a noise-free session built from that robot's own kinematics with known tools
(:func:`~brachycal.simulation.exact_session`: the configurations are where the robot's forward
kinematics puts the true tools, the pixels are the true ones) must give back the truth through the
command line — ``calibrate`` (sequential and ``--solve chain``), ``locate`` and ``export`` with
``--robot NAME`` — and a result or a session of one robot must be refused on another. The UR5
cell has 6-axis arms and no shared joint (no torso): nothing may assume 7 axes or a torso.

Tolerance of the exact recoveries: 1e-9 (metres for translations, unitless for rotation entries).
Exact data leave only floating-point rounding through the forward kinematics and the solvers:
measured at most 1e-11 on the three robots (the UR5 cell's, the largest), so 1e-9 fails on any
modelling mistake (a wrong flange or arm moves an estimate by millimetres) and never on rounding.
"""

from __future__ import annotations

import json
from collections.abc import Callable
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np
import pytest
from hostile import Case, check_refusal, run_cli

from brachycal.calibration import METHODS, RobotRecord, calibrate, identify_robot, read_result
from brachycal.calibration.chain import DEFAULT_ROBOT_ACCURACY
from brachycal.calibration.chain.uncertainty import landing_robot_jacobians
from brachycal.data.session import Session, read_session, write_session
from brachycal.errors import BrachycalWarning, InputError
from brachycal.export import export_files, flange_labels, read_ros_static_transforms
from brachycal.model import NEEDLE_TIP, Robot
from brachycal.model.description import BUNDLED_ROBOTS, load_description
from brachycal.simulation import SessionTruth, default_truth, exact_session

#: Exact recoveries (module docstring).
EXACT = 1e-9
#: ``locate`` prints metres with 9 decimals: rounding of ±5e-10 m on top of the exact estimate.
PRINTED = 1e-9 + 5e-10


@dataclass(frozen=True)
class Calibrated:
    """One robot's exact session, its truth, and the result files of both methods."""

    name: str
    robot: Robot
    truth: SessionTruth
    session: Session
    folder: Path
    sequential: Path
    chain: Path


@pytest.fixture(scope="module")
def calibrated(tmp_path_factory) -> Callable[[str], Calibrated]:
    """``calibrated(name)``: the robot's exact session calibrated by both methods (built once per robot)."""
    done: dict[str, Calibrated] = {}

    def get(name: str) -> Calibrated:
        if name not in done:
            robot = load_description(name).robot
            truth = default_truth(robot)
            session = exact_session(robot, truth)
            where = tmp_path_factory.mktemp(name)
            folder = write_session(session, where / "session")
            paths = {}
            for method in ("sequential", "chain"):
                paths[method] = where / f"{method}.json"
                argv = ["calibrate", str(folder), "--robot", name, "--method", method, "--out", str(paths[method])]
                outcome = run_cli([*argv, "--quiet"])
                assert outcome.code == 0, outcome.err
            done[name] = Calibrated(name, robot, truth, session, folder, paths["sequential"], paths["chain"])
        return done[name]

    return get


@pytest.mark.parametrize("name", BUNDLED_ROBOTS)
def test_both_methods_recover_the_tools_and_the_image_on_every_robot(calibrated, name):
    c = calibrated(name)
    truth = c.truth
    sequential, chain = read_result(c.sequential), read_result(c.chain)
    for stored in (sequential, chain):
        assert np.abs(stored.T_ER_Ntip - truth.T_ER_Ntip).max() < EXACT
        assert np.abs(stored.T_EL_Ptip - truth.T_EL_Ptip).max() < EXACT
        for image in stored.image.values():
            assert np.abs(image.T_Ptip_I - truth.T_Ptip_I).max() < EXACT, image.method
            assert np.abs(image.spacing_m - truth.spacing_m).max() < 1e-15  # the true spacing is the nominal one
    assert set(sequential.image) == set(METHODS) and set(chain.image) == {"chain"}
    tips = sequential.raw["reference_tips_m"]
    assert np.abs(np.array(tips["rtip1"]) - truth.p_R_Rtip1).max() < EXACT
    assert np.abs(np.array(tips["rtip2"]) - truth.p_R_Rtip2).max() < EXACT
    # Each result says which robot it was calibrated with.
    for stored in (sequential, chain):
        assert stored.robot == RobotRecord.of(c.robot)
        assert stored.robot.name == name and stored.robot.joint_names == c.robot.joint_names


def test_the_ur5_cell_has_six_axis_arms_and_no_shared_joint(calibrated):
    rig = calibrated("ur5_pair").robot.rig
    assert len(rig.needle_arm_indices) == len(rig.probe_arm_indices) == 6
    assert rig.shared_joints == () and rig.nq == 12


@pytest.mark.parametrize("name", BUNDLED_ROBOTS)
def test_locate_puts_a_samples_pixel_on_its_needle_tip(calibrated, name, tmp_path):
    c = calibrated(name)
    k = 5  # any sample: its pixel shows the needle tip at its configuration
    q, (u, v) = c.session.samples_q[k], c.session.uv_px[k].tolist()
    joints = tmp_path / "joints.csv"
    joints.write_text(",".join(c.robot.joint_names) + "\n" + ",".join(repr(float(x)) for x in q) + "\n")
    tip = c.truth.robot(c.robot).fk(NEEDLE_TIP, q)[:3, 3]
    for result, method in ((c.sequential, "kabsch"), (c.chain, "chain")):
        argv = ["locate", str(result), str(joints), "--uv", f"{u!r},{v!r}", "--robot", name, "--method", method]
        outcome = run_cli(argv)
        assert outcome.code == 0, outcome.err
        row = outcome.out.splitlines()[1].split(",")
        assert np.abs(np.array(row[1:], dtype=float) - tip).max() < PRINTED, method


@pytest.mark.parametrize("name", BUNDLED_ROBOTS)
def test_export_writes_the_robots_files_and_frames(calibrated, name, tmp_path):
    c = calibrated(name)
    rig = c.robot.rig
    out = tmp_path / "exports"
    outcome = run_cli(["export", str(c.chain), "--robot", name, "--out", str(out)])
    assert outcome.code == 0, outcome.err
    files = export_files(rig)
    assert sorted(p.name for p in out.iterdir()) == sorted([*files, "meshes"])  # the URDF's meshes beside it
    assert files[0] == f"{name}_calibrated.urdf"
    assert files[2:4] == ("ProbeToLeftFlange.tfm", "NeedleTipToRightFlange.tfm")  # each bundled flange names its side
    # The calibrated URDF is the robot's, with the true tools: its needle tip is where the physical one is.
    urdf = Robot.load(out / files[0])
    assert urdf.joint_names == c.robot.joint_names
    q = c.session.samples_q[:4]
    assert np.abs(urdf.fk(NEEDLE_TIP, q) - c.truth.robot(c.robot).fk(NEEDLE_TIP, q)).max() < EXACT
    # ROS: the tools hang on the robot's own flange links.
    ros = read_ros_static_transforms((out / "static_transforms.yaml").read_text())
    assert set(ros) == {(rig.needle_flange, "needle_tip"), (rig.probe_flange, "probe_tip"), ("probe_tip", "us_image")}
    assert np.abs(ros[rig.needle_flange, "needle_tip"] - c.truth.T_ER_Ntip).max() < EXACT


def test_flanges_that_do_not_name_a_side_are_named_by_their_tool():
    rig = load_description("ur5_pair").rig
    assert flange_labels(rig) == ("RightFlange", "LeftFlange")
    unnamed = replace(rig, needle_arm=replace(rig.needle_arm, flange="arm_a_tool0"))
    assert flange_labels(unnamed) == ("NeedleFlange", "ProbeFlange")
    both_left = replace(rig, needle_arm=replace(rig.needle_arm, flange="left_tool1"))
    assert flange_labels(both_left) == ("NeedleFlange", "ProbeFlange")
    assert export_files(unnamed)[2:4] == ("ProbeToProbeFlange.tfm", "NeedleTipToNeedleFlange.tfm")


@pytest.mark.slow
def test_the_ur5_cell_identifies_its_robot_and_reads_only_the_probe_arm_when_aiming(calibrated):
    c = calibrated("ur5_pair")
    rig = c.robot.rig
    initial = calibrate(c.session, c.robot, ("kabsch",))
    use = np.arange(len(c.session.uv_px)) % 2 == 0  # half the samples: enough for exact data, half the time
    identified = identify_robot(c.session, c.robot, initial, "rigid", DEFAULT_ROBOT_ACCURACY, samples=use)
    # Exact data on the nominal robot: nothing to correct (to rounding), the tools exact.
    assert identified.corrections.shape == (12, 6)
    assert np.abs(identified.corrections).max() < EXACT
    assert np.abs(identified.fit.T_ER_Ntip - c.truth.T_ER_Ntip).max() < EXACT
    assert identified.identifiability.posterior_ratio.shape == (12, 6)
    assert all(key.rsplit(".", 1)[0] in c.robot.joint_names for key in identified.identifiability.reasons)
    # When aiming, the needle arm's joints are commanded and the probe arm's read: only the latter's
    # reading errors move the target (the UR5 cell's needle arm is joints 6..11, not the SDA10F's 8..14).
    _, L_q = landing_robot_jacobians(
        identified.fit, c.robot, c.session.spacing_m, c.session.samples_q[:3], c.session.uv_px[:3]
    )
    assert np.all(L_q[:, :, rig.needle_arm_indices] == 0.0)
    assert np.all(np.abs(L_q[:, :, rig.probe_arm_indices]).max(axis=(0, 1)) > 0.0)


# --- another robot's result or session ----------------------------------------------------------
LOCATE = ["locate", "{result}", "{joints}", "--uv", "540,300"]
REFUSALS = [
    Case("locate-on-the-default-robot", LOCATE, ("{result}", "robot.name", "'ur5_pair'", "--robot ur5_pair")),
    Case("locate-on-baxter", [*LOCATE, "--robot", "baxter"], ("calibrated on robot 'ur5_pair', not 'baxter'",)),
    Case(
        "export-on-the-sda10f",
        ["export", "{result}", "--robot", "sda10f", "--out", "{tmp}/x"],
        ("calibrated on robot 'ur5_pair', not 'sda10f'", "--robot ur5_pair"),
    ),
    Case(
        "calibrate-a-ur5-session-on-the-sda10f",
        ["calibrate", "{session}", "--out", "{tmp}/r.json", "--quiet"],
        ("touches.csv", "not those of robot 'sda10f'", "missing torso_joint_b1", "left_shoulder_pan_joint"),
    ),
    Case(
        "calibrate-a-ur5-session-on-baxter",
        ["calibrate", "{session}", "--robot", "baxter", "--solve", "chain", "--out", "{tmp}/r.json", "--quiet"],
        ("touches.csv", "'baxter'", "missing left_s0", "(14 of 14)", "left_shoulder_pan_joint"),
    ),
]


@pytest.mark.parametrize("case", REFUSALS, ids=lambda c: c.id)
def test_another_robots_result_or_session_is_refused(case, calibrated, tmp_path):
    c = calibrated("ur5_pair")
    joints = c.folder / "samples.csv"  # its joint columns are the UR5 cell's
    expect = tuple(word.format(result=c.sequential) for word in case.expect)
    check_refusal(replace(case, expect=expect), tmp_path, result=c.sequential, joints=joints, session=c.folder)


def test_a_result_from_before_robot_descriptions_is_read_without_a_robot_check(calibrated, tmp_path):
    c = calibrated("sda10f")
    raw = json.loads(c.sequential.read_text())
    del raw["robot"]
    old = tmp_path / "old.json"
    old.write_text(json.dumps(raw))
    stored = read_result(old)
    assert stored.robot is None
    assert stored.software_robot(c.robot) is c.robot  # no corrections, nothing checked


def test_a_changed_description_warns_and_a_robot_of_other_joints_or_a_bad_record_is_refused(calibrated, tmp_path):
    c = calibrated("sda10f")
    raw = json.loads(c.sequential.read_text())
    path = tmp_path / "edited.json"

    def stored_with(**robot: object):
        path.write_text(json.dumps({**raw, "robot": {**raw["robot"], **robot}}))
        return read_result(path)

    with pytest.warns(BrachycalWarning, match="has changed since"):
        stored_with(description_sha256="0" * 64).check_robot(c.robot)
    with pytest.raises(InputError, match=r"other joints .*\(it has no arm_right_joint_7_x\): pass --robot sda10f"):
        stored_with(joint_names=[*c.robot.joint_names[:-1], "arm_right_joint_7_x"]).check_robot(c.robot)
    with pytest.raises(InputError, match=r"column 'robot.name': must be a non-empty string"):
        stored_with(name=3)
    with pytest.raises(InputError, match=r"column 'robot.joint_names'"):
        stored_with(joint_names="torso_joint_b1")


def test_session_build_turns_a_ur5_cell_recording_into_its_session(calibrated, tmp_path):
    """A recording of the UR5 cell's exact session (each pose held still for 2 s at 100 Hz, marked
    and imaged in its middle) builds back into that session with --robot ur5_pair, and is refused
    without it (its joint columns are not the SDA10F's)."""
    c = calibrated("ur5_pair")
    s = c.session
    poses, marks, images = [], [], []
    for (tool, reference), touches in s.touches.items():  # trials in order: their numbers follow the time
        for q in touches.q:
            marks.append((2 * len(poses) + 1, "touch", tool, reference))
            poses.append(q)
    for tool, points in s.axes.items():
        for point, q in points.items():
            marks.append((2 * len(poses) + 1, "axes", tool, point))
            poses.append(q)
    for sample, q, (u, v) in zip(s.sample_ids, s.samples_q, s.uv_px, strict=True):
        images.append((2 * len(poses) + 1, u, v, sample))
        poses.append(q)
    time = np.arange(200 * len(poses)) / 100.0
    log = np.column_stack([time, np.array(poses)[np.arange(len(time)) // 200]])
    np.savetxt(tmp_path / "log.csv", log, delimiter=",", header="time," + ",".join(c.robot.joint_names), comments="")
    (tmp_path / "marks.csv").write_text("time,kind,tool,name\n" + "".join(f"{t},{k},{o},{n}\n" for t, k, o, n in marks))
    rows = "".join(f"{t},{float(u)!r},{float(v)!r},{n}\n" for t, u, v, n in images)
    (tmp_path / "images.csv").write_text("time,u_px,v_px,sample\n" + rows)
    argv = ["session", "build", str(tmp_path / "log.csv"), "--marks", str(tmp_path / "marks.csv")]
    argv += ["--images", str(tmp_path / "images.csv"), "--out", str(tmp_path / "built")]
    spacing, tip = (",".join(repr(float(x)) for x in values) for values in (s.spacing_m * 1e3, s.p_ER_Mtip * 1e3))
    argv += ["--spacing-mm", spacing, "--size-px", f"{s.size_px[0]},{s.size_px[1]}", "--top-model-tip-mm", tip]
    refused = run_cli(argv)
    assert refused.code == 2 and "missing joint(s) torso_joint_b1" in refused.err
    assert not (tmp_path / "built").exists()
    outcome = run_cli([*argv, "--robot", "ur5_pair"])
    assert outcome.code == 0, outcome.err
    built = read_session(tmp_path / "built", c.robot)
    # The still window's mean of identical readings, written and read back with every digit:
    # the configurations to rounding (1e-12 rad, far below the 1e-5 rad of an encoder count).
    for key, touches in s.touches.items():
        assert np.array_equal(built.touches[key].trials, touches.trials)
        assert np.abs(built.touches[key].q - touches.q).max() < 1e-12
    assert all(np.abs(built.axes[t][p] - q).max() < 1e-12 for t, points in s.axes.items() for p, q in points.items())
    assert built.sample_ids == s.sample_ids and np.array_equal(built.uv_px, s.uv_px)
    assert np.abs(built.samples_q - s.samples_q).max() < 1e-12
