"""Full sequential calibration with leave-one-out for 64 samples and every method.

Run: ``.venv/bin/python benchmarks/calibrate_speed.py``. Prints the best of five runs of
:func:`brachycal.calibration.calibrate` on a 64-sample session (session reading excluded and
timed separately), and the time per method. The paper's processing took under 1 s.
"""

from __future__ import annotations

import tempfile

from timing import best_of

from brachycal.calibration import METHODS, calibrate
from brachycal.data.session import read_session, write_session
from brachycal.model import Robot
from brachycal.simulation import default_truth, exact_session


def main() -> None:
    robot = Robot.load()
    session = exact_session(robot, default_truth(robot))
    with tempfile.TemporaryDirectory() as tmp:
        write_session(session, tmp, force=True)
        read_s = best_of(5, lambda: read_session(tmp, robot))
    total = best_of(5, lambda: calibrate(session, robot))
    print(f"sequential calibration, {len(session.sample_ids)} samples, all {len(METHODS)} methods with LOO-CV")
    print(f"  total (tips, rotations, {len(METHODS)} fits + {len(METHODS)} x 64 LOO fits): {total * 1e3:.1f} ms")
    print(f"  reading and validating the session folder: {read_s * 1e3:.1f} ms")
    base = best_of(5, lambda: calibrate(session, robot, methods=()))
    print(f"  tips and rotations alone: {base * 1e3:.1f} ms")
    for method in METHODS:
        t = best_of(5, lambda m=method: calibrate(session, robot, methods=(m,))) - base
        print(f"  {method:<10} fit + 64 LOO fits: {t * 1e3:7.1f} ms")


if __name__ == "__main__":
    main()
