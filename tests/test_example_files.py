"""The shipped example files: made by brachycal, read by the real readers, calibrated to their truth;
``brachycal examples DIR`` copies them out all or nothing."""

from __future__ import annotations

import json
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from conftest import ROOT, TOLERANCE_JOINT_RAD, assert_same_files
from hostile import Case, check_refusal

from brachycal.calibration import calibrate_nwire_files, calibrate_pivot_files
from brachycal.calibration.phantom.phantom_file import read_observations
from brachycal.calibration.phantom.wedge import calibrate_wedge_files, read_wedge_phantom
from brachycal.calibration.phantom.wire import calibrate_wire_files, read_wire_phantom
from brachycal.calibration.robot.arm_fit import flange_points
from brachycal.calibration.robot.identification import corrected_robot
from brachycal.calibration.robot.touches import identify_touch_folders
from brachycal.calibration.robot.tracker import identify_tracker_file
from brachycal.calibration.robot_accuracy import RobotAccuracy
from brachycal.cli.examples import bundled_example_files
from brachycal.cli.main import main
from brachycal.data.formats.metaimage import read_image_sequence, read_sequence_header
from brachycal.data.formats.plus_files import read_plus_config, read_segmented_frames
from brachycal.data.pose_list import read_pose_list
from brachycal.model.description import load_robot
from brachycal.se3 import inverse
from brachycal.studies.example_files import (
    NWIRE_CONFIG_NAME,
    NWIRE_FRAMES_NAME,
    NWIRE_SEQUENCE_FRAMES,
    NWIRE_SEQUENCE_NAMES,
    PHANTOM_FILES,
    PHANTOM_FRAMES,
    PHANTOM_TRUTH_NAME,
    PIVOT_NAME,
    TEMPORAL_LAG_S,
    TEMPORAL_NAMES,
    TOUCH_DISTANCE_MM,
    TOUCH_PLACES,
    TOUCH_TOOL_FRAME,
    TOUCH_TRUTH_NAME,
    TRACKER_NAMES,
    simulate_pivot_recording,
    write_example_files,
)
from brachycal.studies.nwire_twin import FCAL2_LANDMARKS_MM, NWireSimConfig
from brachycal.studies.stepper_twin import STEPPER_NAMES

EXAMPLES = ROOT / "examples"
MADE = ["joints.csv", PIVOT_NAME, "pivot/truth.json", NWIRE_CONFIG_NAME, NWIRE_FRAMES_NAME, "nwire/truth.json"]
MADE += [name for files in PHANTOM_FILES.values() for name in files[:2]] + [PHANTOM_TRUTH_NAME]
#: The MetaImage sequences among the made files, compared by :func:`assert_same_sequences`.
SEQUENCES = [name for name in TEMPORAL_NAMES if name.endswith(".mha")] + list(NWIRE_SEQUENCE_NAMES)
SEQUENCES += [name for name in STEPPER_NAMES.values() if name.endswith(".mha")]
MADE += [name for name in TEMPORAL_NAMES if name not in SEQUENCES]
MADE += [TOUCH_TRUTH_NAME, *TRACKER_NAMES]
#: The touch tables (no header: compared as numbers, not as CSV with a header row).
TOUCH_TABLES = [f"touches/{place}/hole_{k}.csv" for place, points in TOUCH_PLACES.items() for k in range(len(points))]
MADE += [name for name in STEPPER_NAMES.values() if name not in SEQUENCES]


def _numbers_or_text(text: str) -> list[float] | str:
    try:
        return [float(v) for v in text.split()]
    except ValueError:
        return text


def assert_same_sequences(got: Path, want: Path) -> None:
    """Two MetaImage sequences hold the same frames: pixels within 1 (uint8 cut from rendered
    floats), per-frame numeric fields within 2e-6 (written with 6 decimals), other fields equal."""
    got_seq, want_seq = read_image_sequence(got), read_image_sequence(want)
    assert got_seq.pixels.shape == want_seq.pixels.shape, want.name
    assert np.abs(got_seq.pixels.astype(int) - want_seq.pixels.astype(int)).max() <= 1, want.name
    (_, got_frames), (_, want_frames) = read_sequence_header(got), read_sequence_header(want)
    assert [sorted(f) for f in got_frames] == [sorted(f) for f in want_frames], want.name
    for k, (a, b) in enumerate(zip(got_frames, want_frames, strict=True)):
        for key in b:
            x, y = _numbers_or_text(a[key]), _numbers_or_text(b[key])
            if isinstance(y, str):
                assert x == y, f"{want.name} frame {k} {key}"
            else:
                assert not isinstance(x, str) and np.allclose(x, y, rtol=0, atol=2e-6), f"{want.name} frame {k} {key}"


