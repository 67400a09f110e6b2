"""Robot identification from touches of fixed points: the arm core and the touch protocol.

Exact touches of a corrected Panda (example-robot-data's URDF) identify it to the last nanometre;
the analytic Jacobians agree with differences; MUKCa's real Panda touches (outside data) are
predicted at places the calibration never saw far better than by the nominal URDF.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from conftest import reference

from brachycal.calibration.robot.arm_fit import ParameterSelection, flange_points
from brachycal.calibration.robot.identification import corrected_robot, prior_sd
from brachycal.calibration.robot.touches import (
    TouchModel,
    TouchPlace,
    configurations,
    evidence_prior,
    identify_touch_folders,
    identify_touches,
    read_places,
    touch_scatter,
)
from brachycal.calibration.robot_accuracy import RobotAccuracy
from brachycal.data.formats.touches import read_touch_folder
from brachycal.errors import InputError
from brachycal.model.description_file import example_robot_data_share
from brachycal.model.robot import Robot

FLANGE = "panda_link8"
TIP = np.array([0.4e-3, -0.3e-3, 0.1354])  # a ball ~13.5 cm out on the flange


@pytest.fixture(scope="module")
def panda() -> Robot:
    return Robot.load(example_robot_data_share() / "robots" / "panda_description" / "urdf" / "panda.urdf")


def position_jacobian(robot: Robot, Q: np.ndarray, tip: np.ndarray) -> np.ndarray:
    """``(N, 3, nq)`` ∂p/∂q of the tip: each joint's turn is the origin's rotation about its axis."""
    J_c = flange_points(robot, Q, FLANGE, tip).J_c
    out = np.zeros((len(Q), 3, robot.nq))
    for j, name in enumerate(robot.joint_names):
        if robot.joint_kinds[name] == "revolute":
            out[:, :, j] = J_c[:, :, 6 * j + 3 : 6 * j + 6] @ robot.joint_axis(name)
    return out


def touches_of(robot: Robot, point: np.ndarray, tip: np.ndarray, n: int, rng: np.random.Generator) -> np.ndarray:
    """``(n, nq)`` configurations putting ``tip`` exactly at ``point`` (least-norm Newton from
    random postures near a reaching one)."""
    start = np.array([0.0, 0.3, 0.0, -2.0, 0.0, 2.3, 0.8, 0.0])
    out = []
    while len(out) < n:
        q = start + rng.normal(0, 0.35, robot.nq) * (np.arange(robot.nq) < 7)
        for _ in range(60):
            p = flange_points(robot, q[None], FLANGE, tip).p[0]
            J = position_jacobian(robot, q[None], tip)[0]
            q = q - np.linalg.pinv(J) @ (p - point)
            if np.linalg.norm(p - point) < 1e-14:
                break
        if np.linalg.norm(flange_points(robot, q[None], FLANGE, tip).p[0] - point) < 1e-13 and robot.within_limits(q):
            out.append(q)
    return np.array(out)


def synthetic_places(true: Robot, rng: np.random.Generator) -> list[TouchPlace]:
    centres = ([0.45, -0.2, 0.15], [0.5, 0.25, 0.3], [0.35, 0.0, 0.45])
    places = []
    for k, c in enumerate(centres):
        points = (np.array(c), np.array(c) + np.array([0.05, 0.0, 0.0]))
        places.append(TouchPlace(f"p{k}", tuple(touches_of(true, p, TIP, 12, rng) for p in points), {(0, 1): 0.05}))
    return places


def noisy_places(true: Robot, rng: np.random.Generator, sd: float) -> list[TouchPlace]:
    """:func:`synthetic_places` with ``sd`` (metres) of touch noise (:func:`with_touch_noise`)."""
    return with_touch_noise(true, synthetic_places(true, rng), rng, sd)


def with_touch_noise(true: Robot, exact: list[TouchPlace], rng: np.random.Generator, sd: float) -> list[TouchPlace]:
    """The touches with ``sd`` (metres) of noise per coordinate at the tip (isotropic), put into the
    joints through the tip Jacobian's pseudo-inverse on ``true``."""
    places = []
    for place in exact:
        touches = []
        for Q in place.touches:
            J = position_jacobian(true, Q, TIP)
            touches.append(Q + np.einsum("nij,nj->ni", np.linalg.pinv(J), rng.normal(0, sd, (len(Q), 3))))
        places.append(TouchPlace(place.name, tuple(touches), place.distances))
    return places


def test_point_jacobian_matches_central_differences(panda):
    rng = np.random.default_rng(3)
    Q = rng.uniform(panda.lower, panda.upper, (4, panda.nq))
    c = rng.normal(0, 1e-3, (panda.nq, 6))
    robot = corrected_robot(panda, c)
    J = flange_points(robot, Q, FLANGE, TIP).J_c
    step = 1e-6
    for k in rng.choice(6 * 7, 10, replace=False):
        plus, minus = c.copy(), c.copy()
        plus.flat[k] += step
        minus.flat[k] -= step
        # the correction composes on the right: differences about c, the Jacobian about the
        # corrected robot's origin (the same to first order in |c| ~ 1e-3: compare at that level)
        diff = (
            flange_points(corrected_robot(panda, plus), Q, FLANGE, TIP).p
            - flange_points(corrected_robot(panda, minus), Q, FLANGE, TIP).p
        ) / (2 * step)
        assert np.allclose(J[:, :, k], diff, atol=5e-3 * np.abs(J).max()), k


def test_point_jacobian_at_zero_matches_differences_exactly(panda):
    rng = np.random.default_rng(4)
    Q = rng.uniform(panda.lower, panda.upper, (3, panda.nq))
    J = flange_points(panda, Q, FLANGE, TIP).J_c
    step = 1e-6
    for k in range(6 * 7):
        c = np.zeros(6 * panda.nq)
        c[k] = step
        plus = flange_points(corrected_robot(panda, c.reshape(-1, 6)), Q, FLANGE, TIP).p
        minus = flange_points(corrected_robot(panda, -c.reshape(-1, 6)), Q, FLANGE, TIP).p
        assert np.allclose(J[:, :, k], (plus - minus) / (2 * step), atol=1e-8), k


