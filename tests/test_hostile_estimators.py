"""Hostile estimator input: well-formed sessions and pose lists whose data cannot determine the
estimate (touches at one pose, a validation tip that is the calibration tip, samples at one robot
pose or without spread, axes moves of no length, pivots without rotation). Each is refused by the
command with one line naming the session file and the figure that failed, exit code 2, nothing
written — before this, such data gave tips off by hundreds of mm with Table I at 0.00 mm, or
similarity spacings of 1e-31 mm/px, or pivot tips 50–360 mm off at exit 0.

Every session case starts from the committed exact session (``examples/session_exact``) and changes
its data in one way; the conditioning checks themselves are specified in ``test_conditioning.py``.
"""

from __future__ import annotations

import shutil
from collections.abc import Callable
from dataclasses import replace
from functools import cache
from pathlib import Path

import numpy as np
import pytest
from conftest import ROOT
from hostile import Case, check_refusal
from scipy.spatial.transform import Rotation

from brachycal.data.pose_list import COLUMNS
from brachycal.data.session import Session, Touches, read_session, write_session
from brachycal.model import Robot
from brachycal.se3 import make_transform

CALIBRATE = ["calibrate", "{tmp}/session", "--out", "{tmp}/result.json", "--quiet"]


@cache
def robot() -> Robot:
    return Robot.load()


def session(edit: Callable[[Session], Session]):
    """Copy the exact example session to ``{tmp}/session`` with its data changed by ``edit``."""

    def setup(tmp: Path) -> None:
        shutil.copytree(ROOT / "examples" / "session_exact", tmp / "session")
        write_session(edit(read_session(tmp / "session", robot())), tmp / "session", force=True)

    return setup


def touches_copied(source: tuple[str, str], targets: list[tuple[str, str]], shift_rad: float = 0.0):
    """Touch groups ``targets`` replaced by the configurations of ``source`` (plus ``shift_rad``)."""

    def edit(s: Session) -> Session:
        touches = dict(s.touches)
        for target in targets:
            touches[target] = Touches(touches[target].trials, touches[source].q + shift_rad)
        return replace(s, touches=touches)

    return edit


def rtip2_retouches_rtip1(s: Session) -> Session:
    """Every rtip2 touch at its tool's rtip1 configuration, each joint read 1e-5 rad off."""
    touches = dict(s.touches)
    for tool in ("top_model", "needle", "probe"):
        touches[tool, "rtip2"] = Touches(touches[tool, "rtip2"].trials, touches[tool, "rtip1"].q + 1e-5)
    return replace(s, touches=touches)


def all_touches_at_one_configuration(s: Session) -> Session:
    one = s.touches["top_model", "rtip1"].q[:1]
    return replace(
        s, touches={k: Touches(g.trials, np.repeat(one, len(g.trials), axis=0)) for k, g in s.touches.items()}
    )


def samples_at_one_pose(s: Session) -> Session:
    # 1e-9 rad apart (1 nm at the probe), so that no two samples of one pixel are one row copied
    wobble = 1e-9 * np.random.default_rng(8).standard_normal(s.samples_q.shape)
    return replace(s, samples_q=np.repeat(s.samples_q[:1], len(s.samples_q), axis=0) + wobble)


def samples_on_a_line(s: Session) -> Session:
    uv = s.uv_px.copy()
    uv[:, 1] = 100.0 + 0.5 * uv[:, 0]
    return replace(s, uv_px=uv)


def samples_without_spread_across(s: Session) -> Session:
    # The annotated v squeezed to 0.3 px about the image's middle row (the needle tips were not).
    uv = s.uv_px.copy()
    uv[:, 1] = 360.0 + 0.3 * np.sign(uv[:, 1] - uv[:, 1].mean())
    return replace(s, uv_px=uv)


def axes_point(tool: str, point: str, like: str):
    def edit(s: Session) -> Session:
        axes = {t: dict(points) for t, points in s.axes.items()}
        axes[tool][point] = axes[tool][like]
        return replace(s, axes=axes)

    return edit


