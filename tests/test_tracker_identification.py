"""Robot identification from an external tracker (3-D or 6-D marker, unknown tracker and marker frames).

Exact measurements of a corrected Panda seen by a tracker in an unknown frame identify the arm and
both frames to the nanometre; the analytic Jacobians agree with differences; leave-one-out keeps
the smaller model on data that hold nothing for a richer one to find (and takes the richer one
when they do); FIGAROH's real UR10 (outside data) gives its published figures. The reader of
tracker tables reads FIGAROH's two files by a column spec and refuses mixed-up units by magnitude.
"""

from __future__ import annotations

import dataclasses
import json
from pathlib import Path

import numpy as np
import pytest
from conftest import ROOT, reference
from scipy.spatial.transform import Rotation

from brachycal.calibration.robot.arm_fit import ParameterSelection, _evaluate
from brachycal.calibration.robot.identification import corrected_robot, prior_sd
from brachycal.calibration.robot.tracker import (
    TrackerData,
    TrackerResiduals,
    fit_tracker,
    identify_from_tracker,
    leave_one_out,
    select_parameters,
    start_frames,
    tracker_data,
    tracker_evidence_prior,
)
from brachycal.calibration.robot_accuracy import RobotAccuracy
from brachycal.cli.main import main
from brachycal.data.formats.tracker_table import (
    MIN_TRACKER_ROWS,
    TrackerColumns,
    TrackerTable,
    read_tracker_columns,
    read_tracker_table,
)
from brachycal.errors import InputError
from brachycal.model.description_file import example_robot_data_share
from brachycal.model.robot import Robot
from brachycal.se3 import make_transform

FLANGE = "panda_link8"
ARM = tuple(f"panda_joint{k}" for k in range(1, 8))
T_TRACKER_BASE = make_transform(Rotation.from_rotvec([0.3, -1.2, 2.0]).as_matrix(), [1.5, -0.4, 0.9])
T_FLANGE_MARKER = make_transform(Rotation.from_rotvec([0.2, 0.1, -0.4]).as_matrix(), [0.03, -0.02, 0.11])
FIGAROH = ("figaroh_mocap",)
SPECS = ROOT / "benchmarks" / "figaroh_mocap"
SPEC_HEAD = 'format = "brachycal-tracker-columns/1"\njoints = ["a"]\n'
POSITION = '[position]\ncolumns = ["x", "y", "z"]\n'


@pytest.fixture(scope="module")
def panda() -> Robot:
    return Robot.load(example_robot_data_share() / "robots" / "panda_description" / "urdf" / "panda.urdf")


def postures(robot: Robot, n: int, seed: int) -> np.ndarray:
    """``(n, nq)`` random postures inside the limits (fingers closed)."""
    rng = np.random.default_rng(seed)
    Q = np.zeros((n, robot.nq))
    Q[:, :7] = rng.uniform(robot.lower[:7] + 0.1, robot.upper[:7] - 0.1, (n, 7))
    return Q


def measured(true: Robot, Q: np.ndarray, six_d: bool, noise_m: float = 0.0, seed: int = 0) -> TrackerData:
    """What a tracker sees of the marker on the true robot at ``Q`` (noise on the position only)."""
    T = T_TRACKER_BASE @ true.fk(FLANGE, Q) @ T_FLANGE_MARKER
    p = T[:, :3, 3] + np.random.default_rng(seed).normal(0, noise_m, (len(Q), 3))
    return TrackerData(true, FLANGE, Q, p, T[:, :3, :3] if six_d else None)


def with_robot(data: TrackerData, robot: Robot) -> TrackerData:
    return TrackerData(robot, data.flange, data.Q, data.p, data.R, data.rows)


def true_robot(nominal: Robot, data_shape: TrackerData, size: float, seed: int) -> tuple[Robot, np.ndarray]:
    """The nominal robot corrected on the joints model's base set only (what the data can see)."""
    selection = select_parameters(data_shape, "joints", None)
    x = np.random.default_rng(seed).normal(0, size, selection.size)
    corrections = selection.expand(x)
    return corrected_robot(nominal, corrections), corrections