def test_touch_model_jacobian_matches_differences(panda):
    rng = np.random.default_rng(5)
    Q = [rng.uniform(panda.lower, panda.upper, (3, panda.nq)) for _ in range(2)]
    moments = tuple(rng.normal(0, 20, (3, panda.nq, 3)) for _ in range(2))
    model = TouchModel((TouchPlace("a", tuple(Q), {(0, 1): 0.05}, moments),), FLANGE, compliant=((1, 2), (3, 0)))
    y = np.concatenate([TIP, [0.4, 0.1, 0.3], [0.45, 0.1, 0.3], [2e-5, -3e-5]])
    evaluation = model.evaluate(panda, y)
    for k in range(len(y)):
        h = 1e-9 if k >= len(y) - 2 else 1e-6
        plus, minus = y.copy(), y.copy()
        plus[k] += h
        minus[k] -= h
        diff = (model.evaluate(panda, plus).r - model.evaluate(panda, minus).r) / (2 * h)
        assert np.allclose(evaluation.J_y[:, k], diff, atol=1e-7 * max(1.0, np.abs(diff).max())), k


def test_exact_touches_identify_the_arm_to_nanometres(panda):
    rng = np.random.default_rng(0)
    # The truth: corrections on the combinations touches can see (the base set at the nominal).
    probe = synthetic_places(panda, rng)
    evaluation = TouchModel(tuple(probe), FLANGE).evaluate(
        panda, np.concatenate([TIP, *[q for p in probe for q in _means(panda, p)]])
    )
    base = ParameterSelection.chain(panda, FLANGE).base_set(evaluation.J_c, evaluation.J_y, np.ones(6 * panda.nq))
    assert 0 < base.size < 42  # the first joint's origin (points absorb it) and the tip's share are not seen
    truth = base.expand(rng.normal(0, 1, base.size) * np.where(base.index % 6 < 3, 1e-3, 2e-3))
    true_robot = corrected_robot(panda, truth)
    places = synthetic_places(true_robot, rng)
    result = identify_touches(  # no prior: a prior shrinks the weakly seen combinations (MAP, not the truth)
        panda,
        places,
        FLANGE,
        None,
        tip=[0, 0, 0.13],
        selection=base,
        touch_sd_m=1e-6,
        distance_sd_m=1e-6,
        estimate_touch_noise=False,
    )
    assert np.allclose(result.tip, TIP, atol=1e-9)
    assert np.allclose(result.fit.corrections, truth, atol=1e-8)
    Q = rng.uniform(panda.lower, panda.upper, (50, panda.nq))
    identified = flange_points(result.robot(panda), Q, FLANGE, result.tip).p
    assert np.max(np.linalg.norm(identified - flange_points(true_robot, Q, FLANGE, TIP).p, axis=1)) < 1e-9
    for place, points in zip(places, result.points, strict=True):
        scatter = touch_scatter(result.robot(panda), place, FLANGE, result.tip)
        assert scatter.mean_scatter_m < 1e-10
        assert np.allclose(points[1] - points[0], [0.05, 0, 0], atol=1e-9)


def _means(robot: Robot, place: TouchPlace) -> list[np.ndarray]:
    return [flange_points(robot, Q, FLANGE, TIP).p.mean(axis=0) for Q in place.touches]


def test_noise_level_and_tip_sd_are_the_truths(panda):
    """Noisy touches: the estimated noise level is the drawn one and the stated tip SD covers its
    error (z-scores over repeated draws have unit spread)."""
    rng = np.random.default_rng(1)
    places = synthetic_places(panda, rng)
    sd = 1e-4
    z, levels = [], []
    for seed in range(5):
        noise = np.random.default_rng(100 + seed)
        # noise on the joint readings that moves the tip by ~sd
        noisy = []
        for place in places:
            touches = []
            for Q in place.touches:
                J = position_jacobian(panda, Q, TIP)
                dq = np.einsum("nij,nj->ni", np.linalg.pinv(J), noise.normal(0, sd, (len(Q), 3)))
                touches.append(Q + dq)
            noisy.append(TouchPlace(place.name, tuple(touches), place.distances))
        result = identify_touches(
            panda, noisy, FLANGE, RobotAccuracy(1e-3, float(np.radians(0.1))), tip=[0, 0, 0.13], selection="chain"
        )
        levels.append(result.fit.sigma["touch"])
        tip_sd = np.sqrt(np.diag(result.fit.y_covariance())[:3])
        z.extend((result.tip - TIP) / tip_sd)
    assert np.mean(levels) == pytest.approx(sd, rel=0.15)
    assert 0.5 < np.std(z) < 1.6


# --- the touch folders' reader ------------------------------------------------------------------

JOINTS = tuple(f"panda_joint{k}" for k in range(1, 8))


def write_place(folder: Path, tables: dict[str, str]) -> Path:
    folder.mkdir(parents=True, exist_ok=True)
    for name, text in tables.items():
        (folder / name).write_text(text)
    return folder


ROW = "0.1,0.2,0.3,-2.0,0.1,2.2,0.7\n"


def test_reader_reads_points_in_order_and_ignores_other_files(tmp_path):
    folder = write_place(
        tmp_path / "front",
        {"hole_1.csv": ROW * 3, "hole_0.csv": ROW * 2, "hole_0_pose.csv": "x\n", "comments.txt": "hi"},
    )
    read = read_touch_folder(folder, JOINTS)
    assert read.name == "front" and [t.shape for t in read.tables] == [(2, 7), (3, 7)]


