"""A twin on disk: the session folder plus ``truth.json`` and ``physical_robot.urdf`` beside it.

``truth.json`` (format ``brachycal-truth/1``) holds the true tool and image transforms (metres),
the true and nominal pixel spacings, the reference tips, the noise settings, and per sample the
true joints, the needle tip's distance from the image plane and the outlier flags; the
physical robot (perturbed kinematics, true tool frames) is a URDF that loads like any other.
Together they let anyone judge a calibration of the session against the truth.
"""

from __future__ import annotations

import dataclasses
import os
from pathlib import Path

import numpy as np

from brachycal.data.json_files import read_format_json
from brachycal.data.session import FILES as SESSION_FILES
from brachycal.data.session import read_session, write_session
from brachycal.errors import InputError
from brachycal.io import OutputSet, output_set, write_json
from brachycal.model.robot import Robot
from brachycal.planning import PlanSpec, SectorFOV
from brachycal.simulation.exact import SessionTruth
from brachycal.simulation.twin import Twin, TwinConfig

FORMAT = "brachycal-truth/1"
TWIN_FILES = (*SESSION_FILES, "physical_robot.urdf", "truth.json")
"""The files :func:`write_twin` writes into its folder."""


def _config_json(config: TwinConfig) -> dict:
    out = {f.name: getattr(config, f.name) for f in dataclasses.fields(config) if f.name != "spec"}
    spec = config.spec
    out["spec"] = {
        "cube_centre_m": spec.cube_centre_m.tolist(),
        "edge_m": spec.edge_m,
        "points_per_axis": spec.points_per_axis,
        "insertion_dir": spec.insertion_dir.tolist(),
        "image_depth_dir": spec.image_depth_dir.tolist(),
        "image_lateral_dir": spec.image_lateral_dir.tolist(),
        "centre_px": list(spec.centre_px),
        "spacing_m": spec.spacing_m.tolist(),
    }
    return {k: (list(v) if isinstance(v, tuple) else v) for k, v in out.items()}


def write_twin(
    twin: Twin, folder: str | os.PathLike[str], *, force: bool = False, outputs: OutputSet | None = None
) -> Path:
    """Write the session and its truth to ``folder`` (created if needed): :data:`TWIN_FILES`.

    All or nothing: with ``outputs`` (a command's :class:`~brachycal.io.OutputSet`) the files
    join that set and are committed with it; without, they are committed together on return.
    """
    folder = Path(folder)
    with output_set(outputs, force=force) as out:
        write_session(twin.session, folder, force=force, outputs=out)
        twin.physical.write_urdf(out.path(folder / "physical_robot.urdf", make_parents=True), force=force)
        write_json(out.path(folder / "truth.json", make_parents=True), _truth_json(twin), indent=1)
    return folder


def _truth_json(twin: Twin) -> dict:
    t = twin.truth
    payload = {
        "format": FORMAT,
        "ER_T_Ntip": t.T_ER_Ntip.tolist(),
        "EL_T_Ptip": t.T_EL_Ptip.tolist(),
        "Ptip_T_I": t.T_Ptip_I.tolist(),
        "spacing_mm": (t.spacing_m * 1e3).tolist(),
        "nominal_spacing_mm": (t.nominal_spacing_m * 1e3).tolist(),
        "top_model_tip_m": t.p_ER_Mtip.tolist(),
        "reference_tips_m": {"rtip1": t.p_R_Rtip1.tolist(), "rtip2": t.p_R_Rtip2.tolist()},
        "config": _config_json(twin.config),
        "true_samples_q": twin.true_samples_q.tolist(),
        "out_of_plane_m": twin.out_of_plane_m.tolist(),
        "outlier": twin.outlier.tolist(),
    }
    return payload


def read_twin(folder: str | os.PathLike[str], nominal: Robot) -> Twin:
    """Read a twin written by :func:`write_twin` (the session is validated as usual).

    ``nominal`` is the robot the twin was simulated with (any description): the physical robot's
    URDF is read with its rig.

    Raises:
        InputError: not a twin folder, or a file of it that does not fit ``nominal`` (other joints).
    """
    folder = Path(folder)
    path = folder / "truth.json"
    if not path.is_file():
        raise InputError("no truth.json: not a simulated session", file=path)
    raw = read_format_json(path, FORMAT)
    settings = dict(raw["config"])
    spec = settings.pop("spec")
    spec = PlanSpec(
        cube_centre_m=np.array(spec["cube_centre_m"]),
        edge_m=spec["edge_m"],
        points_per_axis=spec["points_per_axis"],
        insertion_dir=np.array(spec["insertion_dir"]),
        image_depth_dir=np.array(spec["image_depth_dir"]),
        image_lateral_dir=np.array(spec["image_lateral_dir"]),
        centre_px=tuple(spec["centre_px"]),
        spacing_m=np.array(spec["spacing_m"]),
        fov=SectorFOV(),
    )
    settings["outlier_px"] = tuple(settings["outlier_px"])
    config = TwinConfig(**settings, spec=spec)
    session = read_session(folder, nominal)
    truth = SessionTruth(
        T_ER_Ntip=np.array(raw["ER_T_Ntip"]),
        T_EL_Ptip=np.array(raw["EL_T_Ptip"]),
        T_Ptip_I=np.array(raw["Ptip_T_I"]),
        spacing_m=np.array(raw["spacing_mm"]) * 1e-3,
        nominal_spacing_m=np.array(raw["nominal_spacing_mm"]) * 1e-3,
        p_ER_Mtip=np.array(raw["top_model_tip_m"]),
        p_R_Rtip1=np.array(raw["reference_tips_m"]["rtip1"]),
        p_R_Rtip2=np.array(raw["reference_tips_m"]["rtip2"]),
        size_px=session.size_px.copy(),  # the simulated images' size, as the session states it
    )
    physical = Robot.load(folder / "physical_robot.urdf").with_rig(nominal.rig)
    return Twin(
        session,
        truth,
        physical,
        nominal,
        config,
        np.array(raw["true_samples_q"]),
        np.array(raw["out_of_plane_m"]),
        np.array(raw["outlier"], dtype=bool),
    )
