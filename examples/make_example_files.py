"""Regenerate the examples the documented commands use besides the sessions and the joint log.

Run from the repository root: ``python examples/make_example_files.py``. Deterministic. Writes:

- ``joints.csv``: three configurations of the robot (for ``brachycal locate``): the twin session's
  first, middle and last samples as read (``examples/twin_session/samples.csv``), radians.
- ``pivot/``: a tracked pointer pivoting about a fixed point, in the pose-list format of
  SciKit-Surgery's real recording (``timestamp_ns,m00,…,m33``, millimetres), and its truth
  (:func:`brachycal.studies.example_files.simulate_pivot_recording`).
- ``nwire/``: a PLUS device-set configuration (fCal 2.0 phantom) and a segmented-frames file of a
  tracked probe over it, in PLUS's formats, and their truth (the twin's tracker route,
  :func:`brachycal.studies.nwire_twin.simulate_nwire`); and the first of those frames rendered as
  tracked B-mode sequences (``twin_calibration.mha``, ``twin_validation.mha``) for ``brachycal nwire segment``.
- ``phantom/``: a multi-wedge and an arbitrary-wire session of the same tracked probe (observations
  CSV and each phantom's geometry TOML with the session's landmark registration) and their truth
  (:func:`brachycal.studies.phantom_twin.simulate_phantom`), for ``brachycal phantom``.
- ``temporal/``: a PLUS water-tank video and tracker sequence pair with a known lag and its truth
  (:func:`brachycal.studies.tank_recording.write_tank_files`), for ``brachycal temporal``.
- ``touches/``: a Panda off its URDF touching two sockets at three places (``<place>/hole_k.csv``,
  MUKCa's layout) and its truth (:func:`brachycal.simulation.simulate_touches`), for
  ``brachycal robot identify touches``.
- ``tracker/``: a UR10 off its URDF seen by a tracker (a 6-D marker): the table, its column spec and
  the truth (:func:`brachycal.simulation.simulate_tracker`), for ``brachycal robot identify tracker``.
- ``stepper/``: a TRUS probe on a brachytherapy stepper (PLUS's iCal set-up): the device set, the
  probe-rotation, probe- and template-translation and random-motion recordings (PLUS ``.igs.mha``
  with the stepper's encoder fields) and their truth (:mod:`brachycal.studies.stepper_twin`), for
  ``brachycal stepper``.
"""

from __future__ import annotations

import csv
from pathlib import Path

from brachycal.io import OutputSet
from brachycal.model.names import JOINT_NAMES
from brachycal.studies.example_files import write_example_files

HERE = Path(__file__).parent
#: The twin session's samples (rows of samples.csv) copied into joints.csv: first, middle, last.
SAMPLES = (0, 31, 63)


def main() -> None:
    with (HERE / "twin_session" / "samples.csv").open(newline="") as handle:
        rows = list(csv.DictReader(handle))
    with OutputSet(force=True) as outputs:
        staged = outputs.claim(HERE / "joints.csv")
        with staged.open("w", newline="") as handle:
            writer = csv.writer(handle, lineterminator="\n")
            writer.writerow(JOINT_NAMES)
            for sample in SAMPLES:
                writer.writerow(rows[sample][name] for name in JOINT_NAMES)
        written = write_example_files(HERE, force=True, outputs=outputs)
    for path in [HERE / "joints.csv", *written]:
        print(f"wrote {path}")


if __name__ == "__main__":
    main()