@pytest.mark.parametrize(
    ("tables", "words"),
    [
        ({}, ["no touch table"]),
        ({"hole_1.csv": ROW * 2}, ["hole_0.csv is missing"]),
        ({"hole_0.csv": ROW * 2, "hole_2.csv": ROW * 2}, ["hole_1.csv is missing"]),
        ({"hole_0.csv": "0.1,0.2\n0.1,0.2\n"}, ["row 1", "2 fields, expected 7"]),
        ({"hole_0.csv": ROW + "0.1,0.2,x,-2.0,0.1,2.2,0.7\n"}, ["row 2", "panda_joint3", "not a number"]),
        ({"hole_0.csv": ROW + "0.1,0.2,nan,-2.0,0.1,2.2,0.7\n"}, ["row 2", "not a finite number"]),
        ({"hole_0.csv": ROW + "0.1,0.2,30,-2.0,0.1,2.2,0.7\n"}, ["row 2", "panda_joint3", "radians"]),
        ({"hole_0.csv": ROW}, ["1 touch", "at least 2"]),
        ({"hole_0.csv": ROW + ROW.strip()}, ["truncated"]),
        ({"hole_0.csv": ""}, ["0 touch"]),
        (
            {"hole_0.csv": ROW * 2, "hole_1.csv": ROW * 2, "hole_01.csv": ROW * 2},
            ["hole_01.csv and hole_1.csv", "point 1"],
        ),
    ],
    ids=[
        "empty",
        "no-zero",
        "gap",
        "short-row",
        "text",
        "nan",
        "degrees",
        "one-touch",
        "truncated",
        "empty-table",
        "one-point-twice",
    ],
)
def test_reader_refuses_in_one_line_naming_the_place(tmp_path, tables, words):
    folder = write_place(tmp_path / "place", tables)
    with pytest.raises(InputError) as caught:
        read_touch_folder(folder, JOINTS)
    message = str(caught.value)
    assert "\n" not in message
    for word in words:
        assert word.lower() in message.lower(), message


def test_reader_reads_a_point_numbered_with_a_leading_zero(tmp_path):
    """``hole_01.csv`` is point 1 (its number, not its spelling, places it)."""
    folder = write_place(tmp_path / "front", {"hole_0.csv": ROW * 2, "hole_01.csv": ROW * 3})
    read = read_touch_folder(folder, JOINTS)
    assert [t.shape for t in read.tables] == [(2, 7), (3, 7)] and read.files[1].name == "hole_01.csv"


def test_reader_refuses_a_file_for_a_folder(tmp_path):
    (tmp_path / "f").write_text(ROW)
    with pytest.raises(InputError, match="not a folder"):
        read_touch_folder(tmp_path / "f", JOINTS)


# --- MUKCa's real Pandas ------------------------------------------------------------------------


def test_mukca_panda_held_out_places_beat_the_urdf():
    """panda_2 trained on front_center: every other place's scatter is a tenth of the nominal
    URDF's or less, and their mean is within 0.36 mm (MUKCa's own calibrated URDF: 0.350)."""
    root = reference("mukca_touches")
    nominal = Robot.load(root / "urdf" / "panda.urdf")
    folders = sorted((root / "data" / "panda_2_clean").iterdir())
    places = {p.name: p for p in read_places(nominal, FLANGE, folders, {(0, 1): 0.05})}
    tip = nominal.transform(FLANGE, "ball_link", np.zeros(nominal.nq))[:3, 3]
    result = identify_touches(
        nominal,
        [places["front_center"]],
        FLANGE,
        RobotAccuracy(5e-4, float(np.radians(0.1))),
        tip=tip,
        selection="chain",
    )
    held = [name for name in places if name != "front_center"]
    before = np.array([touch_scatter(nominal, places[n], FLANGE, tip).mean_scatter_m for n in held])
    after = np.array([touch_scatter(result.robot(nominal), places[n], FLANGE, result.tip).mean_scatter_m for n in held])
    assert np.all(after < before / 10)
    assert after.mean() < 0.36e-3
    assert result.fit.sigma["touch"] < 0.15e-3


def test_configurations_fill_the_arm_and_leave_the_fingers():
    robot = Robot.load(example_robot_data_share() / "robots" / "panda_description" / "urdf" / "panda.urdf")
    Q = configurations(robot, FLANGE, np.ones((2, 7)))
    assert Q.shape == (2, robot.nq) and np.all(Q[:, :7] == 1) and np.all(Q[:, 7:] == 0)
    with pytest.raises(InputError, match="6 joint values"):
        configurations(robot, FLANGE, np.ones((2, 6)))


def test_deflection_columns_are_the_joint_frames_turns(panda):
    """A term (j, a) turns joint j's frame (after its turn) about its own axis a by k·m_a: the same
    as moving the origin's rotation by that turn expressed before the joint's turn."""
    from scipy.spatial.transform import Rotation

    from brachycal.calibration.robot.arm_fit import deflection_columns

    rng = np.random.default_rng(6)
    Q = rng.uniform(panda.lower, panda.upper, (3, panda.nq))
    moments = rng.normal(0, 20, (3, panda.nq, 3))
    fp = flange_points(panda, Q, FLANGE, TIP)
    k = 1e-7
    for j, a in ((1, 2), (3, 0), (5, 1)):
        G = deflection_columns(panda, Q, fp, moments, [(j, a)])[0][:, :, 0]
        for n in range(len(Q)):
            turn = Rotation.from_rotvec(Q[n, j] * panda.joint_axis(panda.joint_names[j])).as_matrix()
            c = np.zeros((panda.nq, 6))
            c[j, 3:] = turn[:, a] * moments[n, j, a] * k
            moved = flange_points(corrected_robot(panda, c), Q[n : n + 1], FLANGE, TIP).p[0]
            assert np.allclose(G[n] * k, moved - fp.p[n], atol=1e-3 * np.abs(G[n] * k).max() + 1e-13)


