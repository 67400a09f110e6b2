"""The needle-tip detector on rendered frames, and ``brachycal tips`` writing what the session build reads."""

from __future__ import annotations

import numpy as np
import pytest

from brachycal.cli.main import main
from brachycal.data.formats.metaimage import write_image_sequence
from brachycal.data.recording import read_images
from brachycal.errors import InputError
from brachycal.imaging.needle_tip import MIN_CONFIDENCE, detect_tip
from brachycal.simulation.bmode import BModeSettings, NeedleView, render_frame

SPACING = (0.19e-3, 0.19e-3)
#: A person's annotation (the twin's 1 px SD per axis) lands within 2.45 px of the tip 95 % of the
#: time: a detection at least as good lands within that.
MANUAL_P95_PX = float(np.sqrt(-2.0 * np.log(0.05)))
#: The needle of the SDA10F's plan: crossing the image plane at 35 deg, advancing in depth (+v).
DIRECTION = np.array([0.0, np.cos(np.radians(35.0)), np.sin(np.radians(35.0))])
TIPS_PX = [(540.0, 200.0), (455.3, 130.6), (612.8, 301.2)]


def frame_of(tip_px: tuple[float, float], settings: BModeSettings, index: int = 0, elevation_m: float = 0.0):
    tip = np.array([tip_px[0] * SPACING[0], tip_px[1] * SPACING[1], elevation_m])
    return render_frame(NeedleView(tip, DIRECTION), SPACING, settings, frame_index=index)


def test_on_a_clean_frame_the_tip_is_found_within_a_third_of_a_pixel():
    clean = BModeSettings().only("shaft", "tip", "beam_thickness", "log_compression")
    for tip in TIPS_PX:
        found = detect_tip(frame_of(tip, clean), prior_direction=(0.0, 1.0))
        # No speckle: what is left is the leading-edge model's bias (the shaft's echo adds to the
        # tip's height, so the edge's levels are crossed early: 0.2 px here) and 8-bit rounding.
        assert np.linalg.norm(found.uv_px - tip) < 0.33
        # The agreement factor still charges the ~1 px by which the peak (pulled back by the shaft's
        # echo) sits behind the echo's end: exp(-1/8) = 0.88.
        assert found.confidence > 0.85


@pytest.mark.parametrize("prior", [(0.0, 1.0), None], ids=["with the plan's direction", "without"])
def test_on_default_frames_the_tip_is_found_as_well_as_a_person_clicks_it(prior):
    for k, tip in enumerate(TIPS_PX):
        for elevation in (-0.3e-3, 0.0, 0.3e-3):  # the twin's tips lie within 0.3 mm of the plane
            found = detect_tip(frame_of(tip, BModeSettings(seed=k), index=k, elevation_m=elevation), prior)
            assert np.linalg.norm(found.uv_px - tip) < MANUAL_P95_PX
            assert found.confidence >= MIN_CONFIDENCE


def test_a_frame_without_a_needle_gets_a_low_confidence():
    for k in range(3):
        empty = render_frame(None, SPACING, BModeSettings(seed=k), frame_index=k)
        assert detect_tip(empty).confidence < MIN_CONFIDENCE


def test_a_tip_in_front_of_the_plane_shows_the_shaft_crossing_and_is_flagged():
    # 2 mm in front of the plane (beyond the beam's 1.5 mm FWHM) the tip's echo is gone; what shows
    # is the shaft crossing the plane 3.5 mm behind it: the detector must not vouch for that.
    found = detect_tip(frame_of(TIPS_PX[0], BModeSettings(), elevation_m=2.0e-3), (0.0, 1.0))
    assert np.linalg.norm(found.uv_px - TIPS_PX[0]) > 5.0
    assert found.confidence < MIN_CONFIDENCE


def test_frames_that_are_not_2d_or_a_zero_direction_are_refused():
    with pytest.raises(InputError, match="2D"):
        detect_tip(np.zeros((3, 40, 40), dtype=np.uint8))
    with pytest.raises(InputError, match="direction"):
        detect_tip(np.zeros((40, 40), dtype=np.uint8), prior_direction=(0.0, 0.0))


