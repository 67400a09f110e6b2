"""FIGAROH's own UR10 calibration on FIGAROH's data, the peer ``figaroh_mocap.py`` prints beside brachycal.

Run by ``figaroh_mocap.py`` as a subprocess with a Python that has ``figaroh`` installed (it needs
neither brachycal nor its environment): ``figaroh_peer.py DATA_DIR`` prints one JSON line with the
position RMSE per coordinate (mm), the orientation RMSE (deg), the number of parameters and the
FIGAROH version.

FIGAROH 1.0 reads only its unified configuration format and needs the URDF's meshes, so the
example's legacy ``ur10_config.yaml`` is converted with FIGAROH's own migration tool (its template
reference dropped, the robot named, the base and tool frames declared unknown as the legacy format
meant) and the URDF is loaded without its visual and collision elements, in a temporary folder.
The calibration is FIGAROH's default: ``full_params``, the default cost function (SE(3) log map,
body frame), Levenberg–Marquardt, its outlier pass.
"""

from __future__ import annotations

import contextlib
import io
import json
import logging
import subprocess
import sys
import tempfile
import warnings
import xml.etree.ElementTree as ET
from pathlib import Path


def main(data: Path) -> None:
    from importlib.metadata import version as installed  # lazy: FIGAROH's own environment runs this file

    import numpy as np
    import yaml
    from figaroh.calibration.base_calibration import BaseCalibration
    from figaroh.tools.load_robot import load_robot

    ur10 = data / "ur10"
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        legacy = yaml.safe_load((ur10 / "config" / "ur10_config.yaml").read_text())
        legacy["calibration"]["data_file"] = str(ur10 / "data" / "calibration.csv")
        legacy["calibration"]["nb_sample"] = 23
        (folder / "legacy.yaml").write_text(yaml.safe_dump(legacy))
        unified = folder / "unified.yaml"
        subprocess.run(
            [
                sys.executable,
                "-m",
                "figaroh.utils.config_migration",
                "--input",
                str(folder / "legacy.yaml"),
                "--output",
                str(unified),
            ],
            check=True,
            capture_output=True,
        )
        config = yaml.safe_load(unified.read_text())
        config.pop("extends", None)
        config["robot"]["name"] = "ur10"
        config.get("tasks", {}).pop("identification", None)
        unified.write_text(yaml.safe_dump(config))
        tree = ET.parse(ur10 / "urdf" / "ur10_robot.urdf")
        for link in tree.getroot().iter("link"):
            for tag in ("visual", "collision"):
                for element in link.findall(tag):
                    link.remove(element)
        urdf = folder / "robot.urdf"
        tree.write(urdf)

        class UR10(BaseCalibration):
            pass

        logging.disable(logging.CRITICAL)
        with warnings.catch_warnings(), contextlib.redirect_stdout(io.StringIO()):
            warnings.simplefilter("ignore")
            calibration = UR10(load_robot(str(urdf), load_by_urdf=True), str(unified))
            calibration.calib_config["known_baseframe"] = False
            calibration.calib_config["known_tipframe"] = False
            calibration.initialize()
            calibration.solve(enable_logging=False)
        stats = calibration.evaluation_metrics["per_dof_stats"]
        position = np.array(stats["rmse"][:3])
        orientation = np.array(stats["rmse"][3:6])
        print(
            json.dumps(
                {
                    "figaroh": installed("figaroh"),
                    "parameters": len(calibration.calib_config["param_name"]),
                    "position_mm_per_coordinate": float(np.sqrt(np.mean(position**2))),
                    "orientation_deg": float(np.sqrt(np.mean(orientation**2))),
                    "samples": int(calibration.calib_config["NbSample"]),
                }
            )
        )


if __name__ == "__main__":
    main(Path(sys.argv[1]))