def poses(rotvecs_deg: np.ndarray):
    """A pose list ``{tmp}/poses.csv`` (millimetres) of a pointer turned by ``rotvecs_deg`` about its tip."""

    def setup(tmp: Path) -> None:
        R = (Rotation.from_euler("x", 180, degrees=True) * Rotation.from_rotvec(np.radians(rotvecs_deg))).as_matrix()
        T = make_transform(R, np.array([700.0, 100.0, 900.0]) - R @ np.array([10.0, -20.0, 150.0]))
        rows = [",".join(COLUMNS)] + [",".join(repr(float(v)) for v in matrix.ravel()) for matrix in T]
        (tmp / "poses.csv").write_text("\n".join(rows) + "\n")

    return setup


PIVOT = ["pivot", "{tmp}/poses.csv", "--units", "mm", "--out", "{tmp}/pivot.json"]
ONE_AXIS = np.column_stack([np.zeros(20), np.zeros(20), np.linspace(-30, 30, 20)])

CASES = [
    # Touches: the needle "touching" at the top-model's very configurations made its tip the
    # top-model's (133 mm off) and Table I 0.00 mm.
    Case(
        "calibrate-needle-touches-copied-from-top-model",
        CALIBRATE,
        ("touches.csv", "needle trial 1 at rtip1 has the joints of the top_model trial 1", "largest difference 0 rad"),
        session(touches_copied(("top_model", "rtip1"), [("needle", "rtip1")])),
    ),
    Case(
        "calibrate-all-touches-at-one-pose",
        CALIBRATE,
        ("touches.csv", "has the joints of", "one recording copied"),
        session(all_touches_at_one_configuration),
    ),
    Case(
        "calibrate-rtip2-is-rtip1",
        CALIBRATE,
        ("touches.csv", "rtip1 and rtip2", "mm apart", "10 predicted SDs", "validate on a second reference tip"),
        session(rtip2_retouches_rtip1),
    ),
    # Samples: one robot pose gave a similarity spacing of 1.9e-31 mm/px and LOO 0.00 mm.
    Case(
        "calibrate-samples-at-one-robot-pose",
        CALIBRATE,
        ("samples.csv", "probe frame (eq. 8) spread only 0.000 mm", "one robot pose"),
        session(samples_at_one_pose),
    ),
    Case(
        "calibrate-samples-collinear-in-the-image", CALIBRATE, ("samples.csv", "collinear"), session(samples_on_a_line)
    ),
    Case(
        "calibrate-samples-without-spread-across-the-image",
        CALIBRATE,
        ("samples.csv", "spread only 0.30 px", "at least", "spread the needle positions over the image"),
        session(samples_without_spread_across),
    ),
    # Axes moves of no length, or along one direction twice.
    Case(
        "calibrate-axes-move-of-zero-length",
        CALIBRATE,
        ("axes.csv", "needle: the move p1->p2 (y axis) is 0.000 mm", "at least 2.9 mm"),
        session(axes_point("needle", "p2", "p1")),
    ),
    Case(
        "calibrate-axes-moves-parallel",
        CALIBRATE,
        ("axes.csv", "probe: the moves p1->p2 and p1->p3 are 0.00 deg apart", "off perpendicular"),
        session(axes_point("probe", "p3", "p2")),
    ),
    # Pivots: 3 poses 0.06° apart or rotations about one axis gave tips 50–360 mm off at exit 0.
    Case(
        "pivot-three-poses-0.06-deg-apart",
        PIVOT,
        ("poses.csv", "orientations do not vary enough", "rotation spread 0.0", "(< 1.15 deg)"),
        poses(np.array([[0.0, 0.0, 0.0], [0.06, 0.0, 0.0], [0.0, 0.06, 0.0]])),
    ),
    Case(
        "pivot-rotations-about-one-axis",
        PIVOT,
        ("poses.csv", "orientations do not vary enough", "rotation spread 0 deg"),
        poses(ONE_AXIS),
    ),
    Case(
        "pivot-robust-rotations-about-one-axis",
        [*PIVOT, "--method", "robust"],
        ("poses.csv", "orientations do not vary enough"),
        poses(ONE_AXIS),
    ),
]


@pytest.mark.parametrize("case", CASES, ids=lambda c: c.id)
def test_estimator_refusals(case, tmp_path):
    check_refusal(case, tmp_path)