@pytest.mark.parametrize("six_d", [True, False], ids=["6-D", "3-D"])
def test_exact_measurements_of_a_corrected_arm_are_recovered(panda, six_d):
    """Exact tracker data of a corrected arm (1 mm / 1 mrad per kept component) in an unknown
    tracker frame: the fitted model predicts the marker at postures it never saw to 1e-8 m, and the
    frames come back to 1e-8 m (the true ones: the base set leaves no freedom between them)."""
    Q = postures(panda, 30, seed=1)
    shape = measured(panda, Q, six_d)
    true, _ = true_robot(panda, shape, 1e-3, seed=2)
    data = with_robot(measured(true, Q, six_d), panda)
    fit = fit_tracker(data, "joints", None, estimate_noise=False)
    unseen = postures(panda, 10, seed=3)
    truth = measured(true, unseen, six_d)
    p, R = fit.predict(with_robot(truth, panda))
    assert np.max(np.abs(p - truth.p)) < 1e-8
    if six_d:
        assert truth.R is not None
        assert np.max(np.abs(R - truth.R)) < 1e-8
    assert np.max(np.abs(fit.position_residuals)) < 1e-8
    # the frames are only determined up to what the base set lumps with them: compare their effect
    T_tm = fit.T_tracker_base @ fit.robot(panda).fk(FLANGE, unseen) @ fit.T_flange_marker
    assert np.max(np.abs(T_tm[:, :3, 3] - truth.p)) < 1e-8


def test_the_nominal_arm_fits_its_own_data_with_the_frames_alone(panda):
    """No robot error: the frames-only model recovers the true frames exactly (6-D)."""
    data = measured(panda, postures(panda, 12, seed=4), True)
    fit = fit_tracker(data, "frames", estimate_noise=False)
    assert np.max(np.abs(fit.T_tracker_base - T_TRACKER_BASE)) < 1e-9
    assert np.max(np.abs(fit.T_flange_marker - T_FLANGE_MARKER)) < 1e-9
    assert fit.parameters == []


@pytest.mark.parametrize("six_d", [True, False], ids=["6-D", "3-D"])
def test_jacobians_match_central_differences(panda, six_d):
    """``J_y`` (frames, at a step away from the start so the SO(3) Jacobians matter) and ``J_c``
    (every joint-origin component) agree with central differences to 1e-6 of their largest entry,
    with residuals far from zero (a 6-D fit's orientation rows use log's Jacobian)."""
    Q = postures(panda, 5, seed=5)
    true = corrected_robot(panda, np.random.default_rng(6).normal(0, 3e-3, (panda.nq, 6)))
    data = with_robot(measured(true, Q, six_d), panda)
    model = TrackerResiduals(data, *start_frames(data))
    y = np.random.default_rng(7).normal(0, 0.05, model.ny)
    c = np.random.default_rng(8).normal(0, 2e-3, (panda.nq, 6))
    c[7] = 0.0  # the fingers' joint: not on the chain to the flange
    robot = corrected_robot(panda, c)
    ev = model.evaluate(robot, y)
    h = 1e-6
    J_y = np.column_stack(
        [(model.evaluate(robot, y + h * e).r - model.evaluate(robot, y - h * e).r) / (2 * h) for e in np.eye(model.ny)]
    )
    assert np.max(np.abs(J_y - ev.J_y)) < 1e-6 * np.max(np.abs(ev.J_y))
    # The fit steps the corrections additively: arm_fit turns the protocol's J_c (a motion composed on
    # the corrected origin, joint_twists') into that derivative, exact at any c.
    selection = ParameterSelection.chain(panda, FLANGE)
    x = c.reshape(-1)[selection.index]
    J_add = _evaluate(panda, model, selection, x, y).J_c
    J_c = np.zeros_like(ev.J_c)
    for k in range(6 * 7):  # the arm's joints; the fingers do not move the flange
        e = np.zeros(6 * panda.nq)
        e[k] = h
        plus = model.evaluate(corrected_robot(panda, c + e.reshape(-1, 6)), y).r
        minus = model.evaluate(corrected_robot(panda, c - e.reshape(-1, 6)), y).r
        J_c[:, k] = (plus - minus) / (2 * h)
    assert np.max(np.abs(J_c - J_add)) < 1e-6 * np.max(np.abs(J_add))
    assert np.max(np.abs(J_c - ev.J_c)) > 1e-3 * np.max(np.abs(ev.J_c))  # the composed form differs by ~|c|
    ev0 = model.evaluate(panda, y)
    J_c0 = np.zeros_like(ev0.J_c)
    for k in range(6 * 7):
        e = np.zeros(6 * panda.nq)
        e[k] = h
        plus = model.evaluate(corrected_robot(panda, e.reshape(-1, 6)), y).r
        minus = model.evaluate(corrected_robot(panda, -e.reshape(-1, 6)), y).r
        J_c0[:, k] = (plus - minus) / (2 * h)
    assert np.max(np.abs(J_c0 - ev0.J_c)) < 1e-6 * np.max(np.abs(ev0.J_c))  # at c = 0: exact