def test_committed_example_files_are_what_the_script_makes(tmp_path):
    copy = tmp_path / "examples"
    shutil.copytree(EXAMPLES, copy)
    for name in MADE + SEQUENCES + TOUCH_TABLES:
        (copy / name).unlink()
    subprocess.run([sys.executable, str(copy / "make_example_files.py")], check=True, capture_output=True)
    # Numbers within conftest's TOLERANCE_* (1e-9 SI and mm-valued matrix entries, 1e-6 px): the
    # files are written with full precision, so another machine differs in the last bits only.
    assert_same_files(copy, EXAMPLES, MADE)
    for name in SEQUENCES:
        assert_same_sequences(copy / name, EXAMPLES / name)
    for name in TOUCH_TABLES:  # joint values: within conftest's joint tolerance
        got, want = (np.loadtxt(folder / name, delimiter=",") for folder in (copy, EXAMPLES))
        assert got.shape == want.shape and np.allclose(got, want, rtol=0, atol=TOLERANCE_JOINT_RAD), name


def test_example_files_are_small():
    """They ship inside the package: all the files brachycal bundles stay well under 1 MB."""
    source, files = bundled_example_files()
    assert sum((source / name).stat().st_size for name in files) < 1_000_000


def test_pivot_example_reads_back_and_calibrates_to_its_truth():
    names, T, _ = read_pose_list(EXAMPLES / PIVOT_NAME)
    assert len(names) == len(T) == 200 and names[0].isdigit()  # keyed by timestamp_ns, like the real file
    truth = json.loads((EXAMPLES / "pivot/truth.json").read_text())
    calibration = calibrate_pivot_files(EXAMPLES / PIVOT_NAME, "algebraic", "mm")
    result = calibration.result
    # The fit's own predicted 3D SD (from its residuals) sets the bound: 3 SD in 3D is exceeded with
    # ~3 % chance by a 3D Gaussian error, 4 SD (~0.1 %) leaves no flakiness for this fixed seed.
    tip_error = np.linalg.norm(result.p_marker_tip - truth["p_marker_tip_mm"])
    pivot_error = np.linalg.norm(result.p_ref_pivot - truth["p_tracker_pivot_mm"])
    assert tip_error < 4 * result.tip_sd and pivot_error < 4 * result.pivot_sd
    # The residual per axis is the tracker noise put in (0.144 mm per axis) plus its rotation
    # part (0.02° at the 0.4 m tip: 0.14 mm): within 30 % of their root sum of squares.
    lever_mm = np.radians(truth["noise_sd_deg"]) * np.linalg.norm(truth["p_marker_tip_mm"])
    expected = np.hypot(truth["noise_sd_mm"], lever_mm)
    assert abs(result.rms_per_axis / expected - 1) < 0.3


def test_temporal_example_gives_its_known_lag(tmp_path, capsys):
    """``brachycal temporal`` on the bundled water-tank pair finds the lag it was made with: the
    pair has no noise, so the only error is the search's (1 ms steps, refined) and the
    interpolation of the 20 Hz tracker; within 1 ms, and within 3 of its stated SDs."""
    video, tracker, truth_name = (EXAMPLES / name for name in TEMPORAL_NAMES)
    truth = json.loads(truth_name.read_text())
    assert truth["lag_s"] == TEMPORAL_LAG_S
    out = tmp_path / "lag.json"
    assert main(["temporal", str(video), str(tracker), "--out", str(out)]) == 0
    result = json.loads(out.read_text())
    error = abs(result["lag_s"] - truth["lag_s"])
    assert error < 1e-3 and error <= 3 * result["sd_s"], result
    assert "lag of the tracker behind the video: +137" in capsys.readouterr().out


def test_nwire_sequences_segment_to_the_examples_points(tmp_path, capsys):
    """``brachycal nwire segment`` on the bundled sequences (the N-wire example's first frames,
    rendered) finds every frame's wire points within 0.1 px of the points they were rendered from
    (the segmentation's goal on rendered frames, tests/test_nwire_segmentation.py)."""
    out = tmp_path / "segmented.xml"
    sequences = [str(EXAMPLES / name) for name in NWIRE_SEQUENCE_NAMES]
    argv = ["nwire", "segment", *sequences, "--config", str(EXAMPLES / NWIRE_CONFIG_NAME), "--orientation", "UF"]
    assert main([*argv, "--out", str(out), "--quiet"]) == 0
    assert "twin_calibration.mha: 20 of 20 frames segmented" in capsys.readouterr().out
    found = read_segmented_frames(out)
    rendered = read_segmented_frames(EXAMPLES / NWIRE_FRAMES_NAME)
    for got, want, count in zip(found, rendered, NWIRE_SEQUENCE_FRAMES, strict=True):
        assert len(got) == count and all(f.ok for f in got)
        for g, w in zip(got, want[:count], strict=True):
            assert set(g.points_px) == set(w.points_px)
            assert max(np.linalg.norm(g.points_px[n] - w.points_px[n]) for n in w.points_px) < 0.1
            np.testing.assert_allclose(g.T_tracker_probe, w.T_tracker_probe, rtol=0, atol=1e-9)


