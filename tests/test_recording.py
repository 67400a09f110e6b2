"""A lab's recording: still windows over a joint log, marks, frames and Slicer markups.

The still-window tests use synthetic logs whose stops are known exactly: a robot held at one
configuration, a minimum-jerk move, a slow linear creep. Every value the estimator returns is
checked against that construction, not against the code's own arithmetic.
"""

from __future__ import annotations

import json

import numpy as np
import pytest

from brachycal import InputError
from brachycal.data import JointLog, read_images, read_marks, read_slicer_markups, still_configuration
from brachycal.data.recording import MAX_SPEED_RAD_S, SPEED_SPAN_S, STILL_WINDOW_S

NQ = 3
NAMES = ("j1", "j2", "j3")
Q_A = np.array([0.1, -0.4, 0.7])
Q_B = np.array([0.6, -0.2, 0.3])
# A sum of ~100 equal terms divided by their count rounds to within ~1e-16 relative: 1e-12 rad
# separates "exact" from any real averaging or interpolation error (encoder noise is 2e-5 rad).
EXACT = 1e-12


def synthetic_log(rate_hz: float = 100.0, noise: float = 0.0, seed: int = 0, t0: float = 0.0) -> JointLog:
    """Held at Q_A for [0, 3] s, a 2 s minimum-jerk move to Q_B, held at Q_B for [5, 8] s."""
    t = np.arange(0.0, 8.0 + 1e-9, 1 / rate_hz)
    s = np.clip((t - 3.0) / 2.0, 0.0, 1.0)
    q = Q_A + (s**3 * (10 - 15 * s + 6 * s**2))[:, None] * (Q_B - Q_A)
    q = q + np.random.default_rng(seed).normal(scale=noise, size=q.shape)
    return JointLog(time=t0 + t, q=q, joint_names=NAMES, source="log.csv", rows=np.arange(2, len(t) + 2))


def test_still_window_at_a_stop_is_the_stop_exactly():
    log = synthetic_log()
    for t, q in ((1.5, Q_A), (2.4, Q_A), (6.5, Q_B)):
        w = still_configuration(log, t)
        np.testing.assert_allclose(w.q, q, rtol=0, atol=EXACT)
        assert w.start_s == pytest.approx(t - STILL_WINDOW_S / 2) and w.end_s == pytest.approx(t + STILL_WINDOW_S / 2)
        assert w.samples in (100, 101)  # 1 s at 100 Hz, the ends on or between readings
        np.testing.assert_allclose(w.spread, 0.0, atol=EXACT)
        np.testing.assert_allclose(w.speed, 0.0, atol=1e-9)  # slopes of constants (cumulative sums: ~1e-12)


def test_still_window_keeps_its_digits_on_ros_time():
    """Stamps near 1.7e9 s (ROS time) have a float spacing of 2.4e-7 s: the window works relative
    to the mark's time, so the result stays exact to the same 1e-12 rad."""
    log = synthetic_log(t0=1.7e9)
    np.testing.assert_allclose(still_configuration(log, 1.7e9 + 1.5).q, Q_A, rtol=0, atol=EXACT)


def test_a_slow_creep_is_still_and_its_mean_is_the_value_at_the_mark():
    """A joint creeping at half the still speed is still; the time-average of a linear motion over
    a window centred on t is its value at t, whatever the sampling: a burst of readings on one side
    would pull a plain mean of the readings off (here by ~1e-4 rad), the time-average is exact."""
    rate = 0.5 * MAX_SPEED_RAD_S
    regular = np.arange(0.0, 4.0, 0.01)
    burst = np.arange(2.0, 2.5, 0.001)  # ten times denser on the late half of the window around 2.0 s
    t = np.unique(np.concatenate([regular, burst]).round(9))
    q = Q_A + rate * t[:, None] * np.array([1.0, -1.0, 0.5])
    log = JointLog(time=t, q=q, joint_names=NAMES, source="creep.csv", rows=np.arange(2, len(t) + 2))
    w = still_configuration(log, 2.0)
    np.testing.assert_allclose(w.q, Q_A + rate * 2.0 * np.array([1.0, -1.0, 0.5]), rtol=0, atol=EXACT)
    readings = (t >= 1.5) & (t <= 2.5)
    assert np.abs(q[readings].mean(axis=0) - w.q).max() > 1e-5  # what a plain mean would have said
    np.testing.assert_allclose(w.speed, rate * np.array([1.0, 1.0, 0.5]), rtol=1e-6)


def test_encoder_noise_averages_down_by_the_square_root_of_the_readings():
    """White noise of SD σ: the window mean is off by ~σ/√n (n = 100 readings); 5σ/√n bounds it
    for all three joints at once with odds of ~1e-6 against. The spread estimates σ (within 30 %
    for 100 readings: the SD of a sample SD is σ/√(2n) = 7 %)."""
    sigma = 2e-5
    log = synthetic_log(noise=sigma, seed=3)
    w = still_configuration(log, 1.5)
    assert np.abs(w.q - Q_A).max() < 5 * sigma / np.sqrt(w.samples)
    np.testing.assert_allclose(w.spread, sigma, rtol=0.3)
    assert w.speed.max() < MAX_SPEED_RAD_S / 3  # the noise floor is ~13 times below the threshold