def test_the_base_set_drops_what_the_frames_absorb(panda):
    """The first joint's zero is the tracker frame's turn; the last joint's origin moved along or
    turned about its axis is the marker's place: none is estimated."""
    data = measured(panda, postures(panda, 20, seed=9), False)
    joints = select_parameters(data, "joints", None).names
    offsets = select_parameters(data, "offsets", None).names
    assert "panda_joint1.wz" not in joints and "panda_joint1.wz" not in offsets
    assert "panda_joint7.vz" not in joints and "panda_joint7.wz" not in joints
    assert "panda_joint4.wz" in offsets  # a middle joint's zero is seen


def test_leave_one_out_predicts_each_posture_without_it(panda):
    """A posture's held-out error is its error under a fit that did not see it: equal to the
    training residual of the fit on the others evaluated there, and larger on average than the
    training residuals (noise 0.5 mm)."""
    data = measured(panda, postures(panda, 12, seed=10), False, noise_m=5e-4, seed=11)
    e_p, e_o = leave_one_out(data, "frames")
    assert e_o is None
    keep = np.arange(12) != 4
    fit = fit_tracker(data.subset(keep), "frames")
    p, _ = fit.predict(data.subset(~keep))
    assert np.allclose(e_p[4], p[0] - data.p[4], atol=1e-12)
    full = fit_tracker(data, "frames")
    assert np.mean(e_p**2) > np.mean(full.position_residuals**2)


def test_a_richer_model_on_pure_noise_is_not_chosen(panda):
    """Break on purpose: the nominal arm with 1 mm tracker noise has nothing for joint origins to
    find; their extra parameters fit the noise, predict held-out postures worse, and the frames-only
    model is returned, the report saying why."""
    data = measured(panda, postures(panda, 25, seed=12), False, noise_m=1e-3, seed=13)
    result = identify_from_tracker(data, models=("frames", "joints"))
    assert result.chosen == "frames"
    assert "joints not supported" in result.reason
    frames, joints = result.scores
    assert joints.loo_position_mm > frames.loo_position_mm  # the extra parameters hurt held out
    assert joints.training_position_mm < frames.training_position_mm  # while flattering training