def test_brachycal_tips_writes_an_images_csv_the_session_build_reads(tmp_path, capsys):
    tips = TIPS_PX[:2]
    frames = [frame_of(tip, BModeSettings(seed=5), index=k) for k, tip in enumerate(tips)]
    frames.append(render_frame(None, SPACING, BModeSettings(seed=5), frame_index=9))
    times = [1700000100.25, 1700000104.5, 1700000109.75]
    write_image_sequence(tmp_path / "frames.mha", np.stack(frames), timestamps_s=times, spacing=(0.19, 0.19))
    out, sheet = tmp_path / "images.csv", tmp_path / "sheet.png"
    code = main(["tips", str(tmp_path / "frames.mha"), "--out", str(out), "--sheet", str(sheet), "--direction", "0,1"])
    assert code == 0
    read = read_images(out)
    assert [f.time_s for f in read] == pytest.approx(times, abs=1e-6)
    for frame, tip in zip(read[:2], tips, strict=True):
        assert frame.uv_px is not None and np.linalg.norm(frame.uv_px - tip) < MANUAL_P95_PX
    assert read[2].uv_px is None  # no needle: left for a person, and listed
    assert "annotate by hand" in capsys.readouterr().out
    assert sheet.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_the_twins_recording_renders_its_frames_and_tips_proposes_their_annotations(tmp_path, capsys):
    from brachycal.data.formats.csv_log import read_table
    from brachycal.model import Robot
    from brachycal.planning import PlanSpec
    from brachycal.simulation.bmode import true_tip_px
    from brachycal.simulation.recording import RecordingConfig, record, write_recording
    from brachycal.simulation.twin import TwinConfig

    robot = Robot.load()
    # A 2x2x2 plan and a slow log: eight sample frames (plus one grabbed twice) in seconds, stamped
    # on an ultrasound clock 3 s behind the log's: on the log's clock a stamp falls in an earlier
    # stop or move (holds are 1.6 s), so frames must be taken back to it to find the stop they show.
    config = TwinConfig(seed=4, spec=PlanSpec(points_per_axis=2))
    rec = record(robot, config, RecordingConfig(rate_hz=25.0, hold_s=1.6, unannotated_frames=1, image_lag_s=3.0))
    folder = write_recording(rec, tmp_path / "recording", images=BModeSettings(seed=4))
    header, _, rows = read_table(folder / "frames_truth.csv", ["time", "sample", "u_px", "v_px"])
    frames = read_images(folder / "images.csv")
    assert len(rows) == len(frames) == 9
    # One truth row per frame, in the frames' order and times; each frame's true tip is its sample's.
    truth = true_tip_px(rec.twin)
    for row, frame in zip(rows, frames, strict=True):
        assert float(row[header.index("time")]) == pytest.approx(frame.time_s, abs=1e-6)
        k = rec.session.sample_ids.index(row[header.index("sample")])
        true_px = [float(row[header.index("u_px")]), float(row[header.index("v_px")])]
        assert true_px == pytest.approx(truth[k], abs=1e-9)
        # The person's annotation of the frame (1 px SD) is of that sample: it is the right stop.
        assert frame.uv_px is None or np.linalg.norm(frame.uv_px - true_px) < 5.0

    out = tmp_path / "detected.csv"
    argv = ["tips", str(folder / "frames.mha"), "--out", str(out), "--truth", str(folder / "frames_truth.csv")]
    assert main([*argv, "--direction", "0,1"]) == 0
    detected = read_images(out)
    for frame, row in zip(detected, rows, strict=True):
        assert frame.time_s == pytest.approx(float(row[header.index("time")]), abs=1e-6)
        true_px = np.array([float(row[header.index("u_px")]), float(row[header.index("v_px")])])
        assert frame.uv_px is not None and np.linalg.norm(frame.uv_px - true_px) < MANUAL_P95_PX
    assert "error against the true tips" in capsys.readouterr().out