def test_cli_prints_held_out_first_and_writes_a_urdf_that_reproduces_them(tmp_path, capsys):
    """``brachycal robot identify touches`` on MUKCa's panda_2: the held-out places come first, and
    the written URDF alone (its tool frame at the identified tip) gives the figures printed."""
    import json

    from brachycal.cli.main import main

    root = reference("mukca_touches")
    folders = sorted(str(p) for p in (root / "data" / "panda_2_clean").iterdir())
    code = main(
        [
            "robot", "identify", "touches", *folders,
            "--robot", str(root / "urdf" / "panda.urdf"), "--tool-frame", "ball_link",
            "--train", "front_center", "--distance-mm", "50",
            "--robot-accuracy-mm", "0.3", "--robot-accuracy-deg", "0.1", "--out", str(tmp_path / "out"),
        ]
    )  # fmt: skip
    assert code == 0
    lines = capsys.readouterr().out.splitlines()
    assert lines[0].startswith("held-out places (7)") and lines[8].startswith("training places (1)")
    assert lines[11].startswith("prior per joint origin: 0.3 mm, 0.1 deg (--robot-accuracy-mm 0.3")
    assert "robot-geometry combinations identified beyond the prior" in lines[12]
    report = json.loads((tmp_path / "out" / "identification.json").read_text())
    calibrated = Robot.load(tmp_path / "out" / "robot.urdf")
    for name in ("back_left", "mid_right"):
        Q = [np.loadtxt(root / "data" / "panda_2_clean" / name / f"hole_{k}.csv", delimiter=",") for k in (0, 1)]
        P = [calibrated.fk("ball_link", np.c_[q, np.zeros(len(q))])[:, :3, 3] for q in Q]
        scatter = np.mean([np.mean(np.linalg.norm(p - p.mean(axis=0), axis=1)) for p in P])
        assert scatter * 1e3 == pytest.approx(report["identified"][name]["scatter_mm"], abs=1e-6)
        assert scatter < report["nominal"][name]["scatter_mm"] * 1e-3 / 5


def test_with_compliance_the_written_urdf_is_the_geometry_only_fit(tmp_path, capsys):
    """MUKCa's panda_2 with --dynamics: compliance is fitted, but the written URDF is the fit of the
    geometry alone (the same as without --dynamics), and it reproduces the "URDF only" figures; the
    compliance fit's own figures are printed beside them."""
    import json

    from brachycal.cli.main import main

    root = reference("mukca_touches")
    folders = [str(root / "data" / "panda_2_clean" / name) for name in ("front_center", "back_left", "mid-high")]
    common = ["robot", "identify", "touches", *folders, "--robot", str(root / "urdf" / "panda.urdf")]
    common += ["--tool-frame", "ball_link", "--train", "front_center"]
    dynamics = example_robot_data_share() / "robots" / "panda_description" / "urdf" / "panda.urdf"
    assert main([*common, "--out", str(tmp_path / "geometry")]) == 0
    assert main([*common, "--dynamics", str(dynamics), "--out", str(tmp_path / "compliance")]) == 0
    assert "(with compliance, not in the URDF:" in capsys.readouterr().out
    geometry = json.loads((tmp_path / "geometry" / "identification.json").read_text())
    compliance = json.loads((tmp_path / "compliance" / "identification.json").read_text())
    assert compliance["with_compliance"]["compliance_rad_per_nm"] and geometry["with_compliance"] is None
    for joint, components in geometry["corrections"].items():  # the file's figures are robot.urdf's
        assert compliance["corrections"][joint] == pytest.approx(components, abs=1e-12)
    assert compliance["tip_m"] == pytest.approx(geometry["tip_m"], abs=1e-12)
    assert compliance["with_compliance"]["tip_m"] != pytest.approx(geometry["tip_m"], abs=1e-9)
    written = Robot.load(tmp_path / "compliance" / "robot.urdf")
    for name in ("back_left", "mid-high"):
        expected = geometry["identified"][name]["scatter_mm"]
        assert compliance["urdf_only"][name]["scatter_mm"] == pytest.approx(expected, abs=1e-9)
        assert compliance["identified"][name]["scatter_mm"] != pytest.approx(expected, abs=1e-3)
        Q = [np.loadtxt(root / "data" / "panda_2_clean" / name / f"hole_{k}.csv", delimiter=",") for k in (0, 1)]
        P = [written.fk("ball_link", np.c_[q, np.zeros(len(q))])[:, :3, 3] for q in Q]
        scatter = np.mean([np.mean(np.linalg.norm(p - p.mean(axis=0), axis=1)) for p in P])
        assert scatter * 1e3 == pytest.approx(expected, abs=1e-6)


def test_headline_is_the_written_urdf_s_held_out_scatter(tmp_path, capsys):
    """With --dynamics the first figure printed, and the headline of identification.json, are the
    held-out places' mean scatter of the written robot.urdf (its tool frame's forward kinematics,
    computed here from the file); the compliance fit's figure, which no URDF holds, is only beside
    it, labelled so (on the bundled touches, made without compliance, the two differ by 0.02 mm)."""
    import json
    import re

    from brachycal.cli.main import main

    touches = Path(__file__).resolve().parents[1] / "examples" / "touches"
    out = tmp_path / "out"
    args = ["robot", "identify", "touches", *(str(touches / n) for n in ("front", "left", "right"))]
    args += ["--robot", "panda", "--train", "front", "--distance-mm", "50", "--dynamics", "panda", "--quiet"]
    assert main([*args, "--out", str(out)]) == 0
    first = capsys.readouterr().out.splitlines()[0]
    document = json.loads((out / "identification.json").read_text())
    written = Robot.load(out / "robot.urdf")
    scatter = []
    for name in ("left", "right"):
        Q = [np.loadtxt(touches / name / f"hole_{k}.csv", delimiter=",") for k in (0, 1)]
        P = [written.fk(document["tool_frame"], q)[:, :3, 3] for q in Q]
        scatter.append(np.mean([np.mean(np.linalg.norm(p - p.mean(axis=0), axis=1)) for p in P]) * 1e3)
    headline = document["headline"]
    assert headline["written_urdf_mm"] == pytest.approx(np.mean(scatter), abs=1e-6)
    shown = re.fullmatch(
        r".*written URDF; mean +([\d.]+) -> ([\d.]+) mm \(with compliance, not in the URDF: ([\d.]+)\)", first
    )
    assert shown is not None, first
    assert float(shown[2]) == pytest.approx(np.mean(scatter), abs=6e-4)
    beside = headline["with_compliance_not_in_urdf_mm"]
    assert float(shown[3]) == pytest.approx(beside, abs=6e-4) and abs(beside - np.mean(scatter)) > 0.005