def test_a_mark_while_moving_is_refused_naming_the_joint_and_time():
    log = synthetic_log()
    with pytest.raises(InputError, match=r"log\.csv: the robot was moving at 4\.000 s .*j1 at 0\.\d+ rad/s"):
        still_configuration(log, 4.0)
    # 0.3 s after arriving: the window still holds the end of the move (deceleration).
    with pytest.raises(InputError, match="moving"):
        still_configuration(log, 5.3)
    # 0.6 s after arriving, the window starts after the move: still.
    np.testing.assert_allclose(still_configuration(log, 5.6).q, Q_B, rtol=0, atol=EXACT)


def test_never_extrapolated():
    log = synthetic_log()
    with pytest.raises(InputError, match=r"time -1\.000 s is outside the log's span \[0\.000, 8\.000\] s"):
        still_configuration(log, -1.0)
    with pytest.raises(InputError, match=r"reaches beyond the log's span.*never extrapolated"):
        still_configuration(log, 0.2)
    with pytest.raises(InputError, match="reaches beyond"):
        still_configuration(log, 7.9)


def test_a_sparse_log_cannot_tell_stillness():
    log = synthetic_log(rate_hz=8.0)  # 1-2 readings per 0.2 s span
    with pytest.raises(InputError, match=r"too sparse .*\(at least 3 per speed span"):
        still_configuration(log, 1.5)
    # A longer span judges it (and the window is still exact).
    w = still_configuration(log, 1.5, speed_span_s=0.5)
    np.testing.assert_allclose(w.q, Q_A, rtol=0, atol=EXACT)


def test_window_and_span_are_checked():
    log = synthetic_log()
    with pytest.raises(InputError, match="speed span must be in"):
        still_configuration(log, 1.5, window_s=0.5, speed_span_s=SPEED_SPAN_S * 5)
    with pytest.raises(InputError, match="still window must be"):
        still_configuration(log, 1.5, window_s=0.0)


# --- readers -------------------------------------------------------------------------------------
def test_marks_in_time_order_with_their_rows(tmp_path):
    path = tmp_path / "marks.csv"
    path.write_text("time,kind,tool,name\n12.5,touch,needle,rtip1\n3.0,axes,probe,p2\n7.25, touch ,top_model,rtip2\n")
    marks = read_marks(path)
    assert [(m.time_s, m.kind, m.tool, m.name, m.row) for m in marks] == [
        (3.0, "axes", "probe", "p2", 3),
        (7.25, "touch", "top_model", "rtip2", 4),
        (12.5, "touch", "needle", "rtip1", 2),
    ]


@pytest.mark.parametrize(
    ("row", "message"),
    [
        ("1.0,touched,needle,rtip1", r"row 2, column 'kind': unknown kind 'touched' \(expected touch, axes\)"),
        ("1.0,touch,scalpel,rtip1", r"column 'tool': unknown tool 'scalpel' for a touch mark"),
        ("1.0,axes,top_model,p1", r"column 'tool': unknown tool 'top_model' for an axes mark"),
        ("1.0,touch,needle,p1", r"column 'name': unknown reference tip 'p1'"),
        ("1.0,axes,needle,rtip1", r"column 'name': unknown axes point 'rtip1'"),
        ("x,touch,needle,rtip1", r"column 'time': 'x' is not a number"),
        ("nan,touch,needle,rtip1", r"row 2, column 'time': value is not a finite number, got 'nan'"),
    ],
)
def test_marks_refusals_name_row_and_column(tmp_path, row, message):
    path = tmp_path / "marks.csv"
    path.write_text(f"time,kind,tool,name\n{row}\n")
    with pytest.raises(InputError, match=message):
        read_marks(path)


def test_images_unannotated_rows_and_sample_names(tmp_path):
    path = tmp_path / "images.csv"
    path.write_text("time,u_px,v_px,sample\n1.0,10.5,20.25,a\n2.0,,,\n3.0,30,40,\n")
    frames = read_images(path)
    assert [f.row for f in frames] == [2, 3, 4]
    np.testing.assert_array_equal(frames[0].uv_px, [10.5, 20.25])
    assert frames[1].uv_px is None and frames[1].sample is None
    assert frames[0].sample == "a" and frames[2].sample is None


@pytest.mark.parametrize(
    ("text", "message"),
    [
        ("time,u_px,v_px\n1.0,10,\n", r"row 2, column 'v_px': empty while u_px is given"),
        ("time,u_px,v_px\n1.0,ten,3\n", r"column 'u_px': 'ten' is not a number"),
        ("time,u_px,v_px\n1.0,inf,3\n", r"column 'u_px': must be a finite number"),
        (
            "time,u_px,v_px,sample\n1,1,1,s\n2,2,2,s\n",
            r"row 3, column 'sample': sample 's' appears twice \(also row 2\)",
        ),
        ("time,u_px\n1.0,10\n", r"no 'v_px' column"),
        ("time,u_px,v_px\n", "no frames"),
    ],
)
def test_images_refusals(tmp_path, text, message):
    path = tmp_path / "images.csv"
    path.write_text(text)
    with pytest.raises(InputError, match=message):
        read_images(path)


