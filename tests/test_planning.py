"""Planning the 4×4×4 sample poses: every pose checked again here, ordering, refusals, files."""

from __future__ import annotations

import csv

import mujoco
import numpy as np
import pytest
from conftest import random_configurations

from brachycal.calibration import read_result
from brachycal.cli.main import main
from brachycal.model.collision import ClearanceChecker, collision_link_pairs
from brachycal.model.names import CONTROLLER_JOINT_NAMES
from brachycal.planning import PlanSpec, RectFOV, SectorFOV, plan_poses
from brachycal.planning import order as ordering
from brachycal.se3 import inverse, transform_points


@pytest.fixture(scope="module")
def plan(robot):
    return plan_poses(robot, PlanSpec())


def test_default_plan_has_all_64_poses_and_each_passes_every_check(plan, robot):
    spec = plan.spec
    assert len(plan.poses) == 64 and not plan.infeasible
    checker = ClearanceChecker(robot, collision_link_pairs(robot))
    d = spec.insertion_dir / np.linalg.norm(spec.insertion_dir)
    for pose in plan.poses:
        # Recomputed here from Pinocchio's own FK, not from the plan's stored figures.
        T_needle = robot.fk("needle_tip", pose.q)
        T_image = robot.fk("us_image", pose.q)
        assert np.linalg.norm(T_needle[:3, 3] - pose.point.p_base) < 1e-5  # 0.01 mm
        assert np.degrees(np.arccos(min(1.0, T_needle[:3, 2] @ d))) < 0.05
        p_image = transform_points(inverse(T_image), T_needle[:3, 3])
        assert abs(p_image[2]) < 1e-5
        uv = p_image[:2] / spec.spacing_m
        assert np.abs(uv - pose.point.uv_px).max() < 0.1
        assert spec.fov.margin_to_edge(uv, spec.spacing_m)[0] > 0
        assert robot.within_limits(pose.q, margin=0.05)
        assert checker.distances(pose.q).min() >= 0.010


def test_grid_is_the_papers_cube_and_fills_a_square_of_the_image(plan):
    points = np.array([pose.point.p_base for pose in plan.poses])
    assert np.allclose(points.max(axis=0) - points.min(axis=0), [0.04, 0.04, 0.04])
    uv = np.array([pose.point.uv_px for pose in plan.poses])
    assert len(np.unique(np.round(uv, 6), axis=0)) == 16  # four layers share the 4 x 4 pixels
    assert np.allclose(uv.max(axis=0) - uv.min(axis=0), 0.04 / 0.19e-3)


def test_ordering_is_no_slower_than_serpentine_or_raster(plan):
    m = plan.motion_time_s
    assert m["optimised"] <= m["serpentine"] + 1e-9 and m["optimised"] < m["raster"]
    assert 0 < m["optimised"] < 60


def test_mujoco_and_coal_agree_on_link_clearances(robot):
    # The planner (MuJoCo) and the verifier (Coal) compute hull distances with independent code.
    pairs = collision_link_pairs(robot)
    checker = ClearanceChecker(robot, pairs)
    model = robot.mujoco_model()
    data = mujoco.MjData(model)
    geom = {model.body(model.geom_bodyid[g]).name: g for g in range(model.ngeom)}
    fromto = np.zeros(6)
    for q in random_configurations(robot, 20, seed=40):
        data.qpos[:] = q
        mujoco.mj_kinematics(model, data)
        coal = checker.distances(q)
        for (a, b), d in zip(pairs, coal, strict=True):
            if d > 0.0 and d < 0.2:
                d_mj = mujoco.mj_geomDistance(model, data, geom[a], geom[b], 0.3, fromto)
                assert abs(d_mj - d) < 1e-4, (a, b, d, d_mj)


def test_order_helpers():
    index = np.array([(i, j, k) for k in range(3) for j in range(3) for i in range(3)])
    snake = ordering.serpentine(index)
    steps = np.abs(np.diff(index[snake], axis=0)).sum(axis=1)
    assert sorted(snake) == list(range(27)) and steps.max() == 1  # every move is to a neighbour
    rng = np.random.default_rng(0)
    Q = rng.uniform(-1, 1, size=(12, 3))
    times = ordering.move_times(Q, np.ones(3))
    path = ordering.nearest_neighbour_two_opt(times, start=0)
    assert sorted(path) == list(range(1, 12))
    assert ordering.path_time(path, times, start=0) <= ordering.path_time(np.arange(1, 12), times, start=0)


def test_fields_of_view():
    sector = SectorFOV(apex_px=(540.0, 0.0), radius_m=0.070, angle_rad=np.radians(120))
    s = np.array([0.19e-3, 0.19e-3])
    assert np.isclose(sector.margin_to_edge([540, 300], s)[0], 0.070 - 300 * 0.19e-3)
    assert sector.margin_to_edge([540, 400], s)[0] < 0  # beyond 70 mm
    assert sector.margin_to_edge([900, 20], s)[0] < 0  # outside the 120 degree opening
    rect = RectFOV((0, 1079), (0, 719))
    assert np.isclose(rect.margin_to_edge([10, 300], s)[0], 10 * 0.19e-3)