def test_dynamics_of_another_arm_are_refused_naming_the_option(tmp_path, capsys):
    """A KUKA iiwa identified with a Panda's masses (``--dynamics panda``), and a Panda with the
    iiwa's URDF as its masses: refused in one line naming --dynamics and the joints it lacks,
    nothing written; not a fit without compliance that says nothing."""
    from brachycal.cli.main import main

    root = reference("mukca_touches")
    row = "0.1,0.2,0.3,-1.5,0.1,1.2,0.7\n"
    folders = [str(write_place(tmp_path / name, {"hole_0.csv": row * 3, "hole_1.csv": row * 3})) for name in "ab"]
    common = ["robot", "identify", "touches", *folders, "--tool-frame", "ball_link", "--train", "a"]
    for robot, dynamics, lacks in (
        (root / "urdf" / "iiwa14.urdf", "panda", "joint_a1"),
        (root / "urdf" / "panda.urdf", str(root / "urdf" / "iiwa14.urdf"), "panda_joint1"),
    ):
        assert main([*common, "--urdf", str(robot), "--dynamics", dynamics, "--out", str(tmp_path / "out")]) == 2
        message = capsys.readouterr().err.strip()
        assert "\n" not in message and "--dynamics" in message and f"no joint {lacks}" in message, message
        assert not (tmp_path / "out").exists()


def test_dynamics_with_the_arm_s_joint_names_but_another_geometry_are_refused(panda):
    """The iiwa's URDF with its joints renamed as the Panda's: the names fit, the joint origins do
    not (moments in another arm's frames); the Panda's own masses fit."""
    from brachycal.calibration.robot.arm_fit import check_dynamics
    from brachycal.calibration.robot.touches import arm_joints

    root = reference("mukca_touches")
    text = (root / "urdf" / "iiwa14.urdf").read_text()
    for k in range(7, 0, -1):
        text = text.replace(f'"joint_a{k}"', f'"panda_joint{k}"')
    renamed = Robot(text, base_dir=root / "urdf", source="iiwa14_renamed.urdf")
    joints = arm_joints(panda, FLANGE)
    check_dynamics(panda, Robot.load(root / "urdf" / "panda.urdf"), joints)
    with pytest.raises(InputError, match=r"iiwa14_renamed\.urdf: joint panda_joint\d's origin is .* the same arm's"):
        check_dynamics(renamed, panda, joints)


def tcp_places(panda: Robot, tmp_path: Path, rng: np.random.Generator) -> list[str]:
    """Place folders ``a`` and ``b``: two points 50 mm apart each, touched 10 times by the nominal
    Panda's tool centre point (7 joint columns, joint noise 1e-5 rad)."""
    tcp = panda.tool_transform("panda_hand_tcp")[1][:3, 3]  # in the hand's link
    hand = panda.transform(FLANGE, panda.tool_transform("panda_hand_tcp")[0], np.zeros(panda.nq))
    tip = hand[:3, :3] @ tcp + hand[:3, 3]  # the tool centre point in the flange
    folders = []
    for name, centre in (("a", [0.45, -0.2, 0.15]), ("b", [0.5, 0.25, 0.3])):
        for k, point in enumerate((np.array(centre), np.array(centre) + np.array([0.05, 0.0, 0.0]))):
            Q = touches_of(panda, point, tip, 10, rng)[:, :7] + rng.normal(0, 1e-5, (10, 7))
            write_place(tmp_path / name, {f"hole_{k}.csv": "".join(",".join(f"{v:.17g}" for v in q) + "\n" for q in Q)})
        folders.append(str(tmp_path / name))
    return folders


def test_dynamics_by_name_is_the_bundled_arm_s_urdf(panda, tmp_path):
    """``--dynamics panda`` (the bundled arm, fingers frozen) gives the compliance and figures of
    ``--dynamics`` example-robot-data's Panda URDF file: the same masses; the compliance is fitted."""
    import json

    from brachycal.cli.main import main

    touches = Path(__file__).resolve().parents[1] / "examples" / "touches"
    common = ["robot", "identify", "touches", *(str(touches / n) for n in ("front", "left", "right"))]
    common += ["--robot", "panda", "--train", "front", "--distance-mm", "50", "--quiet"]
    urdf = example_robot_data_share() / "robots" / "panda_description" / "urdf" / "panda.urdf"
    assert main([*common, "--dynamics", "panda", "--out", str(tmp_path / "name")]) == 0
    assert main([*common, "--dynamics", str(urdf), "--out", str(tmp_path / "file")]) == 0
    by_name, by_file = (json.loads((tmp_path / d / "identification.json").read_text()) for d in ("name", "file"))
    name_k, file_k = (d["with_compliance"]["compliance_rad_per_nm"] for d in (by_name, by_file))
    assert name_k and name_k.keys() == file_k.keys()
    for term, k in file_k.items():
        assert name_k[term] == pytest.approx(k, rel=1e-6, abs=1e-12)
    for figures in ("identified", "urdf_only"):
        for place, values in by_file[figures].items():
            assert by_name[figures][place]["scatter_mm"] == pytest.approx(values["scatter_mm"], rel=1e-6)