def test_pivot_recording_without_noise_is_exact():
    recording = simulate_pivot_recording(seed=3, poses=20, noise_sd_mm=0.0, noise_sd_deg=0.0)
    T = recording.T_tracker_marker_mm
    tips = np.einsum("nij,j->ni", T[:, :3, :3], recording.p_marker_tip_mm) + T[:, :3, 3]
    assert np.abs(tips - recording.p_tracker_pivot_mm).max() < 1e-9  # mm: round-off only


def test_nwire_example_reads_back_and_calibrates_to_its_truth():
    config = read_plus_config(EXAMPLES / NWIRE_CONFIG_NAME)
    calibration, validation = read_segmented_frames(EXAMPLES / NWIRE_FRAMES_NAME)
    assert len(config.patterns) == 3 and ("Phantom", "Reference") in config.transforms
    assert len(calibration) == 40 and len(validation) == 20 and all(f.ok for f in calibration + validation)
    truth = json.loads((EXAMPLES / "nwire/truth.json").read_text())
    run = calibrate_nwire_files(EXAMPLES / NWIRE_CONFIG_NAME, EXAMPLES / NWIRE_FRAMES_NAME)
    estimate = run.calibration
    T_true, spacing_true = np.array(truth["T_probe_image"]), np.array(truth["spacing_mm"]) * 1e-3
    # Where the estimate puts the wires' pixels in the probe frame, against the truth. What does not
    # average over frames sets the bound: the tracker's repeatable error field (its stated 0.25 mm
    # 3D RMS accuracy), the phantom's registration from 8 landmarks touched with 0.3 mm SD per axis
    # (3D: 0.3·√3/√8 = 0.18 mm) and its printing tolerance (0.1 mm per axis, 0.17 mm 3D): 0.35 mm
    # root sum of squares. Averaged terms (0.5 px segmentation over 120 points, tracker jitter over
    # 20 frames) add ~0.01 mm. Measured: 0.35 mm RMS (0.17 without the tracker error, 0.27 with it
    # alone). The RMS must stay within twice that budget.
    sim = NWireSimConfig()
    budget_m = np.sqrt(
        sim.tracker_accuracy_m**2
        + 3 * sim.landmark_sd_m**2 / len(FCAL2_LANDMARKS_MM)
        + 3 * sim.phantom_tolerance_sd_m**2
    )
    uv = np.array([uv for frame in validation for uv in frame.points_px.values()])
    got = estimate.to_probe(uv)
    want = (T_true @ np.c_[uv * spacing_true, np.zeros(len(uv)), np.ones(len(uv))].T).T[:, :3]
    rms_m = np.sqrt(np.mean(np.sum((got - want) ** 2, axis=1)))
    assert rms_m < 2 * budget_m, f"{rms_m * 1e3:.3f} mm RMS, budget {budget_m * 1e3:.3f} mm"
    # The spacings within 1 %: a wrong scale of 1 % is 0.4 mm at the 40 mm the wires span.
    assert np.allclose(estimate.spacing_m, spacing_true, rtol=0.01)
    assert np.allclose(inverse(T_true), truth["T_image_probe"], atol=1e-12)