def test_a_richer_model_is_chosen_when_the_arm_is_off(panda):
    """The same noise on an arm off by 1 mm / 1 mrad per kept component: the joints model
    predicts held-out postures better by more than its standard error and is chosen."""
    Q = postures(panda, 25, seed=14)
    true, _ = true_robot(panda, measured(panda, Q, False), 1e-3, seed=15)
    data = with_robot(measured(true, Q, False, noise_m=1e-4, seed=16), panda)
    accuracy = RobotAccuracy(translation_sd_m=1e-3, rotation_sd_rad=1e-3, source="test")
    result = identify_from_tracker(data, accuracy, models=("frames", "joints"))
    assert result.chosen == "joints"
    mean, se = result.scores[1].vs_chosen or (0.0, 0.0)
    assert mean < -se


def test_noise_level_matches_the_tracker_noise(panda):
    """The stated position noise level (frames model, leverage-corrected) is the tracker's SD:
    over 40 draws of 40 postures at 0.5 mm, the mean of the estimates is within 4% of it (3 SE of
    the mean: one estimate's SD is ~8%); a level without the leverages' correction is 4% low."""
    Q = postures(panda, 40, seed=17)
    levels = [fit_tracker(measured(panda, Q, False, 5e-4, seed=s), "frames").sigma["position"] for s in range(40)]
    assert abs(np.mean(levels) / 5e-4 - 1) < 0.04


# --- the prior chosen by the postures' evidence -------------------------------------------------

DRAWN = RobotAccuracy(5e-4, float(np.radians(0.2)))


def drawn_arm(panda: Robot, n: int, seed: int) -> tuple[TrackerData, ParameterSelection]:
    """A Panda whose joints model's base set is drawn from :data:`DRAWN`, seen by a 3-D tracker
    with 20 µm of noise at ``n`` postures; the selection the draw was made on."""
    rng = np.random.default_rng(seed)
    Q = postures(panda, n, seed=seed + 100)
    selection = select_parameters(measured(panda, Q, False), "joints", DRAWN)
    drawn = rng.normal(0, 1, 6 * panda.nq) * prior_sd(panda, DRAWN)
    true = corrected_robot(panda, selection.expand(drawn[selection.index]))
    return with_robot(measured(true, Q, False, noise_m=2e-5, seed=seed + 200), panda), selection


@pytest.mark.slow  # an evidence search: tens of fits
def test_evidence_recovers_the_prior_the_arm_was_drawn_from(panda):
    """An arm whose 22 seen joint-origin components are drawn from 0.5 mm / 0.2° per joint, 40
    postures with 20 µm of tracker noise: the evidence search, started ten times too tight, lands
    within a factor 2 of the drawn SDs (over six seeds both come out at 0.7–1.5 times the truth:
    one arm is a few dozen draws), and ``prior="evidence"`` fits with that choice."""
    data, selection = drawn_arm(panda, 40, seed=1)
    start = RobotAccuracy(5e-5, float(np.radians(0.02)))
    chosen = tracker_evidence_prior(data, "joints", start, selection=selection)
    assert 0.5 < chosen.accuracy.translation_sd_m / DRAWN.translation_sd_m < 2.0
    assert 0.5 < chosen.accuracy.rotation_sd_rad / DRAWN.rotation_sd_rad < 2.0
    fit = fit_tracker(data, "joints", start, selection=selection, prior="evidence")
    assert fit.arm.accuracy == chosen.accuracy
    assert fit.arm.log_evidence == pytest.approx(chosen.log_evidence, abs=1e-6)


@pytest.mark.slow  # an evidence search: tens of fits
def test_tracker_evidence_is_highest_at_the_chosen_prior(panda):
    """The chosen prior is the evidence's maximum: each SD three times looser or tighter (the
    other held) has less evidence."""
    data, selection = drawn_arm(panda, 30, seed=2)
    chosen = tracker_evidence_prior(data, "joints", RobotAccuracy(1e-3, float(np.radians(0.1))), selection=selection)
    a = chosen.accuracy
    for t, r in ((3.0, 1.0), (1 / 3, 1.0), (1.0, 3.0), (1.0, 1 / 3)):
        other = RobotAccuracy(a.translation_sd_m * t, a.rotation_sd_rad * r, a.encoder_sd_rad)
        assert fit_tracker(data, "joints", other, selection=selection).arm.log_evidence < chosen.log_evidence