def markups_file(path, points, system="LPS", units="mm", **extra):
    payload = {
        "@schema": "https://raw.githubusercontent.com/slicer/slicer/master/Modules/Loadable/Markups/Resources/"
        "Schema/markups-schema-v1.0.3.json#",
        "markups": [
            {
                "type": "Fiducial",
                "coordinateSystem": system,
                "coordinateUnits": units,
                "controlPoints": points,
                **extra,
            }
        ],
    }
    path.write_text(json.dumps(payload))
    return path


def test_slicer_markups_lps_ras_and_unplaced_points(tmp_path):
    spacing = (0.19, 0.2)
    points = [
        {"id": "1", "label": "F-1", "position": [0.19 * 100, 0.2 * 50, 0.0], "positionStatus": "defined"},
        {"id": "2", "label": "F-2", "position": [0.0, 0.0, 0.0], "positionStatus": "undefined"},
        {"id": "3", "label": "F-3", "position": [0.19 * 540.5, 0.2 * 359.0, 0.0]},  # status defaults to defined
    ]
    uv = read_slicer_markups(markups_file(tmp_path / "lps.mrk.json", points), spacing)
    np.testing.assert_allclose(uv[0], [100, 50], rtol=0, atol=1e-9)  # pixel = position / spacing
    assert uv[1] is None
    np.testing.assert_allclose(uv[2], [540.5, 359.0], rtol=0, atol=1e-9)
    ras = [{**p, "position": [-p["position"][0], -p["position"][1], 0.0]} for p in points]
    uv_ras = read_slicer_markups(markups_file(tmp_path / "ras.mrk.json", ras, system="RAS"), spacing)
    np.testing.assert_allclose(uv_ras[2], uv[2], rtol=0, atol=1e-9)
    um = [{**p, "position": [x * 1000 for x in p["position"]]} for p in points]
    uv_um = read_slicer_markups(markups_file(tmp_path / "um.mrk.json", um, units="um"), spacing)
    np.testing.assert_allclose(uv_um[0], uv[0], rtol=0, atol=1e-9)


@pytest.mark.parametrize(
    ("points", "options", "message"),
    [
        ([{"position": [1.0, 2.0, 0.5]}], {}, r"control point 1: point lies 0\.5 mm off the frame's plane"),
        ([{"position": [1.0, 2.0]}], {}, r"control point 1: position must be three finite numbers"),
        ([{"position": [1.0, "a", 0]}], {}, "three finite numbers"),
        ([{"position": [1, 2, 0], "positionStatus": "guessed"}], {}, "positionStatus 'guessed'"),
        ([{"position": [1, 2, 0]}], {"system": "IJK"}, "coordinateSystem 'IJK' is neither LPS nor RAS"),
        ([{"position": [1, 2, 0]}], {"units": "cm"}, "coordinateUnits 'cm'"),
        ([], {}, "no control points"),
    ],
)
def test_slicer_markups_refusals(tmp_path, points, options, message):
    path = markups_file(tmp_path / "m.mrk.json", points, **options)
    with pytest.raises(InputError, match=message):
        read_slicer_markups(path, (0.19, 0.19))


def test_slicer_file_with_two_markups_or_not_json_is_refused(tmp_path):
    path = tmp_path / "two.mrk.json"
    path.write_text(json.dumps({"markups": [{"type": "Fiducial"}, {"type": "Fiducial"}]}))
    with pytest.raises(InputError, match=r"one point list.*found 2 markups"):
        read_slicer_markups(path, (0.19, 0.19))
    path.write_text("{not json")
    with pytest.raises(InputError, match="not valid JSON"):
        read_slicer_markups(path, (0.19, 0.19))
    path.write_text(json.dumps({"markups": [{"type": "Line", "controlPoints": []}]}))
    with pytest.raises(InputError, match="'Line', expected a point list"):
        read_slicer_markups(path, (0.19, 0.19))


def test_images_with_markups_pair_by_order(tmp_path):
    images = tmp_path / "images.csv"
    images.write_text("time,sample\n1.0,a\n2.0,b\n")
    frames = read_images(images, markups=[np.array([1.0, 2.0]), None], markups_source="tips.mrk.json")
    np.testing.assert_array_equal(frames[0].uv_px, [1.0, 2.0])
    assert frames[1].uv_px is None and frames[0].annotated_in == "tips.mrk.json, control point 1"
    with pytest.raises(InputError, match="2 frames but 1 control points"):
        read_images(images, markups=[None], markups_source="tips.mrk.json")
    images.write_text("time,u_px,v_px\n1.0,1,2\n")
    with pytest.raises(InputError, match=r"has u_px/v_px columns and annotations come from tips\.mrk\.json"):
        read_images(images, markups=[None], markups_source="tips.mrk.json")
