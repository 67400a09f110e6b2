"""``brachycal robot identify session``: the dual-arm rig's joint geometry identified jointly with
the whole chain from its calibration session, judged at held-out configurations (K-fold)."""

from __future__ import annotations

import argparse
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from pathlib import Path

    from brachycal.calibration.robot.identification import SessionIdentification
    from brachycal.model import Robot

HELP = "the dual-arm rig: its calibration session; judged at held-out configurations (K-fold)"
#: The protocol needs the dual-arm rig (a needle arm and a probe arm).
ANY_ARM = False
DESCRIPTION = """\
Identifies the dual-arm rig's joint geometry (every joint origin's small translation and rotation)
jointly with the whole chain (the tools, the image calibration) from its calibration SESSION (a
session folder, as brachycal calibrate reads), the stated accuracy the corrections' prior. The
image model is chosen by cross-validation first. Judged at held-out configurations: the session's
samples are split into folds, each predicted by a chain fit and by a chain-plus-robot
identification made without it (an identification that over-fits predicts worse, not better).
Printed: the held-out image error first (chain alone -> robot identified), the training error
second, then which combinations of corrections the session determines, and last the verdict: use
the identified robot (its held-out gain exceeds twice its standard error over the folds) or keep
the URDF. It refits the chain and the robot nine times (about 4 s for a 64-sample session on a free
core, more while other programs run); a progress bar counts them in a terminal.

The robot: --robot NAME|FILE, a dual-arm rig (bundled: sda10f, baxter, ur5_pair; or a
brachycal-robot/1 description), or --urdf FILE (an SDA10F URDF); default the bundled SDA10F.
A single arm is refused (its protocols are touches and tracker).

Writes DIR/robot.urdf (the identified robot) and DIR/identification.json (corrections, prior,
identifiability, figures). The same identification runs in brachycal calibrate --solve chain
--identify-robot, which also writes the image calibration.

On the twin's session of the example files (brachycal examples DIR):

example:
  brachycal robot identify session examples/twin_session --robot sda10f --out identified
"""


def add_options(parser: argparse.ArgumentParser) -> None:
    """The session protocol's own options (the robot, --out and --force: :mod:`brachycal.cli.robot.identify`)."""
    from brachycal.cli.common import add_robot_accuracy_options  # lazy: start-up (the command's run only)

    parser.add_argument("session", metavar="SESSION", help="the session folder (session.toml, samples.csv, ...)")
    add_robot_accuracy_options(parser, "the prior of the corrections", zero=False)


def run(args: argparse.Namespace) -> int:
    from pathlib import Path  # lazy: start-up (the command's run only)

    from brachycal.calibration import calibrate  # lazy: start-up (the command's run only)
    from brachycal.calibration.robot.identification import (  # lazy: start-up (the command's run only)
        IDENTIFICATION_FOLDS,
        identify_session,
    )
    from brachycal.cli.common import (
        command_inputs,
        load_robot,
        progress_bar,
        robot_accuracy,
    )  # lazy: start-up (the command's run only)
    from brachycal.cli.robot.report import claim_outputs  # lazy: start-up (the command's run only)
    from brachycal.data.session import read_session  # lazy: start-up (the command's run only)
    from brachycal.io import OutputSet, write_json  # lazy: start-up (the command's run only)

    out = Path(args.out)
    with OutputSet(force=args.force, inputs=command_inputs(args, "session")) as outputs:
        urdf_path, json_path = claim_outputs(outputs, out)
        nominal = load_robot(args)  # refuses a single arm in one line
        session = read_session(args.session, nominal)
        initial = calibrate(session, nominal, ("scaled_uv",))
        with progress_bar(IDENTIFICATION_FOLDS + 1, "identifying, then K-fold", args.quiet, unit="fit") as bar:
            result = identify_session(session, nominal, initial, robot_accuracy(args), progress=bar.update)
        result.identification.robot(nominal).write_urdf(urdf_path, force=True)
        write_json(json_path, {"session": str(args.session), **result.as_json()}, force=True)
    print_report(result, nominal, urdf=out / "robot.urdf")
    print(f"wrote {out / 'robot.urdf'} and {out / 'identification.json'}")
    return 0


def print_report(result: SessionIdentification, nominal: Robot, urdf: Path | None = None) -> None:
    """Held-out (K-fold) image error first, then training; the noise; the identifiability in short;
    the verdict (use the identified robot, written to ``urdf``, or keep the URDF) last."""
    from brachycal.cli.robot.report import print_identifiability  # lazy: start-up (the command's run only)

    (held_a, held_b), (train_a, train_b) = result.held_out, result.training
    print(
        f"held-out configurations ({result.folds}-fold, {held_a.n} samples): image error RMSE, chain alone "
        f"-> robot identified: {held_a.rmse_mm:.3f} -> {held_b.rmse_mm:.3f} mm"
    )
    print(
        f"training ({train_b.n} samples): image error RMSE, chain alone -> robot identified: "
        f"{train_a.rmse_mm:.3f} -> {train_b.rmse_mm:.3f} mm"
    )
    identification = result.identification
    noise = ", ".join(f"{g} {n.sd_m * 1e3:.3f}" for g, n in identification.fit.noise.items())
    print(f"{result.model} image model; noise SD per coordinate (mm): {noise}")
    print_identifiability(identification.identifiability, identification.joint_names)
    verdict = result.verdict
    where = (urdf or "the identified robot's URDF") if verdict.use else "the URDF it started from"
    print(f"verdict: {verdict.sentence()}; use {where}")
