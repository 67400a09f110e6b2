"""Regenerate ``examples/session_exact/``, a noise-free calibration session with its truth.

Run from the repository root: ``python examples/make_session.py``. Deterministic.

The tools and the image sit a few millimetres and degrees away from the URDF's nominal frames
(:func:`brachycal.simulation.default_truth`); every touch is exact and every annotation is the
true pixel, so ``brachycal calibrate examples/session_exact`` must return the truth (written to
``truth.json`` beside the session) and all-zero Tables I and II. Sessions with realistic noise
come from the digital twin.
"""

from __future__ import annotations

from pathlib import Path

from brachycal.data.session import write_session
from brachycal.io import write_json
from brachycal.model import Robot
from brachycal.simulation import default_truth, exact_session


def main() -> None:
    robot = Robot.load()
    truth = default_truth(robot)
    folder = Path(__file__).with_name("session_exact")
    write_session(exact_session(robot, truth), folder, force=True)
    write_json(
        folder / "truth.json",
        {
            "format": "brachycal-truth/1",
            "ER_T_Ntip": truth.T_ER_Ntip.tolist(),
            "EL_T_Ptip": truth.T_EL_Ptip.tolist(),
            "Ptip_T_I": truth.T_Ptip_I.tolist(),
            "spacing_mm": (truth.spacing_m * 1e3).tolist(),
            "reference_tips_m": {"rtip1": truth.p_R_Rtip1.tolist(), "rtip2": truth.p_R_Rtip2.tolist()},
        },
        force=True,
    )
    print(f"wrote {folder}")


if __name__ == "__main__":
    main()