@pytest.mark.parametrize("method", ["wedge", "wire"])
def test_phantom_examples_read_back_and_calibrate_to_their_truth(method, recwarn):
    geometry, observations = (EXAMPLES / name for name in PHANTOM_FILES[method][:2])
    kind = PHANTOM_FILES[method][2]
    phantom = read_wedge_phantom(geometry) if method == "wedge" else read_wire_phantom(geometry)
    bundled = read_wedge_phantom() if method == "wedge" else read_wire_phantom()
    assert phantom.names == bundled.names  # the bundled phantom, with the lab's registration
    assert not np.allclose(phantom.geometry.registration(), np.eye(4))
    seen = read_observations(observations, kind, phantom.names)
    assert len(seen.frames) == PHANTOM_FRAMES[method] and len(seen.feature) == len(phantom.names) * len(seen.frames)
    truth = json.loads((EXAMPLES / PHANTOM_TRUTH_NAME).read_text())
    fit, _, _ = (calibrate_wedge_files if method == "wedge" else calibrate_wire_files)(geometry, observations)
    assert not recwarn.list  # the example is conditioned well enough not to warn (PHANTOM_FRAMES)
    T_true, spacing_true = np.array(truth["T_marker_image"]), np.array(truth["spacing_mm"]) * 1e-3
    # Where the estimate puts the observed pixels on the marker body, against the truth. As for the
    # N-wire example, what does not average over frames sets the bound: the tracker's fixed error
    # field (0.25 mm), the 8-landmark registration (0.18 mm 3D) and the print tolerance (0.17 mm
    # 3D): 0.35 mm root sum of squares; the multi-wedge's B-mode edge bias (the shallowest depth
    # across the 0.6 mm beam of a face tilted 30° in the image: up to 0.3·tan 30° = 0.17 mm in
    # depth) adds to it: 0.40 mm. Measured: 0.28 mm RMS for both. Within twice the budget.
    sim = NWireSimConfig()
    budget_m = np.sqrt(
        sim.tracker_accuracy_m**2
        + 3 * sim.landmark_sd_m**2 / len(phantom.geometry.landmarks_m)
        + 3 * sim.phantom_tolerance_sd_m**2
        + (sim.wire_beam_thickness_m / 2 * np.tan(np.radians(30))) ** 2
    )
    uv = seen.uv_px.reshape(-1, 2)
    image = np.c_[uv * fit.spacing_m, np.zeros(len(uv)), np.ones(len(uv))].T
    got = (fit.T_marker_image @ image).T[:, :3]
    want = (T_true @ np.c_[uv * spacing_true, np.zeros(len(uv)), np.ones(len(uv))].T).T[:, :3]
    rms_m = np.sqrt(np.mean(np.sum((got - want) ** 2, axis=1)))
    assert rms_m < 2 * budget_m, f"{rms_m * 1e3:.3f} mm RMS, budget {budget_m * 1e3:.3f} mm"
    # The spacings within 3 %: the phantom sessions are smaller than the N-wire one (30-50 frames).
    assert np.allclose(fit.spacing_m, spacing_true, rtol=0.03)


def test_written_files_are_all_or_nothing(tmp_path):
    (tmp_path / "nwire").mkdir()
    (tmp_path / NWIRE_FRAMES_NAME).write_text("mine")
    with pytest.raises(Exception, match="exists"):
        write_example_files(tmp_path)
    assert sorted(p.name for p in tmp_path.rglob("*")) == ["nwire", "twin_segmented_frames.xml"]
    assert (tmp_path / NWIRE_FRAMES_NAME).read_text() == "mine"


# --- brachycal examples DIR -----------------------------------------------------------------------


def test_examples_command_copies_every_bundled_file_and_then_has_nothing_to_do(tmp_path, capsys):
    source, files = bundled_example_files()
    assert "joint_log.csv" in {str(f) for f in files} and any(str(f) == PIVOT_NAME for f in files)
    assert main(["examples", str(tmp_path / "ex")]) == 0
    assert sorted(p.relative_to(tmp_path / "ex") for p in (tmp_path / "ex").rglob("*") if p.is_file()) == files
    assert all((tmp_path / "ex" / f).read_bytes() == (source / f).read_bytes() for f in files)
    assert f"wrote {len(files)} example files" in capsys.readouterr().out
    assert main(["examples", str(tmp_path / "ex")]) == 0  # the same files: nothing to do, not an error
    assert f"wrote 0 example files to {tmp_path / 'ex'} ({len(files)} already there" in capsys.readouterr().out


def test_examples_command_replaces_changed_files_only_with_force(tmp_path, capsys):
    assert main(["examples", str(tmp_path)]) == 0
    (tmp_path / "joints.csv").write_text("changed")
    (tmp_path / "mine.txt").write_text("kept")
    assert main(["examples", str(tmp_path), "--force"]) == 0
    assert (tmp_path / "joints.csv").read_bytes() == (EXAMPLES / "joints.csv").read_bytes()
    assert (tmp_path / "mine.txt").read_text() == "kept"  # other files are not touched


def _changed_copy(tmp: Path) -> None:
    assert main(["examples", str(tmp / "ex")]) == 0
    (tmp / "ex" / "joints.csv").write_text("changed")
    (tmp / "ex" / "pivot" / "truth.json").unlink()  # would be copied: but nothing is, on a refusal


def _a_file_named_f(tmp: Path) -> None:
    (tmp / "f").write_text("x")


