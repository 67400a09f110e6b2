"""The interactive 3D view: what it shows (checked without a browser), and a headless Chromium
screenshot of the page showing the robot and the sample points."""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from brachycal.calibration import calibrate, read_result, write_result
from brachycal.data import read_session
from brachycal.model import Robot
from brachycal.reporting.viewer import (
    COLOURS,
    ROBOT_RGB,
    ViewContent,
    Viewer,
    calibration_content,
    cube_edges,
)
from brachycal.se3 import transform_points

ROOT = Path(__file__).resolve().parent.parent
EXAMPLE = ROOT / "examples" / "twin_session"


@pytest.fixture(scope="module")
def calibrated(tmp_path_factory: pytest.TempPathFactory):
    robot = Robot.load()
    session = read_session(EXAMPLE, robot)
    path = tmp_path_factory.mktemp("result") / "result.json"
    write_result(calibrate(session, robot, ("kabsch",)), path, robot=robot)
    return robot, session, read_result(path)


def test_the_sample_points_are_the_needle_tips_through_each_arm(calibrated) -> None:
    robot, session, stored = calibrated
    content = calibration_content(robot, stored, session, "kabsch")
    # An independent second computation of eq. (1)'s two sides, with the stored matrices.
    image = stored.image["kabsch"]
    q = session.samples_q
    p_I = np.column_stack([session.uv_px * image.spacing_m, np.zeros(len(q))])
    real = transform_points(robot.fk("arm_right_link_tool0", q), stored.T_ER_Ntip[:3, 3])
    T_R_I = robot.fk("arm_left_link_tool0", q) @ stored.T_EL_Ptip @ image.T_Ptip_I
    calibrated_points = np.einsum("nij,nj->ni", T_R_I[:, :3, :3], p_I) + T_R_I[:, :3, 3]
    # 1e-12 m: the same products in another order; a wrong frame or transform is off by millimetres.
    np.testing.assert_allclose(content.points["real"], real, atol=1e-12)
    np.testing.assert_allclose(content.points["calibrated"], calibrated_points, atol=1e-12)
    a, b = content.vectors["residual"]
    np.testing.assert_array_equal(a, content.points["real"])
    np.testing.assert_array_equal(b, content.points["calibrated"])
    # The robot drawn carries the calibrated image frame: the plane is where the points are.
    T_R_I0 = content.robot.fk("us_image", q[0])
    np.testing.assert_allclose(T_R_I0, T_R_I[0], atol=1e-12)
    assert content.pose_labels == list(session.sample_ids)


def test_the_cube_holds_the_samples_and_has_twelve_equal_edges(calibrated) -> None:
    robot, session, stored = calibrated
    T_cube, edge = calibration_content(robot, stored, session, "kabsch").cube
    assert 0.035 < edge < 0.045  # the 40 mm cube of the 4x4x4 plan, seen through the noisy robot
    a, b = cube_edges(T_cube, edge)
    assert a.shape == b.shape == (12, 3)
    np.testing.assert_allclose(np.linalg.norm(b - a, axis=1), edge, rtol=1e-12)


def test_content_refuses_poses_of_another_robot() -> None:
    robot = Robot.load()
    with pytest.raises(ValueError, match=r"\(M, 15\)"):
        ViewContent(robot, np.zeros((2, 14)), ["a", "b"])
    with pytest.raises(ValueError, match="2 pose labels for 1 poses"):
        ViewContent(robot, np.zeros(15), ["a", "b"])


def _chromium() -> str:
    for name in ("chromium", "chromium-browser", "google-chrome"):
        if found := shutil.which(name):
            return found
    message = "no Chromium for the screenshot test: install Debian's chromium (apt-get install chromium); CI does"
    if os.environ.get("CI"):
        pytest.fail(message)
    pytest.skip(message)


def _screenshot(url: str, png: Path, profile: Path, ready: Callable[[np.ndarray], bool]) -> np.ndarray:
    """A screenshot of ``url`` in headless Chromium once ``ready(shot)`` holds, or the last of a few.

    The scene reaches the page over a websocket after the page has loaded, and software WebGL draws
    it slowly on a loaded machine: one fixed wait would be flaky, so each attempt waits longer. A
    Chromium that hangs (seen once with two test suites sharing two cores) is an attempt that failed:
    the next one starts a new browser; the caller's checks of the shot stay as they are."""
    from PIL import Image

    shot = np.zeros((1, 1, 3), dtype=int)
    for budget_ms, timeout_s in ((8_000, 120), (20_000, 180), (45_000, 300)):
        try:
            subprocess.run(
                [
                    _chromium(),
                    "--headless",
                    "--no-sandbox",
                    "--disable-gpu",
                    "--enable-unsafe-swiftshader",
                    "--disable-quic",
                    "--no-first-run",
                    "--disable-background-networking",
                    "--disable-component-update",
                    "--disable-sync",
                    f"--user-data-dir={profile / str(budget_ms)}",  # a new one: a hung browser may hold the last
                    "--window-size=900,700",
                    f"--virtual-time-budget={budget_ms}",
                    f"--screenshot={png}",
                    url,
                ],
                check=True,
                capture_output=True,
                timeout=timeout_s,
            )
        except subprocess.TimeoutExpired:
            continue
        shot = np.asarray(Image.open(png).convert("RGB")).astype(int)
        if ready(shot):
            break
    return shot