def test_cli_tilt_prior_is_the_one_fitted_printed_and_written(panda, tmp_path, capsys):
    """``--robot-tilt-deg`` gives the axes' tilt a prior of its own beside the stated rotation: the
    fit's prior (printed, and written in the document) carries both."""
    import json

    from brachycal.cli.main import main

    folders = tcp_places(panda, tmp_path, np.random.default_rng(6))
    out = tmp_path / "out"
    args = ["robot", "identify", "touches", *folders, "--robot", "panda", "--train", "a", "--out", str(out)]
    code = main([*args, "--robot-accuracy-mm", "0.1", "--robot-accuracy-deg", "0.3", "--robot-tilt-deg", "0.02"])
    assert code == 0
    printed = [line for line in capsys.readouterr().out.splitlines() if line.startswith("prior per joint origin")]
    assert printed == [
        "prior per joint origin: 0.1 mm, 0.3 deg, axis tilt 0.02 deg "
        "(--robot-accuracy-mm 0.1 --robot-accuracy-deg 0.3 (encoder SD: the default); --robot-tilt-deg 0.02)"
    ]
    prior = json.loads((out / "identification.json").read_text())["prior"]
    assert prior["axis_tilt_sd_deg"] == pytest.approx(0.02) and prior["joint_rotation_sd_deg"] == pytest.approx(0.3)


def test_cli_takes_a_bundled_arm_and_its_tool(panda, tmp_path, capsys):
    """``--robot panda`` (the bundled description, fingers frozen: 7 joint columns) with no
    --tool-frame: the arm's tool (panda_hand_tcp) touches; touches of the nominal arm (joint noise
    1e-5 rad, the tip's ~5 µm) leave a held-out scatter of that size, and the written URDF holds the arm's 7 joints.
    With no accuracy stated the prior is the touches' own default (a collaborative arm's 0.3 mm /
    0.1°), not the twin's well-built 0.03 mm."""
    import json

    from brachycal.cli.main import main

    folders = tcp_places(panda, tmp_path, np.random.default_rng(5))
    out = tmp_path / "out"
    code = main(["robot", "identify", "touches", *folders, "--robot", "panda", "--train", "a", "--out", str(out)])
    assert code == 0
    lines = capsys.readouterr().out.splitlines()
    assert lines[0].startswith("held-out places (1)") and lines[2].startswith("training places (1)")
    document = json.loads((out / "identification.json").read_text())
    assert document["tool_frame"] == "panda_hand_tcp"
    assert document["identified"]["b"]["scatter_mm"] < 0.02
    assert [line for line in lines if line.startswith("prior per joint origin: 0.3 mm, 0.1 deg (touches default")]
    assert document["prior"]["joint_translation_sd_mm"] == pytest.approx(0.3)
    assert Robot.load(out / "robot.urdf").nq == 7  # the description's fingers stay frozen


# --- the prior chosen by the touches' evidence ----------------------------------------------------


@pytest.mark.slow  # an evidence search: tens of fits
def test_evidence_recovers_the_prior_the_arm_was_drawn_from(panda):
    """An arm whose joint origins are drawn from 0.5 mm / 0.2° per joint, touched with 30 µm of
    noise: the evidence search, started ten times too tight, lands near the drawn SDs (one arm is
    a few dozen draws, the translations seen through fewer independent combinations than the
    rotations: over seeds the translation SD comes out at 0.5–1.4 times the truth, the rotation
    SD at 0.75–1.2 times), and the noise level it re-estimates is the drawn one."""
    rng = np.random.default_rng(11)
    truth = RobotAccuracy(5e-4, float(np.radians(0.2)))
    drawn = rng.normal(0, 1, 6 * panda.nq) * prior_sd(panda, truth)
    chain = ParameterSelection.chain(panda, FLANGE)
    true_robot = corrected_robot(panda, chain.expand(drawn[chain.index]))
    sd = 3e-5
    places = noisy_places(true_robot, rng, sd)
    start = RobotAccuracy(5e-5, float(np.radians(0.02)))
    chosen = evidence_prior(panda, places, FLANGE, start, tip=[0, 0, 0.13])
    assert 0.4 < chosen.accuracy.translation_sd_m / truth.translation_sd_m < 2.5
    assert 0.67 < chosen.accuracy.rotation_sd_rad / truth.rotation_sd_rad < 1.5
    result = identify_touches(panda, places, FLANGE, start, tip=[0, 0, 0.13], prior="evidence")
    assert result.fit.accuracy == chosen.accuracy
    assert result.fit.log_evidence == pytest.approx(chosen.log_evidence, abs=1e-6)
    assert result.fit.sigma["touch"] == pytest.approx(sd, rel=0.2)


@pytest.mark.slow  # an evidence search: tens of fits
def test_evidence_is_highest_at_the_chosen_prior(panda):
    """The chosen prior is the evidence's maximum: a tenfold looser or tighter prior has less."""
    rng = np.random.default_rng(12)
    places = synthetic_places(corrected_robot(panda, rng.normal(0, 3e-4, (panda.nq, 6))), rng)[:2]
    noisy = [
        TouchPlace(
            p.name, tuple(Q + rng.normal(0, 2e-5, Q.shape) * (np.arange(panda.nq) < 7) for Q in p.touches), p.distances
        )
        for p in places
    ]
    chosen = evidence_prior(panda, noisy, FLANGE, RobotAccuracy(3e-4, float(np.radians(0.1))), tip=[0, 0, 0.13])
    for factor in (0.1, 10.0):
        other = RobotAccuracy(chosen.accuracy.translation_sd_m * factor, chosen.accuracy.rotation_sd_rad * factor)
        fit = identify_touches(panda, noisy, FLANGE, other, tip=[0, 0, 0.13]).fit
        assert fit.log_evidence < chosen.log_evidence


@pytest.mark.slow  # an evidence search: tens of fits
def test_evidence_prior_is_the_training_places_own():
    """MUKCa's panda_2 trained on front_center: the prior the evidence chooses is the same whether
    the held-out places are among the folders or not (they never enter the choice)."""
    root = reference("mukca_touches")
    nominal = Robot.load(root / "urdf" / "panda.urdf")
    folders = sorted((root / "data" / "panda_2_clean").iterdir())
    accuracy = RobotAccuracy(3e-4, float(np.radians(0.1)))
    reports = [
        identify_touch_folders(
            nominal, chosen, "ball_link", ["front_center"], accuracy, distance_m=0.05, prior="evidence"
        )
        for chosen in (folders, [f for f in folders if f.name == "front_center"])
    ]
    assert reports[0].result.fit.accuracy == reports[1].result.fit.accuracy
    assert reports[0].result.fit.accuracy != accuracy
    assert len(reports[0].held_out) == 7 and reports[1].held_out == []
    held = np.mean([reports[0].identified[n].mean_scatter_m for n in reports[0].held_out])
    assert held < np.mean([reports[0].nominal[n].mean_scatter_m for n in reports[0].held_out]) / 10