@pytest.mark.slow  # an evidence search per fold
def test_leave_one_out_chooses_each_fold_s_prior_without_the_held_out_posture(panda):
    """With ``prior="evidence"`` a posture's held-out error is the prediction of a fit whose prior
    its fold's postures alone chose: with that posture's measurement moved by 2 cm, its error is
    (to 1e-12 m) the one of ``fit_tracker(prior="evidence")`` on the other postures, computed
    without the moved measurement, and that fold's prior is not the stated one."""
    data, _ = drawn_arm(panda, 8, seed=3)
    start = RobotAccuracy(1e-3, float(np.radians(0.1)))
    moved_p = data.p.copy()
    moved_p[4] += [0.02, 0.0, 0.0]
    moved = TrackerData(data.robot, data.flange, data.Q, moved_p, None)
    e_moved, _ = leave_one_out(moved, "offsets", start, prior="evidence")
    keep = np.arange(8) != 4
    fold = fit_tracker(
        data.subset(keep), "offsets", start, selection=select_parameters(moved, "offsets", start), prior="evidence"
    )
    assert fold.arm.accuracy is not None and fold.arm.accuracy != start
    p, _ = fold.predict(data.subset(~keep))
    assert np.allclose(e_moved[4], p[0] - moved_p[4], atol=1e-12, rtol=0)


@pytest.mark.slow  # an evidence search per fold
def test_cli_prior_from_the_evidence(panda, tmp_path, capsys):
    """``--prior evidence`` on a table of a Panda off its URDF (8 postures, 3-D marker): the prior
    written and printed is the one the postures' evidence chose (the rule recorded), and its
    evidence is at least the stated prior's."""
    data, _ = drawn_arm(panda, 8, seed=3)
    rows = np.hstack([data.Q[:, :7], data.p])
    (tmp_path / "table.csv").write_text(
        ",".join([*ARM, "x", "y", "z"]) + "\n" + "\n".join(",".join(map(repr, r.tolist())) for r in rows) + "\n"
    )
    spec = SPEC_HEAD.replace('["a"]', "[" + ", ".join(f'"{j}"' for j in ARM) + "]") + POSITION + 'unit = "m"\n'
    (tmp_path / "columns.toml").write_text(spec)
    out = tmp_path / "out"
    code = main(
        [
            "robot", "identify", "tracker", str(tmp_path / "table.csv"), "--columns", str(tmp_path / "columns.toml"),
            "--urdf", str(panda.source), "--flange", FLANGE, "--model", "offsets", "--prior", "evidence",
            "--out", str(out),
        ]
    )  # fmt: skip
    assert code == 0
    printed = [line for line in capsys.readouterr().out.splitlines() if line.startswith("prior per joint origin")]
    assert len(printed) == 1 and "chosen by the evidence of the training postures" in printed[0]
    document = json.loads((out / "identification.json").read_text())
    assert document["prior_rule"] == "evidence" and document["chosen"] == "offsets"
    assert document["prior"]["source"] == "chosen by the evidence of the training postures"
    assert document["models"]["offsets"]["prior"] == document["prior"]
    assert document["log_evidence"] >= fit_tracker(data, "offsets").arm.log_evidence - 1e-6


# --- the reader ------------------------------------------------------------------------------


def test_figaroh_files_read_with_their_column_specs():
    ur10 = read_tracker_table(
        reference(*FIGAROH, "ur10", "data", "calibration.csv"), read_tracker_columns(SPECS / "ur10_columns.toml")
    )
    assert len(ur10) == 23 and ur10.R_tracker_marker is not None and ur10.Q.shape == (23, 6)
    first = ur10.R_tracker_marker[0]
    expected = Rotation.from_euler("xyz", [-1.1869330161318221, -0.5109858420062574, -2.3796294050596307])
    assert np.allclose(first, expected.as_matrix(), atol=1e-12)
    tiago = read_tracker_table(
        reference(*FIGAROH, "tiago", "data", "calibration", "mocap", "qualysis_base_hand_calibration.csv"),
        read_tracker_columns(SPECS / "tiago_columns.toml"),
    )
    assert len(tiago) == 34 and tiago.R_tracker_marker is None and tiago.Q.shape == (34, 8)


