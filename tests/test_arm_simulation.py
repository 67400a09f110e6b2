"""Simulated recordings of any arm (brachycal.simulation.arm_touches): touches of fixed points and a tracker.

Without noise they are exact: the physical arm puts its tip on each point to round-off, and the
identification (touches or tracker) recovers the physical arm to nanometres in forward-kinematics
terms. With noise, the stated SD is what the recordings carry.
"""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from brachycal.calibration.robot.arm_fit import ParameterSelection, flange_points
from brachycal.calibration.robot.touches import TouchModel, TouchPlace, configurations, identify_touches, read_places
from brachycal.calibration.robot.tracker import TrackerData, fit_tracker, select_parameters
from brachycal.data.formats.tracker_table import read_tracker_columns, read_tracker_table
from brachycal.model.description import load_robot
from brachycal.se3 import make_transform
from brachycal.simulation import (
    arm_errors,
    simulate_touches,
    simulate_tracker,
    tracker_columns_text,
    write_touch_places,
    write_tracker_table,
)

FLANGE = "panda_link8"
TIP = np.array([0.4e-3, -0.3e-3, 0.1042])
PLACES = {
    "a": np.array([[0.45, -0.2, 0.15], [0.50, -0.2, 0.15]]),
    "b": np.array([[0.5, 0.25, 0.3], [0.55, 0.25, 0.3]]),
    "c": np.array([[0.35, 0.0, 0.45], [0.40, 0.0, 0.45]]),
}
T_TRACKER_BASE = make_transform(Rotation.from_rotvec([0.1, -0.2, 2.5]).as_matrix(), [2.1, 0.4, -0.3])
T_FLANGE_MARKER = make_transform(Rotation.from_rotvec([0.3, 0.2, -0.1]).as_matrix(), [0.03, -0.02, 0.08])


@pytest.fixture(scope="module")
def panda():
    return load_robot("panda")


@pytest.fixture(scope="module")
def ur10():
    return load_robot("ur10")


def _places(recording) -> list[TouchPlace]:
    return [TouchPlace(name, tables, {(0, 1): 0.05}) for name, tables in recording.touches.items()]


def test_arm_errors_touch_only_the_joints_to_the_flange(panda, ur10):
    errors = arm_errors(ur10, "wrist_2_link", 1e-3, 1e-3, np.random.default_rng(0))
    moved = [name for name, e in zip(ur10.joint_names, errors, strict=True) if np.any(e)]
    assert moved == list(ur10.joint_names[:5])  # wrist_3 is beyond wrist_2_link
    assert arm_errors(panda, FLANGE, 1e-3, 1e-3, np.random.default_rng(0)).shape == (panda.nq, 6)


def test_exact_touches_put_the_physical_tip_on_each_point(panda):
    corrections = arm_errors(panda, FLANGE, 3e-4, np.radians(0.05), np.random.default_rng(1))
    recording = simulate_touches(panda, FLANGE, TIP, PLACES, corrections=corrections, touches=5, seed=2)
    for name, tables in recording.touches.items():
        for point, Q in zip(PLACES[name], tables, strict=True):
            assert Q.shape == (5, panda.nq) and all(panda.within_limits(q) for q in Q)
            tips = flange_points(recording.physical, Q, FLANGE, TIP).p
            assert np.abs(tips - point).max() < 1e-12
    # not on the nominal arm: the corrections matter (tenths of a millimetre and more)
    tips = flange_points(panda, recording.touches["a"][0], FLANGE, TIP).p
    assert np.abs(tips - PLACES["a"][0]).max() > 1e-4


def test_exact_touches_identify_the_physical_arm_to_nanometres(panda):
    """The truth on the corrections touches can see (the base set: the first joint's origin is
    absorbed by the points); identified without a prior, the arm's tip agrees with the physical
    one's everywhere in the workspace."""
    shape = simulate_touches(panda, FLANGE, TIP, PLACES, corrections=np.zeros((panda.nq, 6)), touches=6, seed=3)
    model = TouchModel(tuple(_places(shape)), FLANGE)
    y = np.concatenate([TIP, *(p.ravel() for p in PLACES.values())])
    evaluation = model.evaluate(panda, y)
    base = ParameterSelection.chain(panda, FLANGE).base_set(evaluation.J_c, evaluation.J_y, np.ones(6 * panda.nq))
    rng = np.random.default_rng(4)
    truth = base.expand(rng.normal(0, 1, base.size) * np.where(base.index % 6 < 3, 3e-4, 1e-3))
    recording = simulate_touches(panda, FLANGE, TIP, PLACES, corrections=truth, touches=6, seed=5)
    result = identify_touches(
        panda,
        _places(recording),
        FLANGE,
        None,
        tip=[0, 0, 0.1034],
        selection=base,
        touch_sd_m=1e-6,
        distance_sd_m=1e-6,
        estimate_touch_noise=False,
    )
    Q = rng.uniform(panda.lower, panda.upper, (50, panda.nq))
    identified = flange_points(result.robot(panda), Q, FLANGE, result.tip).p
    assert np.abs(identified - flange_points(recording.physical, Q, FLANGE, TIP).p).max() < 1e-9