@pytest.mark.slow  # an evidence search: tens of fits
def test_cli_prior_from_the_evidence_is_the_training_data_s_most_likely(tmp_path, capsys):
    """``--prior evidence`` on the bundled touches: the prior written and printed is the one the
    training place's evidence chose, and that evidence is at least the stated prior's."""
    import json

    from conftest import ROOT

    from brachycal.cli.main import main

    places = [str(ROOT / "examples" / "touches" / name) for name in ("front", "left", "right")]
    common = ["robot", "identify", "touches", *places, "--robot", "panda", "--train", "front"]
    common += ["--robot-accuracy-mm", "0.3", "--robot-accuracy-deg", "0.05"]
    documents = {}
    for prior in ("stated", "evidence"):
        assert main([*common, "--prior", prior, "--out", str(tmp_path / prior)]) == 0
        printed = [line for line in capsys.readouterr().out.splitlines() if line.startswith("prior per joint origin")]
        assert len(printed) == 1
        documents[prior] = json.loads((tmp_path / prior / "identification.json").read_text())
    assert "evidence" in printed[0]
    assert documents["stated"]["prior"]["joint_translation_sd_mm"] == pytest.approx(0.3)
    assert documents["evidence"]["prior"]["source"] == "chosen by the evidence of the training touches"
    assert documents["evidence"]["log_evidence"] >= documents["stated"]["log_evidence"] - 1e-6


# --- the axis tilt's own prior -------------------------------------------------------------------


def test_tilt_prior_is_across_the_axis_and_leaves_the_turn_about_it(panda):
    """A stated tilt SD is the rotation's SD about every direction across a joint's axis; about the
    axis the SD stays the stated rotation's with the zero offset's (variance twice); translations
    keep theirs. Without it the rotation is isotropic as before (the tilt is the rotation SD)."""
    rot, tilt = float(np.radians(0.5)), float(np.radians(0.02))
    tilted = RobotAccuracy(1e-4, rot, tilt_sd_rad=tilt).covariance(panda)
    plain = RobotAccuracy(1e-4, rot).covariance(panda)
    same = RobotAccuracy(1e-4, rot, tilt_sd_rad=rot).covariance(panda)
    np.testing.assert_allclose(same, plain, rtol=1e-12, atol=0)
    for j, name in enumerate(panda.joint_names):
        a = panda.joint_axis(name)
        across = np.linalg.svd(a[None])[2][1:]  # two unit directions across the axis
        block = tilted[6 * j + 3 : 6 * j + 6, 6 * j + 3 : 6 * j + 6]
        assert a @ block @ a == pytest.approx(2 * rot**2, rel=1e-12)
        np.testing.assert_allclose(across @ block @ across.T, tilt**2 * np.eye(2), rtol=0, atol=1e-12 * rot**2)
        np.testing.assert_allclose(across @ block @ a, 0.0, atol=1e-12 * rot**2)
        np.testing.assert_allclose(tilted[6 * j : 6 * j + 3, 6 * j : 6 * j + 3], 1e-8 * np.eye(3), rtol=1e-12)
    assert RobotAccuracy(1e-4, rot, tilt_sd_rad=tilt).as_json()["axis_tilt_sd_deg"] == pytest.approx(0.02)
    assert "axis_tilt_sd_deg" not in RobotAccuracy(1e-4, rot).as_json()
    with pytest.raises(InputError, match="tilt"):
        RobotAccuracy(1e-4, rot, tilt_sd_rad=float(np.radians(2.0)))


@pytest.mark.slow  # an evidence search: tens of fits
def test_evidence_recovers_a_tilt_apart_from_the_turn_about_the_axis(panda):
    """An arm whose joints' zeros and turns about their axes are off by 0.3° but whose axes tilt by
    only 0.02° (drawn here component by component, not through the prior): the evidence search
    with a tilt of its own, started from one rotation SD for both, separates them to the drawn
    SDs' order; the tilt comes out several times tighter than the turn about the axis."""
    rng = np.random.default_rng(21)
    about, tilt = float(np.radians(0.3)), float(np.radians(0.02))
    drawn = np.zeros((panda.nq, 6))
    for j, name in enumerate(panda.joint_names[:7]):
        a = panda.joint_axis(name)
        across = np.linalg.svd(a[None])[2][1:]
        drawn[j, :3] = rng.normal(0, 2e-4, 3)
        drawn[j, 3:] = np.sqrt(2) * about * rng.normal() * a + tilt * rng.normal(0, 1, 2) @ across
    true_robot = corrected_robot(panda, drawn)
    places = noisy_places(true_robot, rng, 3e-5)
    start = RobotAccuracy(2e-4, float(np.radians(0.1)), tilt_sd_rad=float(np.radians(0.1)))
    chosen = evidence_prior(panda, places, FLANGE, start, tip=[0, 0, 0.13])
    assert chosen.accuracy.tilt_sd_rad is not None
    assert 0.5 < chosen.accuracy.rotation_sd_rad / about < 2.0
    assert 0.3 < chosen.accuracy.tilt_sd_rad / tilt < 3.0
    assert chosen.accuracy.tilt_sd_rad < chosen.accuracy.rotation_sd_rad / 3


# --- the setting chosen by cross-validation inside the training places ---------------------------