@pytest.mark.parametrize("origin", ["figaroh_ur10", "brachycal_example"])
def test_radians_stated_as_degrees_are_refused_from_the_data(origin, tmp_path):
    """Orientation angles in radians under ``unit = "deg"`` are refused, naming the column, on a real
    table (FIGAROH's UR10, roll-pitch-yaw) and on brachycal's example (rotation vectors); the same
    angles truly in degrees (each multiplied by 180/π) are read."""
    if origin == "figaroh_ur10":
        table, spec = reference(*FIGAROH, "ur10", "data", "calibration.csv"), SPECS / "ur10_columns.toml"
    else:
        table, spec = ROOT / "examples" / "tracker" / "table.csv", ROOT / "examples" / "tracker" / "columns.toml"
    columns = read_tracker_columns(spec)
    assert columns.angle_unit == "rad"
    as_rad = read_tracker_table(table, columns)
    stated_deg = dataclasses.replace(columns, angle_unit="deg")
    with pytest.raises(InputError, match=r"column '.*these look like radians \(set unit = 'rad'\)"):
        read_tracker_table(table, stated_deg)
    header, *rows = table.read_text().splitlines()
    at = [header.split(",").index(c) for c in columns.orientation]
    converted = []
    for row in rows:
        values = row.split(",")
        for k in at:
            values[k] = repr(float(np.degrees(float(values[k]))))
        converted.append(",".join(values))
    (tmp_path / "deg.csv").write_text("\n".join([header, *converted]) + "\n")
    as_deg = read_tracker_table(tmp_path / "deg.csv", stated_deg)
    assert np.allclose(as_deg.R_tracker_marker, as_rad.R_tracker_marker, atol=1e-12)


def _write(path: Path, rows: list[list[float]], header: list[str]) -> Path:
    path.write_text(",".join(header) + "\n" + "\n".join(",".join(map(str, r)) for r in rows) + "\n")
    return path


HEADER = ["j1", "j2", "x", "y", "z", "qx", "qy", "qz", "qw"]


def _columns(**kw: object) -> TrackerColumns:
    spec: dict[str, object] = dict(
        joints=("j1", "j2"),
        position=("x", "y", "z"),
        orientation=("qx", "qy", "qz", "qw"),
        orientation_kind="quaternion_xyzw",
    )
    spec.update(kw)
    return TrackerColumns(**spec)  # type: ignore[arg-type]


def _good_rows(n: int = 5) -> list[list[float]]:
    return [[0.1 * k, -0.2 * k, 0.5 + 0.1 * k, 0.2, 0.9 - 0.05 * k, 0.0, 0.0, 0.0, 1.0] for k in range(n)]


def test_reader_gives_si_units(tmp_path):
    rows = _good_rows()
    for r in rows:
        r[2:5] = [v * 1e3 for v in r[2:5]]
    table = read_tracker_table(_write(tmp_path / "t.csv", rows, HEADER), _columns(position_unit="mm"))
    assert isinstance(table, TrackerTable)
    assert np.allclose(table.p_tracker_marker[1], [0.6, 0.2, 0.85])
    assert table.rows == (2, 3, 4, 5, 6)


