"""``brachycal fk`` on long logs: read, checked, computed and written in blocks, with the same
poses, the same text and the same refusals as reading the log whole.

Block sizes are made small here (a few hundred bytes or messages) so that short logs cross many
block boundaries; ``benchmarks/fk_scale.py`` measures the real sizes on long logs.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from conftest import random_configurations
from hostile import Case, check_refusal, run_cli

from brachycal.data import read_csv_log, read_pose_table, write_bag_log
from brachycal.data.formats import bags as bags_module
from brachycal.data.formats import csv_log as csv_module
from brachycal.data.formats.bags import bag_log_blocks, read_bag_log
from brachycal.data.formats.csv_log import csv_log_blocks
from brachycal.data.pose_table import PoseTableWriter, continuous_signs, format_fixed
from brachycal.se3 import make_transform

FRAMES = ["needle_tip", "probe_tip"]


def write_log(path: Path, names, time: np.ndarray, values: np.ndarray) -> Path:
    """A CSV log at full precision (``repr``: the numbers read back are the numbers written)."""
    lines = [",".join(["time", *names])]
    lines += [",".join(repr(float(v)) for v in [t, *row]) for t, row in zip(time, values, strict=True)]
    path.write_text("\n".join(lines) + "\n")
    return path


@pytest.fixture
def long_log(tmp_path, robot):
    """103 samples (a prime: no block size divides it), ~300 bytes a row."""
    Q = random_configurations(robot, 103, seed=13) * 0.9
    time = 1.7e9 + np.arange(103) * 0.004
    return write_log(tmp_path / "log.csv", list(robot.joint_names), time, Q), time, Q


@pytest.fixture
def small_blocks(monkeypatch):
    """Blocks of ~1,000 bytes (3 rows) and of 7 bag messages."""
    monkeypatch.setattr(csv_module, "BLOCK_BYTES", 1_000)
    monkeypatch.setattr(bags_module, "BLOCK_MESSAGES", 7)


def test_blocks_cover_the_log_with_absolute_rows(long_log, robot):
    path, time, Q = long_log
    blocks = list(csv_log_blocks(path, robot, block_bytes=1_000))
    assert len(blocks) > 30  # many boundaries, the last block shorter than the others
    rows = np.concatenate([b.rows for b, _ in blocks])
    assert rows.tolist() == list(range(2, 105))  # header = row 1
    assert np.array_equal(np.concatenate([b.time for b, _ in blocks]), time)  # repr round-trips exactly
    assert np.array_equal(np.concatenate([q for _, q in blocks]), Q)


def test_streamed_pose_table_is_the_whole_logs_to_the_byte_and_the_pinocchio_loops(
    tmp_path, long_log, robot, small_blocks
):
    path, time, _ = long_log
    streamed = tmp_path / "streamed.csv"
    assert run_cli(["fk", str(path), "--frames", ",".join(FRAMES), "--out", str(streamed), "--quiet"]).code == 0
    # the table of the whole log in one block, written by Python's own formatting
    log = read_csv_log(path, robot)
    poses = robot.fk_frames_loop(FRAMES, log.q)  # Pinocchio, one configuration at a time
    from brachycal.se3 import to_position_quaternion

    position, quat = to_position_quaternion(poses)
    lines = ["time,frame,x,y,z,qx,qy,qz,qw"]
    for i, t in enumerate(time):
        for k, frame in enumerate(FRAMES):
            x, y, z = position[k, i]
            qx, qy, qz, qw = quat[k, i]
            lines.append(f"{t:.9f},{frame},{x:.9f},{y:.9f},{z:.9f},{qx:.12f},{qy:.12f},{qz:.12f},{qw:.12f}")
    want = "\n".join(lines) + "\n"
    got = streamed.read_text()
    if got != want:  # the batch path and Pinocchio agree to 1e-12 m; a 9th decimal may round apart
        a = np.loadtxt(streamed, delimiter=",", skiprows=1, usecols=(0, 2, 3, 4, 5, 6, 7, 8))
        b = np.loadtxt(want.splitlines()[1:], delimiter=",", usecols=(0, 2, 3, 4, 5, 6, 7, 8))
        # one unit of the last printed decimal (1e-9 m) is the most a 1e-12 m difference can move it
        assert np.abs(a - b).max() <= 1.0000001e-9


def test_a_bad_field_in_a_later_block_is_named_with_its_file_row_and_column(tmp_path, robot, long_log, small_blocks):
    path, _, _ = long_log
    lines = path.read_text().splitlines()
    fields = lines[79].split(",")  # file row 80, far past the first block
    fields[5] = "1.2.3"
    lines[79] = ",".join(fields)
    path.write_text("\n".join(lines) + "\n")
    column = lines[0].split(",")[5]
    with pytest.raises(csv_module.InputError, match=rf"log\.csv, row 80, column '{column}': '1\.2\.3' is not a number"):
        read_csv_log(path, robot)
    outcome = run_cli(["fk", str(path), "--frames", "needle_tip", "--out", str(tmp_path / "p.csv"), "--quiet"])
    assert outcome.code == 2 and "row 80" in outcome.err and not (tmp_path / "p.csv").exists()


@pytest.mark.parametrize("defect", ["time-backwards-at-a-boundary", "blank-lines", "quoted-field"])
def test_rows_stay_absolute_whatever_the_fast_reader_hands_back(tmp_path, robot, long_log, defect):
    path, time, _ = long_log
    lines = path.read_text().splitlines()
    if defect == "time-backwards-at-a-boundary":
        lines[60] = lines[60].replace(repr(float(time[59])), repr(float(time[57])), 1)  # row 61
        path.write_text("\n".join(lines) + "\n")
        for block_bytes in (1_000, 1 << 20):  # the step inside a block and across a boundary alike
            with pytest.raises(csv_module.InputError, match=r"log\.csv, row 61, column 'time': .* does not increase"):
                list(csv_log_blocks(path, robot, block_bytes=block_bytes))
        return
    if defect == "blank-lines":
        lines[40:40] = ["", "  "]  # rows 41, 42 blank: the sample after them is row 43
    else:
        fields = lines[40].split(",")
        fields[3] = f'"{fields[3]}"'  # a quoted number: the rest of the file goes through the row scan
        lines[40] = ",".join(fields)
    path.write_text("\n".join(lines) + "\n")
    blocks = list(csv_log_blocks(path, robot, block_bytes=1_000))
    rows = np.concatenate([b.rows for b, _ in blocks]).tolist()
    want = list(range(2, 105)) if defect == "quoted-field" else [*range(2, 41), *range(43, 107)]
    assert rows == want
    assert np.array_equal(np.concatenate([b.time for b, _ in blocks]), time)


REFUSALS = [
    Case(
        "fk-bad-number-in-a-later-block",
        ["fk", "{tmp}/log.csv", "--frames", "needle_tip", "--out", "{tmp}/poses.csv", "--quiet"],
        ("log.csv", "row 90", "column 'arm_left_joint_3_e'", "'x' is not a number"),
    ),
]


@pytest.mark.parametrize("case", REFUSALS, ids=lambda c: c.id)
def test_refusals_in_a_later_block(case, tmp_path, robot, monkeypatch):
    monkeypatch.setattr(csv_module, "BLOCK_BYTES", 1_000)
    Q = random_configurations(robot, 103, seed=3) * 0.9
    names = list(robot.joint_names)
    path = write_log(tmp_path / "log.csv", names, np.arange(103) * 0.01, Q)
    lines = path.read_text().splitlines()
    fields = lines[89].split(",")
    fields[1 + names.index("arm_left_joint_3_e")] = "x"
    lines[89] = ",".join(fields)
    path.write_text("\n".join(lines) + "\n")
    check_refusal(case, tmp_path)


def test_times_are_interpolated_across_blocks_as_in_the_whole_log(tmp_path, robot, long_log, small_blocks):
    path, time, _ = long_log
    rng = np.random.default_rng(5)
    requested = np.concatenate([rng.uniform(time[0], time[-1], 40), time[[0, 3, 50, -1]]])  # unsorted, knots too
    times_csv = tmp_path / "times.csv"
    times_csv.write_text("time\n" + "\n".join(repr(float(t)) for t in requested) + "\n")
    out = tmp_path / "p.csv"
    argv = ["fk", str(path), "--frames", "needle_tip", "--out", str(out), "--times", str(times_csv), "--quiet"]
    assert run_cli(argv).code == 0
    t, _, T = read_pose_table(out)
    want = robot.fk("needle_tip", read_csv_log(path, robot).interpolate(requested))
    assert np.allclose(t, requested, rtol=0, atol=5e-10)  # 9 printed decimals
    # positions printed to 9 decimals: half a unit of the last one, plus interpolation rounding (1e-15)
    assert np.abs(T[:, :3, 3] - want[:, :3, 3]).max() <= 5.1e-10


def test_format_fixed_is_pythons_formatting():
    rng = np.random.default_rng(0)
    values = np.concatenate(
        [
            rng.normal(size=20_000),
            rng.uniform(-1, 1, 20_000) * 10.0 ** rng.uniform(-14, 12, 20_000),
            [0.0, -0.0, 0.5e-9, 1.5e-9, 2.5e-9, -2.5e-9, 0.9999999995, 9.9999999995, -1e-13, 1.7e9 + 0.0005],
            [2.0**53, 1e20, -1e300, np.nan, np.inf, -np.inf, 0.49999999999999994],
            np.round(rng.normal(size=5_000), 9) + rng.choice([-0.5e-9, 0.5e-9], 5_000),  # near rounding ties
        ]
    )
    for decimals in (9, 12):
        text = format_fixed(values, decimals)
        got = [bytes(row[row != 0]).decode() for row in text]
        assert got == [f"%.{decimals}f" % v for v in values]


def rotations_about_z(angles: np.ndarray) -> np.ndarray:
    c, s = np.cos(angles), np.sin(angles)
    R = np.zeros((len(angles), 3, 3))
    R[:, 0, 0], R[:, 0, 1], R[:, 1, 0], R[:, 1, 1], R[:, 2, 2] = c, -s, s, c, 1.0
    return make_transform(R, np.zeros((len(angles), 3)))


@pytest.mark.parametrize("continuity", [False, True])
def test_quaternion_continuity_through_qw_zero_across_blocks(tmp_path, continuity):
    """A turn about z from 0 to 1.9π: qw = cos(θ/2) passes 0 at θ = π, between blocks 2 and 3."""
    angles = np.linspace(0.0, 1.9 * np.pi, 60)
    T = rotations_about_z(angles)
    out = tmp_path / "p.csv"
    with out.open("w", newline="") as handle:
        writer = PoseTableWriter(handle, ["tool"], continuity=continuity)
        for start in range(0, 60, 16):  # the flip (sample 31 of 60) falls inside the second block; 16, 32 are edges
            writer.write(angles[start : start + 16], T[None, start : start + 16])
    quat = np.loadtxt(out, delimiter=",", skiprows=1, usecols=(5, 6, 7, 8))
    assert np.allclose(np.abs(quat[:, 2]), np.abs(np.sin(angles / 2)), atol=1e-12)  # the same rotations
    dots = np.einsum("ij,ij->i", quat[1:], quat[:-1])
    if continuity:
        assert (dots > 0).all()  # no jump from q to -q
        assert quat[0, 3] >= 0 and quat[-1, 3] < 0  # the first row canonical, the last one followed on
    else:
        assert (quat[:, 3] >= 0).all() and (dots < 0).sum() == 1  # canonical: one jump where qw crosses 0


def test_continuous_signs_carries_the_previous_blocks_last_quaternion():
    q = np.array([[0.0, 0.0, 1.0, 0.1], [0.0, 0.0, 1.0, 0.2]]) / np.hypot(1.0, [[0.1], [0.2]])
    assert np.array_equal(continuous_signs(q, previous=-q[0]), -q)
    assert np.array_equal(continuous_signs(q, previous=None), q)


def test_fk_quaternion_continuity_option_through_a_wrist_turn(tmp_path, robot):
    """The right wrist (joint 7_t) turns from −3.1 to 3.1 rad: the needle tip's frame turns by
    almost 2π, so its canonical quaternion must jump once; with the option it does not."""
    n = 200
    Q = np.tile(random_configurations(robot, 1, seed=4) * 0.5, (n, 1))
    Q[:, robot.joint_names.index("arm_right_joint_7_t")] = np.linspace(-3.1, 3.1, n)
    path = write_log(tmp_path / "log.csv", list(robot.joint_names), np.arange(n) * 0.01, Q)
    signs = {}
    for option in ([], ["--quaternion-continuity"]):
        out = tmp_path / f"p{len(option)}.csv"
        assert run_cli(["fk", str(path), "--frames", "needle_tip", "--out", str(out), "--quiet", *option]).code == 0
        quat = np.loadtxt(out, delimiter=",", skiprows=1, usecols=(5, 6, 7, 8))
        signs[bool(option)] = np.einsum("ij,ij->i", quat[1:], quat[:-1])
        if not option:
            assert (quat[:, 3] >= 0).all()
    assert (signs[False] < 0).sum() >= 1 and (signs[True] > 0).all()


@pytest.mark.parametrize("kind", ["ros1", "ros2-sqlite3", "ros2-mcap"])
def test_bags_stream_to_the_same_table_as_the_csv_log(tmp_path, robot, kind, small_blocks):
    Q = random_configurations(robot, 50, seed=7) * 0.9
    time = 1.7e9 + np.arange(50) * 0.004
    bag = tmp_path / ("log.bag" if kind == "ros1" else "log")
    write_bag_log(bag, time, Q, robot.joint_names, ros=1 if kind == "ros1" else 2, storage=kind.split("-")[-1])
    blocks = list(bag_log_blocks(bag, robot, block_messages=7))
    assert [len(b.rows) for b, _ in blocks] == [7] * 7 + [1]
    assert np.array_equal(np.concatenate([q for _, q in blocks]), Q)  # positions cut from the raw bytes, exact
    log = read_bag_log(bag, robot)
    assert log.rows.tolist() == list(range(1, 51)) and log.row_label == "message"
    assert np.allclose(log.time, time, rtol=0, atol=1e-6)  # stamps hold whole nanoseconds
    csv = write_log(tmp_path / "log.csv", list(robot.joint_names), log.time, Q)
    for source, out in ((bag, tmp_path / "bag.csv"), (csv, tmp_path / "csv.csv")):
        assert run_cli(["fk", str(source), "--frames", ",".join(FRAMES), "--out", str(out), "--quiet"]).code == 0
    assert (tmp_path / "bag.csv").read_bytes() == (tmp_path / "csv.csv").read_bytes()


def test_quaternions_are_scipys_including_the_sign_convention(robot):
    from scipy.spatial.transform import Rotation

    from brachycal.data.pose_table import quaternions

    T = robot.fk_frames(["needle_tip", "probe_tip", "us_image"], random_configurations(robot, 3_000, seed=9))
    R = np.concatenate(
        [T[..., :3, :3].reshape(-1, 3, 3), rotations_about_z(np.linspace(-np.pi, np.pi, 101))[:, :3, :3]]
    )
    R = np.concatenate([R, np.diag([1.0, -1.0, -1.0])[None], np.diag([-1.0, 1.0, -1.0])[None]])  # w = 0 exactly
    # Same formula as SciPy's (so the tables' text is unchanged); compared to a few units of rounding
    # of unit-length numbers, not to the last bit (another CPU or library build may round differently):
    # a wrong branch, sign convention or component order is off by order 1.
    assert np.abs(quaternions(R) - Rotation.from_matrix(R).as_quat(canonical=True)).max() <= 1e-15


# The order and bytes of the bag fast paths against rosbags' reader: tests/test_bags_records.py