@pytest.fixture(scope="module")
def far_off_arm(panda):
    """A Panda off its URDF by 0.5 mm / 0.2° per joint-origin component, touched at two places
    (30 µm of touch noise): a stated accuracy of 0.02 mm / 0.002° is far too tight for it."""
    rng = np.random.default_rng(11)
    free = ParameterSelection.chain(panda, FLANGE).free
    c = rng.normal(0, 1, (panda.nq, 6)) * np.r_[[5e-4] * 3, [np.radians(0.2)] * 3] * free
    return noisy_places(corrected_robot(panda, c), rng, 3e-5)[:2]


@pytest.mark.slow  # four evidence searches
def test_choice_leaves_the_default_only_for_a_setting_better_by_more_than_its_se(panda, far_off_arm):
    """Leave-one-place-out inside the training places: with a stated accuracy far too tight, the
    evidence's prior predicts each training place from the other ~10 times better and replaces the
    stated one; listed the other way round, the stated accuracy does not replace the evidence's."""
    from brachycal.calibration.robot.touches import choose_touch_setting

    tight = RobotAccuracy(2e-5, float(np.radians(0.002)))
    choice = choose_touch_setting(panda, far_off_arm, FLANGE, tight, tip=TIP, settings=("stated", "evidence"))
    assert choice.over == "places" and choice.chosen == "evidence", choice.reason
    stated, evidence = choice.scores
    assert evidence.cv_error_mm < stated.cv_error_mm / 5
    mean, se = evidence.vs_chosen
    assert mean < -3 * se
    reverse = choose_touch_setting(panda, far_off_arm, FLANGE, tight, tip=TIP, settings=("evidence", "stated"))
    assert reverse.chosen == "evidence" and reverse.scores[1].vs_chosen[0] > 0, reverse.reason


def test_one_training_place_keeps_the_defaults_unscored(panda, far_off_arm):
    """With one training place there is no place to leave out: the default, with the reason."""
    from brachycal.calibration.robot.touches import choose_touch_setting

    choice = choose_touch_setting(panda, far_off_arm[:1], FLANGE, RobotAccuracy(3e-4, float(np.radians(0.1))))
    assert choice.chosen == "stated" and choice.scores == () and "one training place" in choice.reason


def test_cross_validation_over_places_predicts_each_from_the_others_only(panda, far_off_arm):
    """Leave-one-place-out errors are those of the fit of the other place alone (an independent
    fit here), per touch the distance of its tip from its point's mean tip."""
    from brachycal.calibration.robot.touches import touch_cv_errors

    accuracy = RobotAccuracy(3e-4, float(np.radians(0.1)))
    errors, block = touch_cv_errors(panda, far_off_arm, FLANGE, accuracy, tip=TIP)
    fit = identify_touches(panda, [far_off_arm[1]], FLANGE, accuracy, tip=TIP, selection="chain")
    expected = []
    for Q in far_off_arm[0].touches:
        p = fit.robot(panda).fk(FLANGE, Q)
        tips = p[:, :3, :3] @ fit.tip + p[:, :3, 3]
        expected.append(np.linalg.norm(tips - tips.mean(axis=0), axis=1))
    expected = np.concatenate(expected)
    assert errors[: len(expected)] == pytest.approx(expected, abs=1e-12)
    assert len(errors) == sum(len(Q) for p in far_off_arm for Q in p.touches)
    assert len(np.unique(block)) == 2 * 2 * 5  # places x points x contiguous fifths


@pytest.mark.slow  # three settings, two folds each, evidence searches
def test_cli_prior_choose_prints_and_writes_the_choice_and_why(tmp_path, capsys):
    """``--prior choose`` with two training places: the setting left at the default (the bundled
    touches' arm is off by about the stated accuracy), each setting's cross-validated error and the
    rule printed and written; the prior written is the stated one."""
    import json

    from brachycal.cli.main import main

    touches = Path(__file__).resolve().parents[1] / "examples" / "touches"
    out = tmp_path / "out"
    args = ["robot", "identify", "touches", *(str(touches / n) for n in ("front", "left", "right"))]
    args += ["--robot", "panda", "--train", "front,left", "--distance-mm", "50", "--prior", "choose", "--quiet"]
    assert main([*args, "--out", str(out)]) == 0
    printed = [line for line in capsys.readouterr().out.splitlines() if line.startswith("setting: ")]
    assert len(printed) == 1 and printed[0].startswith("setting: stated (stated: the default;")
    assert "leave-one-place-out over the training places" in printed[0]
    document = json.loads((out / "identification.json").read_text())
    choice = document["setting_choice"]
    assert choice["chosen"] == "stated" and list(choice["scores"]) == ["stated", "evidence", "evidence+tilt"]
    for name in ("evidence", "evidence+tilt"):
        mean, se = choice["scores"][name]["vs_previous_choice_mm"]
        assert not mean < -se
    assert document["prior"]["joint_translation_sd_mm"] == pytest.approx(0.3)


def test_cross_validation_over_postures_leaves_out_contiguous_blocks(panda, far_off_arm):
    """Over postures: each point's touches cut into five contiguous blocks; the first block's
    errors are those of an independent fit without it, per touch the distance of its tip from its
    point as that fit placed it."""
    from brachycal.calibration.robot.touches import touch_cv_errors

    accuracy = RobotAccuracy(3e-4, float(np.radians(0.1)))
    place = far_off_arm[0]
    errors, block = touch_cv_errors(panda, [place], FLANGE, accuracy, over="postures", tip=TIP)
    n = len(place.touches[0])
    first = np.arange(-(-n // 5))  # numpy's array_split: the first blocks are the longer ones
    kept = TouchPlace(place.name, tuple(np.delete(Q, first, axis=0) for Q in place.touches), place.distances)
    fit = identify_touches(panda, [kept], FLANGE, accuracy, tip=TIP, selection="chain")
    T = fit.robot(panda).fk(FLANGE, place.touches[0][first])
    expected = np.linalg.norm(T[:, :3, :3] @ fit.tip + T[:, :3, 3] - fit.points[0][0], axis=1)
    assert errors[: len(first)] == pytest.approx(expected, abs=1e-12)
    assert list(block[:n]) == [k for k, c in enumerate(np.array_split(np.arange(n), 5)) for _ in c]
