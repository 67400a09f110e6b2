"""The ``brachycal`` command: fk pose tables, help, demo, and one-line refusals with exit code 2."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import numpy as np
from conftest import ROOT
from hostile import run_cli
from test_joint_log import write_log

from brachycal.calibration import read_result
from brachycal.cli.main import build_parser, joined_command, main
from brachycal.data import read_csv_log, read_pose_table

EXAMPLE = ROOT / "examples" / "joint_log.csv"
CONSOLE = Path(sys.executable).parent / "brachycal"


def test_fk_writes_the_pose_table_of_the_conventions(tmp_path, robot, capsys):
    out = tmp_path / "poses.csv"
    assert main(["fk", str(EXAMPLE), "--frames", "needle_tip,probe_tip", "--out", str(out)]) == 0
    assert "wrote 1002 poses (501 samples x 2 frames)" in capsys.readouterr().out
    lines = out.read_text().splitlines()
    assert lines[0] == "time,frame,x,y,z,qx,qy,qz,qw"
    assert lines[1].split(",")[1] == "needle_tip" and lines[2].split(",")[1] == "probe_tip"
    time, frames, T = read_pose_table(out)
    log = read_csv_log(EXAMPLE, robot)
    expected = robot.fk_frames(["needle_tip", "probe_tip"], log.q).transpose(1, 0, 2, 3).reshape(-1, 4, 4)
    assert np.abs(T[:, :3, 3] - expected[:, :3, 3]).max() < 1e-9  # 9 decimals of a metre
    assert np.abs(T[:, :3, :3] - expected[:, :3, :3]).max() < 1e-11
    assert np.array_equal(time[::2], log.time) and frames[:2] == ["needle_tip", "probe_tip"]
    qw = np.array([float(line.split(",")[8]) for line in lines[1:]])
    assert (qw >= 0).all()


def test_fk_at_requested_times(tmp_path, robot):
    times = tmp_path / "frames.csv"
    times.write_text("time,frame_id\n2.5,1\n7.25,2\n")
    out = tmp_path / "p.csv"
    assert (
        main(["fk", str(EXAMPLE), "--frames", "needle_tip", "--out", str(out), "--times", str(times), "--quiet"]) == 0
    )
    time, _, T = read_pose_table(out)
    log = read_csv_log(EXAMPLE, robot)
    assert time.tolist() == [2.5, 7.25]
    assert np.allclose(T[1], robot.fk("needle_tip", log.interpolate([7.25])[0]), atol=1e-9)


def test_fk_refuses_to_overwrite_without_force(tmp_path, capsys):
    out = tmp_path / "p.csv"
    out.write_text("keep me")
    assert main(["fk", str(EXAMPLE), "--frames", "needle_tip", "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert "already exists; pass --force" in err and "force=True" not in err  # the command line's words
    assert out.read_text() == "keep me"
    assert main(["fk", str(EXAMPLE), "--frames", "needle_tip", "--out", str(out), "--force", "--quiet"]) == 0
    assert out.read_text().startswith("time,frame")


def one_line_refusal(capsys, argv: list[str]) -> str:
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and err.startswith("brachycal: error: ")
    return err


def test_fk_refusals_are_one_line_with_exit_code_2(tmp_path, robot, capsys):
    out = str(tmp_path / "o.csv")
    assert "unknown frame 'needle'" in one_line_refusal(
        capsys, ["fk", str(EXAMPLE), "--frames", "needle", "--out", out]
    )
    bad = write_log(tmp_path / "deg.csv", list(robot.joint_names), np.arange(3.0), np.full((3, 15), 45.0))
    assert "row 2, column 'torso_joint_b1': value 45 looks like degrees" in one_line_refusal(
        capsys, ["fk", str(bad), "--frames", "needle_tip", "--out", out]
    )
    assert "no such file" in one_line_refusal(
        capsys, ["fk", str(tmp_path / "x.csv"), "--frames", "needle_tip", "--out", out]
    )
    late = tmp_path / "late.csv"
    late.write_text("time\n99\n")
    assert "outside the log's span" in one_line_refusal(
        capsys, ["fk", str(EXAMPLE), "--frames", "needle_tip", "--out", out, "--times", str(late)]
    )
    assert not Path(out).exists()


def test_model_lists_axes_and_tool_frames(capsys):
    assert main(["model"]) == 0
    text = capsys.readouterr().out
    assert "15 controlled axes" in text and "arm_right_link_tool0 -> needle_tip" in text


def test_console_script_exits_2_without_traceback(tmp_path):
    result = subprocess.run(
        [str(CONSOLE), "fk", str(tmp_path / "missing.csv"), "--frames", "needle_tip", "--out", str(tmp_path / "o.csv")],
        capture_output=True,
        text=True,
        check=False,
    )
    assert result.returncode == 2
    assert "Traceback" not in result.stderr and result.stderr.count("\n") == 1


def test_help_explains_the_commands():
    result = subprocess.run([str(CONSOLE), "--help"], capture_output=True, text=True, check=True)
    for word in ("demo", "fk", "model", "needle tip", "radians"):
        assert word in result.stdout
    fk_help = subprocess.run([str(CONSOLE), "fk", "--help"], capture_output=True, text=True, check=True).stdout
    assert "ROS 2 bag folder" in fk_help and "--times" in fk_help


def test_a_command_group_is_listed_once_with_its_sub_commands():
    listing = build_parser(full=()).format_help()
    assert "nwire segment" in listing and "plan check" in listing and "plan excitation" in listing
    # A sub-command's own name is how the parser knows it, not how a user spells it.
    assert "nwire-segment" not in listing and "plan-check" not in listing and "plan-excitation" not in listing


def test_nwire_calibrate_is_the_default_of_the_nwire_group():
    args = ["CONFIG", "FRAMES", "--out", "nwire.json"]
    assert joined_command(["nwire", "calibrate", *args]) == ["nwire", *args]
    assert joined_command(["nwire", "segment", "CAL.mha", "--out", "f.xml"])[0] == "nwire-segment"


def test_the_earlier_spelling_nwire_segment_runs_nwire_segment_with_a_note(tmp_path):
    argv = [str(tmp_path / "missing.mha"), "--config", str(tmp_path / "config.xml"), "--out", str(tmp_path / "f.xml")]
    old, new = run_cli(["nwire-segment", *argv]), run_cli(["nwire", "segment", *argv])
    note = "brachycal: note: 'nwire-segment' is now 'nwire segment'"
    assert old.code == new.code == 2 and old.err.splitlines()[0].startswith(note)
    assert old.err.splitlines()[1:] == new.err.splitlines() and note not in new.err
    assert not (tmp_path / "f.xml").exists()


def test_output_into_a_closed_pipe_ends_quietly(tmp_path, robot):
    result_file = tmp_path / "r.json"
    assert main(["calibrate", str(ROOT / "examples" / "session_exact"), "--out", str(result_file)]) == 0
    joints = tmp_path / "q.csv"
    joints.write_text(",".join(robot.joint_names) + "\n" + ("0," * 14 + "0\n") * 20000)
    command = f"'{CONSOLE}' locate '{result_file}' '{joints}' --uv 1,2 | head -1"
    result = subprocess.run(command, shell=True, capture_output=True, text=True, check=False)
    assert result.stdout == "line,x_m,y_m,z_m\n"
    # Only the line naming the calibration used: no traceback, no broken-pipe message.
    assert len(result.stderr.splitlines()) == 1 and result.stderr.startswith("brachycal locate: method ")


def test_the_earlier_spelling_calibrate_method_chain_solves_the_chain_with_a_note(tmp_path):
    session = str(ROOT / "examples" / "session_exact")
    old = run_cli(["calibrate", session, "--out", str(tmp_path / "old.json"), "--method", "chain", "--quiet"])
    new = run_cli(["calibrate", session, "--out", str(tmp_path / "new.json"), "--solve", "chain", "--quiet"])
    note = "brachycal: note: 'calibrate --method chain' is now 'calibrate --solve chain'"
    assert old.code == new.code == 0 and old.err.splitlines()[0].startswith(note) and note not in new.err
    # The same calibration: the chain solved, and the next commands told they use it (--quiet: no next: line).
    assert "chain" in read_result(tmp_path / "old.json").image and "chain" in read_result(tmp_path / "new.json").image
    assert old.out.splitlines()[-1] == new.out.splitlines()[-1]
    assert new.out.splitlines()[-1].startswith("the next commands use: chain (the result's best: the whole chain")


def test_the_phantom_kind_is_a_sub_command_and_the_earlier_method_option_runs_it_with_a_note(tmp_path):
    files = [str(ROOT / "examples" / "phantom" / name) for name in ("multi_wedge.toml", "wedge_observations.csv")]
    old = run_cli(["phantom", "--method", "wedge", *files, "--out", str(tmp_path / "old.json")])
    new = run_cli(["phantom", "wedge", *files, "--out", str(tmp_path / "new.json")])
    note = "brachycal: note: 'phantom --method wedge' is now 'phantom wedge'; the old spelling goes in the next release"
    assert old.code == new.code == 0 and old.err.splitlines() == [note] and new.err == ""
    assert old.out.replace("old.json", "new.json") == new.out  # the same calibration
    assert (tmp_path / "old.json").read_text() == (tmp_path / "new.json").read_text()
    # The note's form is the kind's own command, its --help among the kinds of `phantom --help`.
    assert joined_command(["phantom", "--method=wire", "G", "O"]) == ["phantom", "wire", "G", "O"]
    kinds = run_cli(["phantom", "--help"]).out
    assert "KIND" in kinds and all(f"brachycal phantom {kind} " in kinds for kind in ("wedge", "wire", "nwire"))
