"""``brachycal examples``: copy the bundled example files out, so that every documented command runs."""

from __future__ import annotations

import argparse
import filecmp
from pathlib import Path

from brachycal.cli.common import add_quiet_option

HELP = "copy the bundled example files (joint log, sessions, pivot, N-wire, phantom, temporal, stepper) into a folder"
DESCRIPTION = """\
Copies the example files that ship with brachycal into DIR: a joint log and a few configurations,
a noise-free session and the digital twin's session (each with its truth), a tracked-pointer pivot
recording, PLUS N-wire files (segmented frames and tracked B-mode sequences), multi-wedge and
arbitrary-wire phantom sessions, a water-tank video and tracker pair with a known lag, a TRUS
probe on a brachytherapy stepper (PLUS's iCal device set and recordings), made by the twin, a
Panda's touches of fixed points and a UR10's tracker table for robot identification (each with
its truth), and the scripts that made them. The README's and the
documentation's commands refer to them as examples/...: run them in the folder where DIR is
examples (in a clone of the repository they are there already).

Files already in DIR with the same content are left as they are; a file with other content is
refused (nothing is copied) unless --force replaces it. Other files in DIR are not touched.

example:
  brachycal examples examples
"""

#: What each top-level entry of the examples is for (a folder, a file, or the scripts ``make_*.py``),
#: printed by the command: the "try" list below runs each.
PURPOSES = {
    "joint_log.csv": "a joint log of the SDA10F (fk: tool poses over time)",
    "joints.csv": "a few SDA10F configurations (locate: where a pixel is)",
    "session_exact": "a noise-free calibration session, with its truth (calibrate: exact answers)",
    "twin_session": "the digital twin's calibration session, with its truth (calibrate, robot identify session)",
    "pivot": "a tracked pointer pivoting (pivot)",
    "nwire": "PLUS N-wire files: segmented frames and tracked B-mode sequences (nwire, nwire segment)",
    "phantom": "multi-wedge and arbitrary-wire phantom sessions (phantom wedge|wire)",
    "temporal": "a water-tank video and tracker pair with a known lag (temporal)",
    "stepper": "a TRUS probe on a brachytherapy stepper, PLUS iCal recordings (stepper calibrate|image)",
    "touches": "a Panda's touches of fixed points, with its truth (robot identify touches)",
    "tracker": "a UR10 seen by a tracker, with its truth (robot identify tracker)",
    "make_*.py": "the scripts that made them",
}

#: What the copy leaves out: Python's caches (an installed package may have them next to the scripts).
_SKIPPED_PARTS = {"__pycache__"}


