"""Regenerate ``examples/twin_session/``: the digital twin's session with seed 0, and its truth.

Run from the repository root: ``python examples/make_twin_session.py``. Deterministic: the same
files as ``brachycal demo`` simulates (see :mod:`brachycal.simulation.twin` for the noise model;
``truth.json`` and ``physical_robot.urdf`` hold the truth).
"""

from __future__ import annotations

from pathlib import Path

from brachycal.model import Robot
from brachycal.simulation.twin import TwinConfig, simulate
from brachycal.simulation.twin_files import write_twin


def main() -> None:
    folder = write_twin(
        simulate(Robot.load(), TwinConfig(seed=0)), Path(__file__).with_name("twin_session"), force=True
    )
    print(f"wrote {folder}")


if __name__ == "__main__":
    main()
