"""Joint tables without a time column (still touches: MUKCa's ``hole_0.csv``, 7 numbers a row, no
header) and ``brachycal fk`` on them: one pose per row and frame, samples numbered 1..N in a
``sample`` column; hostile rows refused in one line naming the file, the row and the joint."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from conftest import random_configurations, reference
from hostile import Case, check_refusal, run_cli

from brachycal.data.formats.joint_table import read_joint_table, still_table_kind
from brachycal.data.pose_table import read_pose_table
from brachycal.model.description import load_description

PANDA = load_description("panda").robot
JOINTS = PANDA.joint_names  # panda_joint1..7: the fingers are frozen


def write_rows(path: Path, Q: np.ndarray, header: list[str] | None = None) -> Path:
    lines = [] if header is None else [",".join(header)]
    lines += [",".join(f"{v:.17g}" for v in row) for row in Q]
    path.write_text("\n".join(lines) + "\n")
    return path


def test_a_table_without_header_holds_the_robots_coordinates_in_order(tmp_path):
    Q = random_configurations(PANDA, 6, seed=4)
    path = write_rows(tmp_path / "touches.csv", Q)
    (tmp_path / "gaps.csv").write_text(path.read_text().replace("\n", "\n\n", 2))  # blank lines skipped
    assert still_table_kind(path) == "no header"
    table = read_joint_table(path, PANDA)
    assert np.array_equal(table.q, Q) and table.rows.tolist() == [1, 2, 3, 4, 5, 6]
    assert table.samples.tolist() == [1, 2, 3, 4, 5, 6]
    gaps = read_joint_table(tmp_path / "gaps.csv", PANDA)
    assert np.array_equal(gaps.q, Q) and gaps.rows.tolist() == [1, 3, 5, 6, 7, 8]


def test_the_kind_of_a_table_is_told_by_its_first_line(tmp_path):
    (tmp_path / "log.csv").write_text("time," + ",".join(JOINTS) + "\n0," + ",".join(["0"] * 7) + "\n")
    (tmp_path / "named.csv").write_text(",".join(JOINTS) + "\n" + ",".join(["0"] * 7) + "\n")
    (tmp_path / "bare.csv").write_text("\n\n" + ",".join(["0.5"] * 7) + "\n")
    kinds = [still_table_kind(tmp_path / name) for name in ("log.csv", "named.csv", "bare.csv")]
    assert kinds == [None, "named", "no header"]


def test_fk_of_a_table_without_header_gives_one_pose_per_row_and_frame(tmp_path):
    Q = random_configurations(PANDA, 5, seed=5)
    path = write_rows(tmp_path / "touches.csv", Q)
    out = tmp_path / "poses.csv"
    frames = ["panda_link8", "panda_hand_tcp"]
    outcome = run_cli(["fk", str(path), "--robot", "panda", "--frames", ",".join(frames), "--out", str(out)])
    assert outcome.code == 0, outcome.err
    assert "10 poses (5 samples x 2 frames)" in outcome.out
    assert out.read_text().splitlines()[0] == "sample,frame,x,y,z,qx,qy,qz,qw"
    assert [line.split(",")[0] for line in out.read_text().splitlines()[1:]] == [
        str(k) for k in (1, 1, 2, 2, 3, 3, 4, 4, 5, 5)
    ]
    samples, names, T = read_pose_table(out)
    for frame in frames:
        mine = np.array(names) == frame
        assert samples[mine].tolist() == [1, 2, 3, 4, 5]
        assert np.abs(T[mine, :3, 3] - PANDA.fk(frame, Q)[:, :3, 3]).max() < 1e-9  # 9 decimals written
        assert np.abs(T[mine, :3, :3] - PANDA.fk(frame, Q)[:, :3, :3]).max() < 1e-9


def test_fk_of_a_table_naming_its_joints_without_time_is_the_same(tmp_path):
    Q = random_configurations(PANDA, 4, seed=6)
    order = list(JOINTS[::-1])  # any column order
    named = write_rows(tmp_path / "named.csv", Q[:, ::-1], header=order)
    bare = write_rows(tmp_path / "bare.csv", Q)
    for path in (named, bare):
        outcome = run_cli(["fk", str(path), "--robot", "panda", "--frames", "panda_link8", "--out", f"{path}.out"])
        assert outcome.code == 0, outcome.err
    assert Path(f"{named}.out").read_text() == Path(f"{bare}.out").read_text()


def mukca_description(tmp: Path, urdf: Path) -> Path:
    """MUKCa's Panda (its URDF carries the touch ball as ``ball_link``) as a single arm: the fingers
    frozen, so that a configuration is the 7 joints of its tables."""
    path = tmp / f"{urdf.stem}.toml"
    path.write_text(
        f'format = "brachycal-robot/1"\nname = "mukca_panda"\nurdf = "{urdf}"\nbase = "panda_link0"\n'
        'frozen = { panda_finger_joint1 = 0.0 }\n[[arm]]\nname = "arm"\nflange = "panda_link8"\ntool = "ball_link"\n'
    )
    return path


def socket_scatter_mm(tmp: Path, description: Path, place: str) -> float:
    """MUKCa's metric on ``brachycal fk``'s poses: for each socket, the mean distance of the ball from its
    mean position over the touches; averaged over the two sockets."""
    scatter = []
    for hole in ("hole_0", "hole_1"):
        table = reference("mukca_touches", "data", "panda_2_clean", place, f"{hole}.csv")
        out = tmp / f"{description.stem}_{place}_{hole}.csv"
        argv = ["fk", str(table), "--robot", str(description), "--frames", "ball_link", "--out", str(out), "--quiet"]
        outcome = run_cli(argv)
        assert outcome.code == 0, outcome.err
        samples, _, T = read_pose_table(out)
        assert samples.tolist() == list(range(1, len(np.loadtxt(table, delimiter=",")) + 1))
        p = T[:, :3, 3]
        scatter.append(np.linalg.norm(p - p.mean(axis=0), axis=1).mean())
    return 1e3 * float(np.mean(scatter))


def test_fk_of_mukca_touches_reproduces_their_published_scatter(tmp_path):
    """A real Panda's touches (MUKCa, ``panda_2_clean``), read without a header as 7 joint angles:
    their published figures, nominal 8.28 mm on ``front_center`` and, with MUKCa's calibrated URDF,
    0.166 mm there and 0.29-0.39 mm at the other places (the reference data's README)."""
    nominal = mukca_description(tmp_path, reference("mukca_touches", "urdf", "panda.urdf"))
    calibrated = mukca_description(
        tmp_path, reference("mukca_touches", "calibrated_urdf", "panda_2", "panda_calibrated.urdf")
    )
    assert round(socket_scatter_mm(tmp_path, nominal, "front_center"), 2) == 8.28
    assert round(socket_scatter_mm(tmp_path, calibrated, "front_center"), 3) == 0.166
    for place in ("back_left", "mid_right"):
        assert 0.285 <= socket_scatter_mm(tmp_path, calibrated, place) < 0.395


def test_fk_refuses_times_for_a_table_without_time(tmp_path):
    path = write_rows(tmp_path / "touches.csv", random_configurations(PANDA, 2, seed=7))
    (tmp_path / "times.csv").write_text("time\n0.5\n")
    case = Case(
        "fk-still-with-times",
        [
            "fk",
            str(path),
            "--robot",
            "panda",
            "--frames",
            "panda_link8",
            "--times",
            "{tmp}/times.csv",
            "--out",
            "{tmp}/p.csv",
        ],
        ("touches.csv", "--times", "no time column"),
    )
    check_refusal(case, tmp_path)


# --- hostile rows ---------------------------------------------------------------------------------
GOOD = ",".join(["0.1", "0.2", "0.3", "-1.5", "0.4", "1.6", "0.7"])
FK = ["fk", "{tmp}/t.csv", "--robot", "panda", "--frames", "panda_link8", "--out", "{tmp}/p.csv", "--quiet"]


def table(*lines: str, end: str = "\n"):
    def setup(tmp: Path) -> None:
        (tmp / "t.csv").write_text("\n".join(lines) + end)

    return setup


def with_field(k: int, text: str) -> str:
    fields = GOOD.split(",")
    fields[k] = text
    return ",".join(fields)


HOSTILE = [
    Case("still-too-few-columns", FK, ("t.csv", "row 2", "has 6 fields, expected 7"), table(GOOD, "0,0,0,-1,0,1")),
    Case("still-too-many-columns", FK, ("t.csv", "row 1", "has 8 fields"), table(GOOD + ",0.0")),
    Case("still-nan", FK, ("t.csv", "row 2", "panda_joint3", "not a finite number"), table(GOOD, with_field(2, "nan"))),
    Case(
        "still-text",
        FK,
        ("t.csv", "row 3", "panda_joint5", "'abc' is not a number"),
        table(GOOD, GOOD, with_field(4, "abc")),
    ),
    Case("still-empty-field", FK, ("t.csv", "row 1", "panda_joint1", "is not a number"), table(with_field(0, ""))),
    Case("still-empty-file", FK, ("t.csv", "empty file"), table(end="")),
    Case("still-blank-lines-only", FK, ("t.csv", "empty file"), table("", "", "")),
    Case(
        "still-absurd-angle",
        FK,
        ("t.csv", "row 2", "panda_joint4", "looks like degrees"),
        table(GOOD, with_field(3, "150")),
    ),
    Case(
        "still-beyond-limit",
        FK,
        ("t.csv", "row 1", "panda_joint4", "outside the joint limits"),
        table(with_field(3, "0.5")),
    ),
    Case("still-cut-mid-number", FK, ("t.csv", "row 2", "truncated"), table(GOOD, GOOD[:-2], end="")),
    Case("still-a-directory", ["fk", "{tmp}/d.csv", *FK[2:]], ("d.csv", "folder"), lambda tmp: (tmp / "d.csv").mkdir()),
    Case(
        "still-another-robots-table",
        [*FK[:2], "--robot", "ur10", "--frames", "tool0", *FK[6:]],
        ("t.csv", "row 1", "has 7 fields, expected 6", "shoulder_pan_joint"),
        table(GOOD),
    ),
]


@pytest.mark.parametrize("case", HOSTILE, ids=lambda c: c.id)
def test_a_hostile_still_table_is_refused_in_one_line(case, tmp_path):
    check_refusal(case, tmp_path)