def add_parser(sub: argparse._SubParsersAction) -> None:
    parser = sub.add_parser(
        "examples", help=HELP, description=DESCRIPTION, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("folder", metavar="DIR", help="folder to copy the examples into (created if missing)")
    parser.add_argument("--force", action="store_true", help="replace files in DIR whose content differs")
    add_quiet_option(parser, "list of the files written or of the commands to try")
    parser.set_defaults(run=run)


def bundled_example_files() -> tuple[Path, list[Path]]:
    """``(the bundled examples folder, its files as paths relative to it, sorted)``."""
    from brachycal.io import bundled  # lazy: start-up (the command's run only)

    source = bundled("examples")
    files = sorted(
        path.relative_to(source)
        for path in source.rglob("*")
        if path.is_file()
        and not _SKIPPED_PARTS.intersection(path.relative_to(source).parts)
        and not path.name.startswith(".")
    )
    return source, files


def run(args: argparse.Namespace) -> int:
    import shutil  # lazy: start-up (the command's run only)

    from brachycal.errors import BrachycalError, InputError  # lazy: start-up (the command's run only)
    from brachycal.io import OutputSet  # lazy: start-up (the command's run only)

    source, files = bundled_example_files()
    if not files:
        raise BrachycalError(f"no bundled examples found in {source} (a broken installation: reinstall brachycal)")
    folder = Path(args.folder)
    if folder.exists() and not folder.is_dir():
        raise InputError("DIR exists and is not a folder", file=folder)
    # Decide everything before writing: same content is kept, other content needs --force.
    to_copy: list[Path] = []
    differing: list[Path] = []
    for name in files:
        target = folder / name
        if target.is_file() and filecmp.cmp(source / name, target, shallow=False):
            continue
        if target.exists() or target.is_symlink():
            if not target.is_file():
                raise InputError("exists and is not a file (an example file goes there)", file=target)
            differing.append(name)
        to_copy.append(name)
    if differing and not args.force:
        more = f" and {len(differing) - 1} other file(s)" if len(differing) > 1 else ""
        raise InputError(
            f"has other content than the bundled example{more} (nothing copied; --force replaces them)",
            file=folder / differing[0],
        )
    with OutputSet(force=args.force) as outputs:
        for name in to_copy:
            staged = outputs.claim(folder / name, make_parents=True, label="DIR")
            shutil.copyfile(source / name, staged)
    kept = len(files) - len(to_copy)
    replaced = f", {len(differing)} replaced" if differing else ""
    print(f"wrote {len(to_copy)} example files to {folder}{replaced} ({kept} already there, the same)")
    if args.quiet:
        return 0
    for name in to_copy:
        print(f"  {folder / name}")
    d = folder.as_posix()
    print("what each is for:")
    for entry, purpose in PURPOSES.items():
        print(f"  {d}/{entry:<16} {purpose}")
    stepper = f"{d}/stepper/twin_"
    print("try (from this folder; the documentation shows more):")
    for line in (
        f"brachycal fk {d}/joint_log.csv --frames needle_tip,probe_tip --out poses.csv",
        f"brachycal calibrate {d}/twin_session --out result.json",
        f"brachycal locate result.json {d}/joints.csv --uv 540,300",
        f"brachycal pivot {d}/pivot/pointer_pivot.csv --units mm --out pivot.json",
        f"brachycal nwire {d}/nwire/PlusDeviceSet_twin_fCal2.xml {d}/nwire/twin_segmented_frames.xml --out nwire.json",
        f"brachycal phantom wedge {d}/phantom/multi_wedge.toml {d}/phantom/wedge_observations.csv "
        "--out phantom_wedge.json",
        f"brachycal temporal {d}/temporal/tank_video.mha {d}/temporal/tank_tracker.mha --out lag.json",
        f"brachycal nwire segment {d}/nwire/twin_calibration.mha {d}/nwire/twin_validation.mha "
        f"--config {d}/nwire/PlusDeviceSet_twin_fCal2.xml --orientation UF --out twin_frames.xml",
        f"brachycal stepper {stepper}ProbeRotation.igs.mha {stepper}ProbeTranslation.igs.mha "
        f"{stepper}TemplateTranslation.igs.mha --config {d}/stepper/PlusDeviceSet_twin_iCal.xml --out stepper.json",
        f"brachycal stepper image {stepper}ProbeRotation.igs.mha {stepper}RandomStepperMotionCalibration.igs.mha "
        f"{stepper}RandomStepperMotionValidation.igs.mha --config {d}/stepper/PlusDeviceSet_twin_iCal.xml "
        "--out stepper_image.json",
        f"brachycal robot identify touches {d}/touches/front {d}/touches/left {d}/touches/right --robot panda "
        "--tool-frame panda_hand_tcp --train front --distance-mm 50 --robot-accuracy-mm 0.3 --robot-accuracy-deg 0.05 "
        "--out touches_identified",
        f"brachycal robot identify tracker {d}/tracker/table.csv --columns {d}/tracker/columns.toml --robot ur10 "
        "--out tracker_identified",
        f"brachycal robot identify session {d}/twin_session --out session_identified",
    ):
        print(f"  {line}")
    return 0