def test_touch_noise_is_the_stated_sd_at_the_tip(panda):
    sd = 1e-4
    corrections = np.zeros((panda.nq, 6))
    recording = simulate_touches(panda, FLANGE, TIP, {"a": PLACES["a"][:1]}, corrections=corrections, touches=150)
    errors = flange_points(panda, recording.touches["a"][0], FLANGE, TIP).p - PLACES["a"][0]
    assert np.abs(errors).max() < 1e-12  # noise 0 by default
    noisy = simulate_touches(
        panda, FLANGE, TIP, {"a": PLACES["a"][:1]}, corrections=corrections, touches=150, noise_sd_m=sd
    )
    errors = flange_points(panda, noisy.touches["a"][0], FLANGE, TIP).p - PLACES["a"][0]
    # 450 draws: the SD's sampling error is ~3.3 %; the joint noise is the least motion giving the
    # tip's error, to first order (its curvature adds ~1e-4 relative at 0.1 mm)
    assert np.std(errors, axis=0) == pytest.approx([sd] * 3, rel=0.15)
    assert np.std(errors) == pytest.approx(sd, rel=0.1)


def test_written_places_read_back_as_the_recording(panda, tmp_path):
    corrections = arm_errors(panda, FLANGE, 3e-4, np.radians(0.05), np.random.default_rng(6))
    recording = simulate_touches(panda, FLANGE, TIP, PLACES, corrections=corrections, touches=3, noise_sd_m=5e-5)
    folders = write_touch_places(tmp_path, recording)
    assert [f.name for f in folders] == list(PLACES)
    for place, name in zip(read_places(panda, FLANGE, folders), PLACES, strict=True):
        assert place.name == name
        for got, want in zip(place.touches, recording.touches[name], strict=True):
            assert np.array_equal(got, want)  # full precision: the files hold what was simulated


def test_exact_tracker_data_identify_the_physical_arm_to_nanometres(ur10):
    """A UR10 corrected on the joints model's base set, seen exactly by a 6-D tracker in an unknown
    frame: the fit predicts the marker at unseen postures to 1e-9 m."""
    shape = simulate_tracker(ur10, "tool0", T_TRACKER_BASE, T_FLANGE_MARKER, corrections=np.zeros((ur10.nq, 6)))
    base = select_parameters(TrackerData(ur10, "tool0", shape.Q, shape.p, shape.R), "joints", None)
    truth = base.expand(np.random.default_rng(7).normal(0, 1e-3, base.size))
    recording = simulate_tracker(ur10, "tool0", T_TRACKER_BASE, T_FLANGE_MARKER, corrections=truth, seed=8)
    data = TrackerData(ur10, "tool0", recording.Q, recording.p, recording.R)
    fit = fit_tracker(data, "joints", None, estimate_noise=False)
    Q = np.random.default_rng(9).uniform(-3, 3, (20, ur10.nq))
    predicted = fit.T_tracker_base @ fit.robot(ur10).fk("tool0", Q) @ fit.T_flange_marker
    true = T_TRACKER_BASE @ recording.physical.fk("tool0", Q) @ T_FLANGE_MARKER
    assert np.abs(predicted[:, :3, 3] - true[:, :3, 3]).max() < 1e-9
    assert np.abs(predicted[:, :3, :3] - true[:, :3, :3]).max() < 1e-9


def test_tracker_noise_is_the_stated_sd(ur10):
    sd_m, sd_rad = 2e-4, np.radians(0.1)
    corrections = np.zeros((ur10.nq, 6))
    exact = simulate_tracker(ur10, "tool0", T_TRACKER_BASE, T_FLANGE_MARKER, corrections=corrections, postures=300)
    noisy = simulate_tracker(
        ur10,
        "tool0",
        T_TRACKER_BASE,
        T_FLANGE_MARKER,
        corrections=corrections,
        postures=300,
        noise_sd_m=sd_m,
        noise_sd_rad=sd_rad,
    )
    assert np.array_equal(exact.Q, noisy.Q)  # the same postures: the noise streams come after them
    # 900 draws each: the SD's sampling error is ~2.4 %
    assert np.std(noisy.p - exact.p) == pytest.approx(sd_m, rel=0.08)
    turns = Rotation.from_matrix(noisy.R @ np.swapaxes(exact.R, 1, 2)).as_rotvec()
    assert np.std(turns) == pytest.approx(sd_rad, rel=0.08)


def test_written_tracker_table_reads_back_with_its_column_spec(ur10, tmp_path):
    corrections = arm_errors(ur10, "tool0", 5e-4, np.radians(0.05), np.random.default_rng(10))
    recording = simulate_tracker(ur10, "tool0", T_TRACKER_BASE, T_FLANGE_MARKER, corrections=corrections, postures=6)
    write_tracker_table(tmp_path / "table.csv", recording)
    (tmp_path / "columns.toml").write_text(tracker_columns_text(recording.joints, comment="a\nb"))
    table = read_tracker_table(tmp_path / "table.csv", read_tracker_columns(tmp_path / "columns.toml"))
    assert table.joint_names == recording.joints
    assert np.array_equal(configurations(ur10, "tool0", table.Q), recording.Q)
    assert np.allclose(table.p_tracker_marker, recording.p, rtol=0, atol=1e-12)  # written in mm
    assert table.R_tracker_marker is not None
    assert np.allclose(table.R_tracker_marker, recording.R, rtol=0, atol=1e-12)