@pytest.mark.parametrize(
    ("case", "rows", "header", "kw", "expect"),
    [
        ("missing column", _good_rows(), [h if h != "z" else "zz" for h in HEADER], {}, ["'z'"]),
        ("NaN", [*_good_rows(4), [0.1, 0.2, "nan", 0.2, 0.3, 0, 0, 0, 1]], HEADER, {}, ["row 6", "'x'"]),
        (
            "millimetres stated as metres",
            [[0.1, 0.2, 512.0, 80.0, 300.0, 0, 0, 0, 1], *_good_rows(4)],
            HEADER,
            {},
            ["row 2", "'x'", "unit"],
        ),
        ("metres stated as millimetres", _good_rows(), HEADER, {"position_unit": "mm"}, ["'x'", "metres"]),
        ("too few rows", _good_rows(MIN_TRACKER_ROWS - 1), HEADER, {}, ["posture", f"at least {MIN_TRACKER_ROWS}"]),
        (
            "degrees for radians",
            [[95.0, 0.2, 0.5, 0.2, 0.3, 0, 0, 0, 1], *_good_rows(4)],
            HEADER,
            {},
            ["'j1'", "degrees"],
        ),
        ("quaternion not unit", [[0.1, 0.2, 0.5, 0.2, 0.3, 0, 0, 0, 2], *_good_rows(4)], HEADER, {}, ["'qx'", "norm"]),
    ],
)
def test_reader_refuses_in_one_line_naming_the_field(tmp_path, case, rows, header, kw, expect):
    path = _write(tmp_path / "t.csv", rows, header)
    with pytest.raises(InputError) as info:
        read_tracker_table(path, _columns(**kw))
    message = str(info.value)
    assert "\n" not in message and "t.csv" in message, case
    for word in expect:
        assert word.lower() in message.lower(), (case, message)


@pytest.mark.parametrize(
    ("text", "expect"),
    [
        ('format = "other"\n', "format"),
        (SPEC_HEAD + 'jionts = ["a"]\n', "jionts"),
        ('format = "brachycal-tracker-columns/1"\njoints = ["a"]\n', "position"),
        (
            SPEC_HEAD + POSITION + 'unit = "cm"\n',
            "position.unit",
        ),
        (
            SPEC_HEAD + POSITION + 'unit = "m"\n[orientation]\ncolumns = ["a1", "a2", "a3"]\nkind = "euler"\n',
            "orientation.kind",
        ),
    ],
)
def test_column_spec_refusals_name_the_key(tmp_path, text, expect):
    path = tmp_path / "c.toml"
    path.write_text(text)
    with pytest.raises(InputError, match=expect.replace(".", r"\.")) as refused:
        read_tracker_columns(path)
    # A TOML key is called a key, not a column (the table's columns are what the spec names).
    assert f"key '{expect.split('.')[0]}" in str(refused.value) and "column '" not in str(refused.value)


def test_table_placed_on_a_robot_refuses_a_joint_it_lacks_or_beyond_limits(panda, tmp_path):
    header = [*ARM, "x", "y", "z"]
    rows = [[0.1] * 3 + [-1.0] + [0.1] * 3 + [0.5, 0.2, 0.3 + 0.1 * k] for k in range(5)]
    columns = TrackerColumns(joints=ARM, position=("x", "y", "z"))
    table = read_tracker_table(_write(tmp_path / "t.csv", rows, header), columns)
    assert tracker_data(panda, table).Q.shape == (5, panda.nq)
    bad = read_tracker_table(_write(tmp_path / "b.csv", [[*r[:3], 1.0, *r[4:]] for r in rows], header), columns)
    with pytest.raises(InputError, match=r"panda_joint4.*limits|limits.*panda_joint4"):
        tracker_data(panda, bad)
    short = TrackerColumns(joints=ARM[:-1], position=("x", "y", "z"))
    with pytest.raises(InputError, match="panda_joint7"):
        tracker_data(panda, read_tracker_table(tmp_path / "t.csv", short), FLANGE)


# --- real robots (outside data) ----------------------------------------------------------------