def _pixels(shot: np.ndarray, rgb: tuple[int, int, int], tolerance: int = 40) -> int:
    """Pixels within ``tolerance`` per channel of ``rgb`` (shading moves a flat colour by up to ~30)."""
    return int((np.abs(shot - np.array(rgb)).max(axis=2) < tolerance).sum())


def _hue_pixels(shot: np.ndarray, rgb: tuple[int, int, int], window_deg: float = 12.0) -> int:
    """Saturated pixels of ``rgb``'s hue (± ``window_deg``): the points are lit spheres, which shading
    lightens by up to ~60 per channel but leaves at their hue; the frames' red and blue axes, the
    nearest other hues, are 20° and more away."""
    from matplotlib.colors import rgb_to_hsv

    hsv = rgb_to_hsv(shot / 255.0)
    hue = rgb_to_hsv(np.array(rgb) / 255.0)[0]
    distance = np.abs((hsv[..., 0] - hue + 0.5) % 1.0 - 0.5) * 360.0
    return int(((distance < window_deg) & (hsv[..., 1] > 0.35) & (hsv[..., 2] > 0.3)).sum())


@pytest.mark.slow
def test_a_headless_browser_shows_the_robot_and_the_points(calibrated, tmp_path: Path) -> None:
    robot, session, stored = calibrated
    chromium = _chromium()
    assert chromium
    # Without the image plane: the points lie in it, and its half-transparent orange tints them.
    content = replace(calibration_content(robot, stored, session, "kabsch"), image_size_px=None)
    viewer = Viewer(content, port=0)
    # The robot covers a good part of the page; the 2 × 64 points show in their colours (each ~10 px).
    checks = {
        "robot": lambda shot: _pixels(shot, ROBOT_RGB) > 0.02 * shot.shape[0] * shot.shape[1],
        "needle tips through the needle arm": lambda shot: _hue_pixels(shot, COLOURS["real"]) >= 200,
        "needle tips through the image": lambda shot: _hue_pixels(shot, COLOURS["calibrated"]) >= 200,
    }
    try:
        shot = _screenshot(
            viewer.url, tmp_path / "view.png", tmp_path / "profile", lambda s: all(c(s) for c in checks.values())
        )
    finally:
        viewer.close()
    assert not [name for name, check in checks.items() if not check(shot)]


@contextmanager
def _served(result: str) -> Iterator[tuple[subprocess.Popen[str], str]]:
    """``brachycal view RESULT --session EXAMPLE --port 0`` running; yields it and its address, then
    sends SIGTERM (the caller checks how it ended)."""
    view = subprocess.Popen(
        [sys.executable, "-m", "brachycal.cli.main", "view", result, "--session", str(EXAMPLE), "--port", "0"],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    try:
        lines: list[str] = []
        while len(lines) < 20 and lines[-1:] != [""]:  # viser's own banner comes first; "" is the end
            lines.append(view.stdout.readline())
            if lines[-1].startswith("brachycal view: http://127.0.0.1:"):
                break
        assert lines[-1].startswith("brachycal view: "), "".join(lines)
        yield view, lines[-1].split()[2]
    finally:
        view.terminate()
        view.wait(timeout=30)


@pytest.mark.slow
def test_the_command_serves_the_view_and_stops_on_sigterm(calibrated, tmp_path: Path) -> None:
    _chromium()
    with _served(calibrated[2].source) as (view, url):
        # The robot. (Not the half-transparent image plane: software WebGL on a loaded machine has
        # left it out of a screenshot now and then, seen on a fresh clone; where it is drawn is
        # checked without a browser, test_the_sample_points_are_the_needle_tips_through_each_arm.)
        checks = {"robot": lambda shot: _pixels(shot, ROBOT_RGB) > 0.02 * shot.shape[0] * shot.shape[1]}
        shot = _screenshot(
            url, tmp_path / "view.png", tmp_path / "profile", lambda s: all(c(s) for c in checks.values())
        )
        assert not [name for name, check in checks.items() if not check(shot)]
    assert view.returncode == 143, view.stderr.read()
    assert view.stderr.read().strip().splitlines()[-1] == "brachycal: terminated"


def test_the_command_serves_a_page_without_a_browser_and_stops_on_sigterm(calibrated) -> None:
    """Serving and stopping need no browser: this runs everywhere (the screenshots need Chromium)."""
    from urllib.request import urlopen

    with _served(calibrated[2].source) as (view, url), urlopen(url, timeout=30) as page:
        assert page.status == 200 and b"<html" in page.read().lower()
    assert view.returncode == 143


def test_view_of_a_result_names_the_method_it_shows(calibrated) -> None:
    from brachycal.cli.main import build_parser
    from brachycal.cli.view import _content

    _, _, stored = calibrated
    parser = build_parser()
    args = parser.parse_args(["view", stored.source, "--session", str(EXAMPLE)])
    assert _content(args)[1].startswith("kabsch (the result's best: lowest leave-one-out RMSE, ")
    args = parser.parse_args(["view", stored.source, "--session", str(EXAMPLE), "--method", "kabsch"])
    assert _content(args)[1] == "kabsch (--method)"
    # Without a result there is no calibration to name.
    assert _content(parser.parse_args(["view", "--session", str(EXAMPLE)]))[1] is None