def test_points_outside_the_field_of_view_are_reported_not_dropped(robot):
    plan = plan_poses(robot, PlanSpec(points_per_axis=2, centre_px=(540.0, 330.0)))  # deep rows beyond 70 mm
    assert len(plan.poses) + len(plan.infeasible) == 8
    assert plan.infeasible and all(item.reasons == ("fov",) for item in plan.infeasible)


def test_cli_writes_plan_in_controller_order_with_pixels_and_figure(tmp_path, robot, capsys):
    out = tmp_path / "plan.csv"
    assert main(["plan", "--out", str(out), "--points", "3", "--quiet"]) == 0
    text = capsys.readouterr().out
    assert "planned 27 of 27 poses" in text and "raster" in text
    rows = list(csv.DictReader(out.open()))
    assert len(rows) == 27
    header = list(rows[0])
    assert header[12:27] == list(CONTROLLER_JOINT_NAMES)
    assert header[27:] == [f"{n}_deg" for n in CONTROLLER_JOINT_NAMES]
    for row in rows[:5]:
        q = robot.configuration({n: float(row[n]) for n in CONTROLLER_JOINT_NAMES})
        assert np.isclose(
            float(row["arm_right_joint_3_e_deg"]), np.degrees(float(row["arm_right_joint_3_e"])), atol=1e-4
        )
        T_image = robot.fk("us_image", q)
        tip = robot.fk("needle_tip", q)[:3, 3]
        uv = transform_points(inverse(T_image), tip)[:2] / 0.19e-3
        assert np.abs(uv - [float(row["u_px"]), float(row["v_px"])]).max() < 0.01
        assert np.abs(tip - [float(row[c]) for c in "xyz"]).max() < 1e-5
    assert (tmp_path / "plan.png").stat().st_size > 10_000


def test_unreachable_cube_is_refused_with_a_report(tmp_path, capsys):
    out = tmp_path / "plan.csv"
    code = main(["plan", "--out", str(out), "--points", "2", "--centre-mm", "2500,0,1000", "--quiet"])
    assert code == 2
    captured = capsys.readouterr()
    assert "infeasible g000" in captured.out and "reach" in captured.out
    assert captured.err.count("\n") == 1 and "8 of 8 grid points have no verified pose (reach: 8)" in captured.err
    assert list(tmp_path.iterdir()) == []


def test_partial_plans_list_the_infeasible_points(tmp_path, capsys):
    out = tmp_path / "plan.csv"
    args = ["plan", "--out", str(out), "--points", "2", "--centre-px", "540,330", "--allow-partial", "--quiet"]
    assert main(args) == 0
    rows = list(csv.DictReader((tmp_path / "plan_infeasible.csv").open()))
    assert rows and all(row["reasons"] == "fov" for row in rows)
    assert len(rows) + len(list(csv.DictReader(out.open()))) == 8


def test_plan_with_a_calibration_result(tmp_path, capsys):
    from conftest import ROOT

    result = tmp_path / "r.json"
    assert main(["calibrate", str(ROOT / "examples" / "session_exact"), "--out", str(result)]) == 0
    out = tmp_path / "plan.csv"
    assert main(["plan", "--out", str(out), "--points", "2", "--result", str(result), "--quiet"]) == 0
    printed = capsys.readouterr().out
    assert "planned 8 of 8 poses" in printed
    best = read_result(result).best_method()
    assert f"planning with method: {best} (the result's best: " in printed


def test_a_point_whose_qp_fails_is_listed_as_solver_and_the_plan_is_refused(tmp_path, robot, monkeypatch, capsys):
    # A start 1 rad past the left shoulder's limit makes every point's first QP infeasible (a real
    # daqp failure): each point is listed with the reason "solver" and the solver's one-line
    # message, the plan is refused with one line on stderr, and nothing is written.
    from brachycal.model.rig import Rig

    k = robot.joint_names.index("arm_left_joint_1_s")
    start = robot.rig.ready  # planning starts from the rig's ready stance
    start[k] = robot.upper[k] + 1.0
    monkeypatch.setattr(Rig, "ready", property(lambda rig: start.copy()))
    out = tmp_path / "plan.csv"
    assert main(["plan", "--out", str(out), "--points", "2", "--quiet"]) == 2
    captured = capsys.readouterr()
    assert captured.out.count(": solver — dual-arm IK: the QP solver daqp found no joint velocity") == 8
    assert "outside its limits: arm_left_joint_1_s" in captured.out
    assert captured.err.count("\n") == 1 and "8 of 8 grid points have no verified pose (solver: 8)" in captured.err
    assert list(tmp_path.iterdir()) == []