@pytest.fixture(scope="module")
def ur10() -> TrackerData:
    robot = Robot.load(reference(*FIGAROH, "ur10", "urdf", "ur10_robot.urdf"))
    table = read_tracker_table(
        reference(*FIGAROH, "ur10", "data", "calibration.csv"), read_tracker_columns(SPECS / "ur10_columns.toml")
    )
    return tracker_data(robot, table, "wrist_3_link")


def test_ur10_figures_match_the_published_ones(ur10):
    """FIGAROH's UR10 (23 postures, 6-D): the frames alone fit to 2.06 mm per coordinate (an
    independent fit: 2.10 mm), leave-one-out 2.35 mm (2.38); frames + the joints' base set (30
    parameters) train to 1.727 mm (FIGAROH 0.2.x, 32 parameters: 1.727 mm) and predict held-out
    postures to 2.28 mm (independent check: 2.35 mm). The difference is within its standard
    error: the supported model is the frames alone."""
    result = identify_from_tracker(ur10, models=("frames", "joints"))
    frames, joints = result.scores
    assert 2.0 < frames.training_position_mm < 2.12
    assert 2.25 < frames.loo_position_mm < 2.45
    assert 1.70 < joints.training_position_mm < 1.75
    assert 2.15 < joints.loo_position_mm < 2.40
    assert joints.parameters == 30
    assert frames.loo_orientation_deg is not None and 0.25 < frames.loo_orientation_deg < 0.45
    assert result.chosen == "frames" and "joints not supported" in result.reason


def test_cli_writes_a_urdf_that_reproduces_the_fit(ur10, tmp_path):
    """``robot identify tracker`` on FIGAROH's UR10 with the joints model: the written URDF with the
    written frames predicts every measured pose as the fit did (to 1e-9 m), and the JSON holds the
    figures of both models scored, held out first."""
    root = reference(*FIGAROH, "ur10")
    out = tmp_path / "out"
    code = main(
        [
            "robot", "identify", "tracker", str(root / "data" / "calibration.csv"),
            "--columns", str(SPECS / "ur10_columns.toml"), "--urdf", str(root / "urdf" / "ur10_robot.urdf"),
            "--flange", "wrist_3_link", "--model", "joints", "--out", str(out),
        ]
    )  # fmt: skip
    assert code == 0
    document = json.loads((out / "identification.json").read_text())
    assert document["chosen"] == "joints" and set(document["models"]) == {"frames", "joints"}
    assert 2.15 < document["models"]["joints"]["loo_position_mm_per_coordinate"] < 2.40
    robot = Robot.load(out / "robot.urdf")
    T = np.array(document["T_tracker_base"]) @ robot.fk("wrist_3_link", ur10.Q) @ np.array(document["T_flange_marker"])
    fit = fit_tracker(ur10, "joints")
    assert np.max(np.abs(T[:, :3, 3] - ur10.p - fit.position_residuals)) < 1e-9


@pytest.mark.slow
def test_tiago_figures_match_the_published_ones():
    """FIGAROH's TIAGo (34 postures, a Qualisys 3-D hand marker, torso lift + 7 arm joints): the
    frames alone fit to 2.29 mm per coordinate and predict held-out postures to 2.53 mm (both as
    published); the joints' base set predicts them to 2.42 mm, better by more than the standard
    error, and is returned."""
    robot = Robot.load(reference(*FIGAROH, "tiago", "urdf", "tiago_48_schunk.urdf"))
    table = read_tracker_table(
        reference(*FIGAROH, "tiago", "data", "calibration", "mocap", "qualysis_base_hand_calibration.csv"),
        read_tracker_columns(SPECS / "tiago_columns.toml"),
    )
    result = identify_from_tracker(tracker_data(robot, table, "arm_7_link"), models=("frames", "joints"))
    frames, joints = result.scores
    assert 2.25 < frames.training_position_mm < 2.33
    assert 2.48 < frames.loo_position_mm < 2.58
    assert 2.30 < joints.loo_position_mm < 2.50
    assert result.chosen == "joints"