def _a_file_where_the_pivot_folder_goes(tmp: Path) -> None:
    (tmp / "ex").mkdir()
    (tmp / "ex" / "pivot").write_text("x")


CASES = [
    Case("dir-is-a-file", ["examples", "{tmp}/f"], ("f", "not a folder"), setup=_a_file_named_f),
    Case("changed-file", ["examples", "{tmp}/ex"], ("joints.csv", "other content", "--force"), setup=_changed_copy),
    Case("file-where-a-folder-goes", ["examples", "{tmp}/ex"], ("pivot",), setup=_a_file_where_the_pivot_folder_goes),
    Case("no-dir", ["examples"], ("DIR",)),
]


@pytest.mark.parametrize("case", CASES, ids=lambda c: c.id)
def test_examples_command_refuses(case, tmp_path):
    check_refusal(case, tmp_path)


# --- the robot identification examples -------------------------------------------------------------


def test_touch_example_identifies_the_arm_it_was_made_with():
    """``examples/touches``: a Panda off its URDF by 0.3 mm / 0.05° per joint-origin axis touches two
    sockets at three places. Trained on one place with that stated accuracy, the held-out places'
    tip scatter falls far below the nominal URDF's (the drawn errors, ~1.4 mm of scatter, against
    0.05 mm of touch noise: a mean scatter of ~0.08 mm would be the noise alone), and the fitted
    tip is the true one within 4 of its stated SDs per axis."""
    truth = json.loads((EXAMPLES / TOUCH_TRUTH_NAME).read_text())
    nominal = load_robot(truth["robot"])
    folders = [EXAMPLES / "touches" / place for place in TOUCH_PLACES]
    accuracy = RobotAccuracy(0.3e-3, float(np.radians(0.05)))
    report = identify_touch_folders(
        nominal, folders, TOUCH_TOOL_FRAME, ["front"], accuracy, distance_m=TOUCH_DISTANCE_MM * 1e-3
    )
    assert report.held_out == ["left", "right"]
    for place in report.held_out:
        assert report.identified[place].mean_scatter_m < report.nominal[place].mean_scatter_m / 5, place
    # the fitted tip is in the tool frame's link (the hand), the truth's in the flange
    q0 = nominal.neutral()[None]
    T_hand_flange = inverse(nominal.fk(report.result.flange, q0)[0]) @ nominal.fk(truth["flange"], q0)[0]
    tip = T_hand_flange[:3, :3] @ truth["tip_m"] + T_hand_flange[:3, 3]
    tip_sd = np.sqrt(np.diag(report.result.fit.y_covariance())[:3])
    assert np.all(np.abs(report.result.tip - tip) < 4 * tip_sd), (report.result.tip - tip, tip_sd)
    # the truth's own arm puts every touch of a place within the noise of one point
    physical = corrected_robot(nominal, _corrections(nominal, truth["corrections"]))
    for place, points in truth["points_m"].items():
        for k, point in enumerate(points):
            Q = np.loadtxt(EXAMPLES / "touches" / place / f"hole_{k}.csv", delimiter=",")
            tips = flange_points(physical, Q, truth["flange"], np.array(truth["tip_m"])).p
            assert np.sqrt(np.mean((tips - point) ** 2)) < 2 * truth["noise_sd_m"], (place, k)


def _corrections(robot, named: dict[str, list[float]]) -> np.ndarray:
    corrections = np.zeros((robot.nq, 6))
    for name, c in named.items():
        corrections[robot.joint_names.index(name)] = c
    return corrections


@pytest.mark.slow
def test_tracker_example_identifies_the_arm_it_was_made_with():
    """``examples/tracker``: a UR10 off its URDF by 0.5 mm / 0.05° per joint-origin axis, a 6-D marker
    read with 0.1 mm and 0.05° of noise per axis. The joints model is chosen, its noise levels are
    the drawn ones (within 25 %: 72 residuals each, less the fitted parameters), and it predicts
    postures it never saw as well as the noise allows."""
    truth = json.loads((EXAMPLES / TRACKER_NAMES[2]).read_text())
    table, columns, _ = (EXAMPLES / name for name in TRACKER_NAMES)
    identification = identify_tracker_file(load_robot(truth["robot"]), table, columns)
    assert identification.chosen == "joints"
    sigma = identification.fit.sigma
    assert sigma["position"] == pytest.approx(truth["noise_sd_m"], rel=0.25)
    assert np.degrees(sigma["orientation"]) == pytest.approx(truth["noise_sd_deg"], rel=0.25)
    held_out = next(s for s in identification.scores if s.model == "joints")
    assert held_out.loo_position_mm < 1.5 * truth["noise_sd_m"] * 1e3
