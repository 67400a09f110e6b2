"""Session folders: round trip, and every refusal names file, row and column (exit code 2 from the CLI)."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from test_joint_log import edit

from brachycal import InputError
from brachycal.calibration import read_result
from brachycal.cli.main import main
from brachycal.data.session import read_session


def test_round_trip(session_dir, robot, exact):
    session = read_session(session_dir, robot)
    assert session.sample_ids == exact.sample_ids
    assert np.array_equal(session.samples_q, exact.samples_q)
    assert np.array_equal(session.uv_px, exact.uv_px)
    assert np.array_equal(session.touches["needle", "rtip2"].q, exact.touches["needle", "rtip2"].q)
    assert np.allclose(session.spacing_m, [0.19e-3, 0.19e-3]) and np.allclose(session.p_ER_Mtip, [0, 0, 0.15])
    assert set(session.inputs) == {"session.toml", "touches.csv", "axes.csv", "samples.csv"}
    assert session.sector is None and "[image.sector]" not in (session_dir / "session.toml").read_text()


def test_a_stated_imaging_sector_is_read_in_si_units_and_written_back_as_stated(session_dir, robot, exact, tmp_path):
    from dataclasses import replace

    from brachycal.data.session import write_session

    toml = session_dir / "session.toml"
    sector = "[image.sector]\napex_px = [540, -20.5]\ndepth_mm = 140\nangle_deg = 120\n\n"
    toml.write_text(toml.read_text().replace("[top_model]", sector + "[top_model]"))
    read = read_session(session_dir, robot).sector
    assert read is not None
    assert read.apex_px == (540.0, -20.5) and read.depth_m == pytest.approx(0.140, rel=1e-15)
    assert read.angle_rad == pytest.approx(2 * np.pi / 3, rel=1e-15)
    written = write_session(replace(exact, sector=read), tmp_path / "again")
    text = (written / "session.toml").read_text()
    assert "apex_px = [540, -20.5]" in text and "depth_mm = 140\n" in text and "angle_deg = 120 " in text
    assert read_session(written, robot).sector == read


def refused(folder: Path, robot) -> str:
    with pytest.raises(InputError) as info:
        read_session(folder, robot)
    assert "\n" not in str(info.value)
    return str(info.value)


def drop_rows(path: Path, predicate) -> None:
    lines = path.read_text().splitlines()
    path.write_text("\n".join([lines[0]] + [line for line in lines[1:] if not predicate(line)]) + "\n")


def test_fewer_than_three_samples(session_dir, robot):
    lines = (session_dir / "samples.csv").read_text().splitlines()
    (session_dir / "samples.csv").write_text("\n".join(lines[:3]) + "\n")
    assert "2 samples: at least 3" in refused(session_dir, robot)


def test_collinear_image_points(session_dir, robot):
    lines = (session_dir / "samples.csv").read_text().splitlines()
    header = lines[0].split(",")
    rows = []
    for k, line in enumerate(lines[1:]):
        fields = line.split(",")
        fields[header.index("u_px")] = str(100.0 + k)
        fields[header.index("v_px")] = str(50.0 + 2 * k)
        rows.append(",".join(fields))
    (session_dir / "samples.csv").write_text("\n".join([lines[0], *rows]) + "\n")
    assert "samples.csv: the annotated image points are collinear" in refused(session_dir, robot)


def test_missing_touches(session_dir, robot):
    drop_rows(session_dir / "touches.csv", lambda line: line.startswith("probe,rtip2"))
    assert "touches.csv: no touches of probe at rtip2" in refused(session_dir, robot)


def test_missing_axes_point(session_dir, robot):
    drop_rows(session_dir / "axes.csv", lambda line: line.startswith("probe,p3"))
    assert "axes.csv: missing axes point p3 for probe" in refused(session_dir, robot)


def test_unequal_trial_counts(session_dir, robot):
    drop_rows(session_dir / "touches.csv", lambda line: line.startswith("needle,rtip2,3"))
    assert "unequal trials at rtip2: needle has [1, 2], top_model has [1, 2, 3]" in refused(session_dir, robot)


def test_unknown_tool(session_dir, robot):
    edit(session_dir / "touches.csv", 5, "tool", "laser")
    assert "touches.csv, row 5, column 'tool': unknown tool 'laser'" in refused(session_dir, robot)


def test_nan_joint(session_dir, robot):
    edit(session_dir / "samples.csv", 12, "arm_left_joint_3_e", "nan")
    assert "samples.csv, row 12, column 'arm_left_joint_3_e': value is not a finite number" in refused(
        session_dir, robot
    )


def test_nan_pixel_and_pixel_outside_the_image(session_dir, robot):
    edit(session_dir / "samples.csv", 4, "v_px", "nan")
    assert "row 4, column 'v_px'" in refused(session_dir, robot)
    edit(session_dir / "samples.csv", 4, "v_px", "800")
    assert "row 4, column 'v_px': 800 is outside the image (0..719 px)" in refused(session_dir, robot)


def test_degrees_in_a_session(session_dir, robot):
    edit(session_dir / "axes.csv", 3, "arm_right_joint_2_l", "45.0")
    assert "axes.csv, row 3, column 'arm_right_joint_2_l': value 45 looks like degrees" in refused(session_dir, robot)


def test_a_reading_within_the_encoder_tolerance_of_a_limit_is_calibrated_with_a_warning(session_dir, tmp_path, capsys):
    # One sample read a few encoder counts beyond a limit (a pose planned on the limit) must not
    # make calibrate refuse the whole session. Within 1e-3 rad it is kept as read, with a warning
    # naming the file, row and joint; the first sample's wrist sits 0.05 rad inside its limit π.
    edit(session_dir / "samples.csv", 2, "arm_right_joint_7_t", repr(np.pi + 7e-6))
    out = tmp_path / "result.json"
    assert main(["calibrate", str(session_dir), "--out", str(out)]) == 0
    warnings = [line for line in capsys.readouterr().err.splitlines() if "warning:" in line]
    assert len(warnings) == 1 and "samples.csv, row 2, column 'arm_right_joint_7_t'" in warnings[0]
    assert "7e-06 rad beyond the joint limit" in warnings[0] and "kept as read" in warnings[0]
    assert out.exists()


def test_a_reading_beyond_the_encoder_tolerance_of_a_limit_is_refused(session_dir, tmp_path, capsys):
    edit(session_dir / "axes.csv", 3, "arm_right_joint_7_t", repr(np.pi + 2e-3))
    out = tmp_path / "result.json"
    assert main(["calibrate", str(session_dir), "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "axes.csv, row 3, column 'arm_right_joint_7_t'" in err
    assert "outside the joint limits" in err and "more than the 0.001 rad allowed" in err and not out.exists()


def test_duplicate_touch(session_dir, robot):
    lines = (session_dir / "touches.csv").read_text().splitlines()
    (session_dir / "touches.csv").write_text("\n".join([*lines, lines[1]]) + "\n")
    assert "top_model at rtip1 trial 1 appears twice (also row 2)" in refused(session_dir, robot)


def test_bad_toml(session_dir, robot):
    toml = session_dir / "session.toml"
    toml.write_text(toml.read_text().replace("brachycal-session/1", "brachycal-session/9"))
    assert "format is 'brachycal-session/9'" in refused(session_dir, robot)
    toml.write_text(toml.read_text().replace("brachycal-session/9", "brachycal-session/1").replace("0.19,", "-0.19,"))
    assert "key 'image.spacing_mm': expected positive finite numbers" in refused(session_dir, robot)
    toml.write_text("format = ")
    assert "not valid TOML" in refused(session_dir, robot)


def test_missing_file(session_dir, robot):
    (session_dir / "axes.csv").unlink()
    assert refused(session_dir, robot).endswith("axes.csv: missing session file")


def test_calibrate_cli(session_dir, tmp_path, capsys):
    out = tmp_path / "result.json"
    assert main(["calibrate", str(session_dir), "--out", str(out)]) == 0
    text = capsys.readouterr().out
    assert "TABLE I. THE ACCURACY OF MECHANICAL CALIBRATION" in text
    assert "TABLE II. THE ACCURACY OF US PROBE CALIBRATION (leave-one-out over 64 samples)" in text
    for label in ("Needle-tip calibration", "US probe-tip calibration", "ICP", "Kabsch", "Landmark (Horn)"):
        assert label in text
    raw = json.loads(out.read_text())
    assert len(raw["inputs"]) == 4 and all(len(h) == 64 for h in raw["inputs"].values())
    # never overwrites without --force
    out.write_text("keep")
    assert main(["calibrate", str(session_dir), "--out", str(out)]) == 2
    assert out.read_text() == "keep"
    assert "already exists" in capsys.readouterr().err


def test_calibrate_cli_refusal_is_one_line_and_writes_nothing(session_dir, tmp_path, capsys):
    drop_rows(session_dir / "axes.csv", lambda line: line.startswith("needle,p2"))
    out = tmp_path / "r.json"
    assert main(["calibrate", str(session_dir), "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "missing axes point p2 for needle" in err
    assert not out.exists() and list(tmp_path.glob(".r.json*")) == []


def test_locate_cli(session_dir, tmp_path, capsys, robot, truth, exact):
    out = tmp_path / "result.json"
    main(["calibrate", str(session_dir), "--out", str(out)])
    best = read_result(out).best_method()
    # calibrate ends by naming the calibration the next commands use (the result file's rule), then
    # the next commands themselves.
    lines = capsys.readouterr().out.splitlines()
    said, next_line = lines[-3], lines[-2]
    assert said.startswith(f"the next commands use: {best} (the result's best: lowest leave-one-out RMSE, ")
    assert next_line == f"next: brachycal locate {out} JOINTS --uv U,V"
    assert lines[-1].strip() == f"brachycal export {out} --out DIR"
    joints = tmp_path / "q.csv"
    q = exact.samples_q[:2]
    joints.write_text(
        ",".join(robot.joint_names) + "\n" + "\n".join(",".join(repr(float(x)) for x in row) for row in q) + "\n"
    )
    capsys.readouterr()
    assert main(["locate", str(out), str(joints), "--uv", "540,300", "--method", "scaled_uv"]) == 0
    printed = capsys.readouterr()
    lines = printed.out.splitlines()
    assert lines[0] == "line,x_m,y_m,z_m" and len(lines) == 3
    # Each point names its configuration's line in the file (the header is line 1): q[1] is line 3.
    assert [line.split(",")[0] for line in lines[1:]] == ["2", "3"]
    # Method, frame and unit in one stderr line (stdout stays a plain CSV with the unit in its columns).
    assert printed.err == (
        f"brachycal locate: method scaled_uv (--method); frame base_link; unit m; result {out}; "
        f"line: of {joints} (its header is line 1)\n"
    )
    assert main(["locate", str(out), str(joints), "--uv", "540,300"]) == 0
    assert capsys.readouterr().err.startswith(f"brachycal locate: method {best} (the result's best: ")
    p = np.array([float(x) for x in lines[2].split(",")[1:]])
    physical = truth.robot(robot)
    expected = physical.fk("us_image", q[1]) @ [540 * 0.19e-3, 300 * 0.19e-3, 0, 1]
    assert np.abs(p - expected[:3]).max() < 1e-8  # printed to 1e-9 m
    assert main(["locate", str(out), str(joints), "--uv", "540"]) == 2  # argparse checks --uv before any work
    assert "argument --uv: must be 2 comma-separated numbers" in capsys.readouterr().err
    assert main(["locate", str(joints), str(joints), "--uv", "1,2"]) == 2
    assert "not valid JSON" in capsys.readouterr().err
