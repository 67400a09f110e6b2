"""The demo: the paper's calibration of a digital-twin session, judged against the twin's truth.

What ``brachycal demo`` runs (:func:`run_demo`): a twin session with the paper's set-up is
simulated (or the committed example is read), its files are written, the session is calibrated
*from those files* as a lab would (so the files are what the numbers come from), and the
calibration is judged by the end-to-end targeting error of every method on the same simulated
robot, next to the tracker route (N-wire phantom + hand–eye with an optical tracker, Table III).
The returned :class:`DemoRun` holds everything the tables and figures show
(:mod:`brachycal.reporting.demo_report` renders them).

Any robot with a description (``robot.rig``): the twin plans in its workspace, touches and moves
with its arms; the committed example is the SDA10F's only.
"""

from __future__ import annotations

import os
import tempfile
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path

from brachycal.calibration.image_to_probe import METHODS
from brachycal.calibration.result_file import write_result
from brachycal.calibration.sequential import CalibrationResult, calibrate, loo_points
from brachycal.data.session import FILES as SESSION_FILES
from brachycal.data.session import Session, read_session
from brachycal.errors import InputError
from brachycal.files import OutputSet, bundled, output_set
from brachycal.imaging.pixels import image_points
from brachycal.model.robot import Robot
from brachycal.se3 import FloatArray, transform_points
from brachycal.simulation.nwire_twin import NWireSimConfig, tracker_route
from brachycal.simulation.targeting import TargetingResult, targeting_error
from brachycal.simulation.twin import Twin, TwinConfig, simulate
from brachycal.simulation.twin_files import read_twin, write_twin

#: The method whose leave-one-out points the demo's figures show (Figs. 10 and 11).
FIGURE_METHOD = "icp"
#: The methods whose calibrated image frame the demo compares with the truth.
TRUTH_METHODS = ("kabsch", "scaled_uv")


@dataclass(frozen=True)
class DemoRun:
    """A demo's session, calibration and judgement (SI units; ``base_link`` unless said).

    Attributes:
        origin: where the session came from, in words (a seed, or the committed example).
        twin: the simulated session with its truth.
        session: the session as read back from the files written (what was calibrated).
        result: the sequential calibration of it.
        n_targets: targets of the targeting error.
        targeting: method → its end-to-end targeting error.
        tracking: the tracker route's settings.
        tracker: the tracker route's targeting error (Table III).
        loo_real_m, loo_cal_m: ``(N, 3)`` :data:`FIGURE_METHOD`'s leave-one-out points.
    """

    origin: str
    twin: Twin
    session: Session
    result: CalibrationResult
    n_targets: int
    targeting: dict[str, TargetingResult]
    tracking: NWireSimConfig
    tracker: TargetingResult
    loo_real_m: FloatArray
    loo_cal_m: FloatArray

    def tip_errors_m(self) -> tuple[FloatArray, FloatArray]:
        """``(3,)`` needle tip and ``(3,)`` probe tip, calibrated minus true, on their flanges."""
        truth, result = self.twin.truth, self.result
        return result.T_ER_Ntip[:3, 3] - truth.T_ER_Ntip[:3, 3], result.T_EL_Ptip[:3, 3] - truth.T_EL_Ptip[:3, 3]

    def image_centre_error_m(self, method: str) -> FloatArray:
        """``(3,)`` where ``method`` puts the planned cube centre's pixel on the left flange, minus the truth.

        A secondary figure: a calibration rightly absorbs part of the robot's own error, so it
        need not reproduce the true transforms to target well.
        """
        truth, image = self.twin.truth, self.result.image[method]
        centre_px = self.twin.config.spec.centre_px
        calibrated = transform_points(self.result.T_EL_Ptip @ image.T_Ptip_I, image_points(centre_px, image.spacing_m))
        true = transform_points(truth.T_EL_Ptip @ truth.T_Ptip_I, image_points(centre_px, truth.spacing_m))
        return (calibrated - true)[0]


def check_example_robot(robot: Robot) -> None:
    """Refuse the committed example (``examples/twin_session``, simulated on the SDA10F) for another robot.

    Raises:
        InputError: ``robot`` is not the SDA10F.
    """
    name = robot.rig.name
    if name != "sda10f":
        raise InputError(
            f"the committed example examples/twin_session is the SDA10F's, not {name!r}'s: "
            "simulate one instead (drop --example)"
        )


@contextmanager
def _as_written(outputs: OutputSet, session_dir: Path) -> Iterator[Path]:
    """A temporary folder showing the staged session files under their own names (symlinks)."""
    with tempfile.TemporaryDirectory(prefix="brachycal-demo-") as tmp:
        for name in SESSION_FILES:
            os.symlink(outputs.path(session_dir / name).absolute(), Path(tmp) / name)
        yield Path(tmp)


def run_demo(
    robot: Robot,
    folder: str | os.PathLike[str],
    *,
    seed: int = 0,
    example: bool = False,
    n_targets: int = 50,
    force: bool = False,
    outputs: OutputSet | None = None,
) -> DemoRun:
    """Simulate (or read) a twin session, write it, calibrate it from its files, judge it.

    Writes ``folder/session`` (the session, ``truth.json`` and ``physical_robot.urdf``:
    :data:`~brachycal.simulation.twin_files.TWIN_FILES`) and ``folder/result.json``. All or
    nothing: with ``outputs`` (a command's :class:`~brachycal.files.OutputSet`) the files join
    that set and are committed with it; without, they are committed together on return.

    Args:
        robot: the nominal model (the software's).
        folder: where the session and the result go.
        seed: the simulated session's seed (ignored with ``example``).
        example: calibrate the committed ``examples/twin_session`` (seed 0, the SDA10F's) instead.
        n_targets: targets of the targeting error.
        force: replace existing files.

    Raises:
        SolverError: a pose of the set-up is unreachable for the simulated robot.
        OutputError: a file cannot be written.
        InputError: ``example`` with a robot other than the SDA10F.
    """
    folder = Path(folder)
    rig = robot.rig
    if example:
        check_example_robot(robot)
        twin = read_twin(bundled("examples", "twin_session"), robot)
        origin = "the committed example examples/twin_session"
    else:
        twin = simulate(robot, TwinConfig(seed=seed))
        origin = (
            f"a simulated session (seed {seed})"
            if rig.name == "sda10f"
            else f"a simulated {rig.name} session (seed {seed})"
        )
    session_dir = folder / "session"
    with output_set(outputs, force=force) as out:
        write_twin(twin, session_dir, force=force, outputs=out)
        # Calibrate from the files as written (the staged ones: the same bytes the folder will hold).
        with _as_written(out, session_dir) as written:
            session = read_session(written, robot)
        result = calibrate(session, robot)
        write_result(result, out.path(folder / "result.json", make_parents=True), force=force, robot=robot)
    targeting = {
        m: targeting_error(twin, result.T_ER_Ntip, result.T_EL_Ptip, result.image[m], n_targets) for m in METHODS
    }
    tracking = NWireSimConfig(seed=twin.config.seed)
    route = tracker_route(twin, tracking)
    tracker = targeting_error(twin, result.T_ER_Ntip, route.T_EL_marker, route.image, n_targets)
    p_real, p_cal = loo_points(session, robot, result, FIGURE_METHOD)
    return DemoRun(origin, twin, session, result, n_targets, targeting, tracking, tracker, p_real, p_cal)
