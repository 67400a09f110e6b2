"""CSV joint logs: any column order, interpolation, and every refusal naming file, row and column."""

from __future__ import annotations

import warnings
from pathlib import Path

import numpy as np
import pytest
from conftest import random_configurations

from brachycal import InputError
from brachycal.data import read_csv_log, read_joint_log
from brachycal.data.joint_log import LIMIT_TOLERANCE_RAD, configurations_from_columns
from brachycal.errors import BrachycalWarning


def write_log(path: Path, names: list[str], time: np.ndarray, values: np.ndarray) -> Path:
    lines = [",".join(["time", *names])]
    lines += [",".join([repr(float(t)), *(repr(float(x)) for x in row)]) for t, row in zip(time, values, strict=True)]
    path.write_text("\n".join(lines) + "\n")
    return path


@pytest.fixture
def log_data(robot):
    Q = random_configurations(robot, 20, seed=20) * 0.5
    return np.arange(20) * 0.1 + 100.0, Q


@pytest.fixture
def good_log(tmp_path, robot, log_data):
    time, Q = log_data
    return write_log(tmp_path / "log.csv", list(robot.joint_names), time, Q)


def test_columns_in_any_order_and_extra_columns(tmp_path, robot, log_data):
    time, Q = log_data
    names = list(robot.joint_names)
    order = np.random.default_rng(0).permutation(len(names))
    values = np.column_stack([Q[:, order], np.full(len(time), 42.0), Q[:, 0]])
    path = write_log(tmp_path / "shuffled.csv", [names[k] for k in order] + ["gripper", "torso_joint_b2"], time, values)
    log = read_csv_log(path, robot)
    assert log.joint_names == robot.joint_names
    assert np.array_equal(log.q, Q)
    assert np.array_equal(log.time, time)
    assert log.rows.tolist() == list(range(2, 22))


def test_interpolates_to_requested_times(tmp_path, robot):
    time = np.array([0.0, 1.0, 3.0])
    Q = np.outer([0.0, 0.1, 0.3], np.ones(robot.nq))  # linear in time
    log = read_csv_log(write_log(tmp_path / "lin.csv", list(robot.joint_names), time, Q), robot)
    assert np.allclose(log.interpolate([0.5, 2.0, 3.0]), np.outer([0.05, 0.2, 0.3], np.ones(robot.nq)), atol=1e-15)
    with pytest.raises(InputError, match=r"lin\.csv: requested time 3\.500000 s is outside the log's span"):
        log.interpolate([3.5])


def test_dispatches_csv_and_refuses_missing_path(good_log, robot, tmp_path):
    assert len(read_joint_log(good_log, robot)) == 20
    with pytest.raises(InputError, match="no such file"):
        read_joint_log(tmp_path / "nope.csv", robot)


def refusal(path: Path, robot) -> str:
    with pytest.raises(InputError) as info:
        read_csv_log(path, robot)
    message = str(info.value)
    assert "\n" not in message and message.startswith(str(path))
    return message


def edit(path: Path, row: int, column: str, value: str) -> Path:
    lines = path.read_text().splitlines()
    header = lines[0].split(",")
    fields = lines[row - 1].split(",")
    fields[header.index(column)] = value
    lines[row - 1] = ",".join(fields)
    path.write_text("\n".join(lines) + "\n")
    return path


def test_missing_joint(tmp_path, robot, log_data):
    time, Q = log_data
    names = list(robot.joint_names)
    path = write_log(tmp_path / "m.csv", names[:5] + names[6:], time, np.delete(Q, 5, axis=1))
    assert "missing joint(s) arm_left_joint_5_r" in refusal(path, robot)


def test_nan_value(good_log, robot):
    assert refusal(edit(good_log, 7, "arm_right_joint_2_l", "nan"), robot).endswith(
        "row 7, column 'arm_right_joint_2_l': value is not a finite number, got 'nan'"
    )


def test_not_a_number(good_log, robot):
    message = refusal(edit(good_log, 4, "arm_left_joint_1_s", "0.1x"), robot)
    assert message.endswith("row 4, column 'arm_left_joint_1_s': '0.1x' is not a number")


def test_empty_field(good_log, robot):
    assert "row 3, column 'torso_joint_b1': '' is not a number" in refusal(
        edit(good_log, 3, "torso_joint_b1", ""), robot
    )


def test_non_increasing_time(good_log, robot):
    message = refusal(edit(good_log, 9, "time", "100.6"), robot)
    assert "row 9, column 'time': time 100.6 does not increase (previous 100.6)" in message


def test_values_outside_joint_limits(good_log, robot):
    message = refusal(edit(good_log, 5, "arm_left_joint_2_l", "2.5"), robot)
    assert (
        "row 5, column 'arm_left_joint_2_l': value 2.500000 rad is outside the joint limits [-1.919862, 1.919862]"
        in message
    )


def test_readings_within_the_encoder_tolerance_of_a_limit_are_kept_with_one_warning(good_log, robot):
    # 1.919869 rad read against the limit 1.9198622 (6.8e-6 rad over, encoder noise
    # at a pose planned on the limit). Kept as read; one warning for the file names the first
    # reading and counts them all.
    edit(good_log, 5, "arm_left_joint_2_l", "1.919869")
    edit(
        good_log,
        9,
        "arm_right_joint_4_u",
        repr(float(robot.lower[robot.joint_names.index("arm_right_joint_4_u")]) - 9e-4),
    )
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        log = read_csv_log(good_log, robot)
    assert [w.category for w in caught] == [BrachycalWarning]
    message = str(caught[0].message)
    assert message.startswith(
        f"{good_log}, row 5, column 'arm_left_joint_2_l': value 1.919869 rad is 6.8e-06 rad beyond"
    )
    assert "2 reading(s)" in message and "kept as read" in message and "\n" not in message
    assert log.q[3, robot.joint_names.index("arm_left_joint_2_l")] == 1.919869  # what the encoder said, not clipped


def test_readings_beyond_the_encoder_tolerance_are_refused(good_log, robot):
    k = robot.joint_names.index("arm_left_joint_2_l")
    over = robot.upper[k] + LIMIT_TOLERANCE_RAD + 1e-5  # just past the stated tolerance
    message = refusal(edit(good_log, 5, "arm_left_joint_2_l", repr(float(over))), robot)
    assert "row 5, column 'arm_left_joint_2_l'" in message and "more than the 0.001 rad allowed" in message


def test_a_joint_listed_twice_is_refused_by_the_validator_too(robot):
    # Readers other than the CSV one (bags, sessions built in code) reach the same check.
    names = [*robot.joint_names, "arm_left_joint_3_e"]
    with pytest.raises(InputError, match=r"src, column 'arm_left_joint_3_e': joint listed twice \(columns 4 and 16\)"):
        configurations_from_columns(robot, names, np.zeros((2, len(names))), source="src")


def test_values_that_look_like_degrees(tmp_path, robot, log_data):
    time, Q = log_data
    path = write_log(tmp_path / "deg.csv", list(robot.joint_names), time, np.degrees(Q))
    assert "looks like degrees" in refusal(path, robot)


def test_mimic_joint_must_mirror_its_leader(tmp_path, robot, log_data):
    time, Q = log_data
    b2 = Q[:, 0].copy()
    b2[11] += 0.1
    path = write_log(tmp_path / "b2.csv", [*robot.joint_names, "torso_joint_b2"], time, np.column_stack([Q, b2]))
    assert "row 13, column 'torso_joint_b2': torso_joint_b2 must equal torso_joint_b1" in refusal(path, robot)


def test_ragged_row(good_log, robot):
    lines = good_log.read_text().splitlines()
    lines[5] += ",1.0"
    good_log.write_text("\n".join(lines) + "\n")
    assert "row 6: has 17 fields, the header has 16" in refusal(good_log, robot)


def test_duplicate_column(tmp_path, robot, log_data):
    time, Q = log_data
    names = list(robot.joint_names)
    path = write_log(tmp_path / "dup.csv", [*names, names[2]], time, np.column_stack([Q, Q[:, 2]]))
    assert f"row 1, column '{names[2]}': column appears twice" in refusal(path, robot)


def test_no_time_column_and_empty_files(tmp_path, robot):
    (tmp_path / "nt.csv").write_text("t," + ",".join(robot.joint_names) + "\n")
    assert "no 'time' column" in refusal(tmp_path / "nt.csv", robot)
    (tmp_path / "empty.csv").write_text("")
    assert "empty file" in refusal(tmp_path / "empty.csv", robot)
    (tmp_path / "header_only.csv").write_text("time," + ",".join(robot.joint_names) + "\n")
    assert "the log has no samples" in refusal(tmp_path / "header_only.csv", robot)


def test_binary_garbage(tmp_path, robot):
    (tmp_path / "bin.csv").write_bytes(b"\xff\xfe\x00garbage")
    assert "not a readable CSV file" in refusal(tmp_path / "bin.csv", robot)


def test_blank_lines_keep_true_row_numbers(good_log, robot):
    lines = good_log.read_text().splitlines()
    lines.insert(3, "")
    good_log.write_text("\n".join(lines) + "\n")
    log = read_csv_log(good_log, robot)
    assert log.rows[:4].tolist() == [2, 3, 5, 6]


def test_prismatic_joints_get_a_tolerance_in_metres():
    # 1 µm beyond a linear axis' limit is encoder noise; the 1e-3 of a revolute joint would be 1 mm.
    from brachycal.model import Robot

    urdf = """<robot name="slide"><link name="a"/><link name="b"/>
      <joint name="slide" type="prismatic"><parent link="a"/><child link="b"/><axis xyz="0 0 1"/>
        <limit lower="0" upper="0.1" effort="1" velocity="1"/></joint></robot>"""
    slide = Robot(urdf, base_dir=".")
    with pytest.warns(BrachycalWarning, match=r"row 1, column 'slide': value 0\.100000500 m is 5e-07 m beyond"):
        configurations_from_columns(slide, ["slide"], [[0.1 + 5e-7]], source="s.csv")
    with pytest.raises(InputError, match=r"by 2e-06 m \(more than the 1e-06 m allowed for encoder noise\)"):
        configurations_from_columns(slide, ["slide"], [[0.1 + 2e-6]], source="s.csv")
