"""Blank templates of a lab's own session: ``session.toml`` and the recording's ``marks.csv`` and ``images.csv``.

The CSV readers refuse anything that is not a row (no comment lines), so the CSV templates are
header-only and ``README.txt`` explains every file and column. ``session.toml`` has a comment on
every key; its values are empty lists that the session reader refuses, naming the key, until the
lab fills them in: a template never calibrates with another lab's spacing or tip by mistake.
"""

from __future__ import annotations

import os
from pathlib import Path

from brachycal.data.session import FORMAT
from brachycal.io import OutputSet, atomic_open, output_set

#: The files of a template folder, in the order they are written.
TEMPLATE_FILES = ("session.toml", "marks.csv", "images.csv", "README.txt")

SESSION_TOML = f"""\
# session.toml of a brachycal calibration session. Fill in the three empty lists, then use it as
# `brachycal session build ... --template session.toml`. A list left empty is refused, naming its key.

# The file format; leave as it is.
format = "{FORMAT}"

[image]
# Pixel spacing (s_u, s_v) of the ultrasound frames, millimetres per pixel, as the scanner states
# it at the depth setting used: s_u along image columns (u), s_v along rows (v). E.g. [0.19, 0.19].
spacing_mm = []
# Size (width, height) of the frames in whole pixels, as annotated in images.csv. E.g. [1080, 720].
size_px = []

# Optional: the probe's imaging sector (the pixels that show tissue), for the report's map of the
# predicted landing error. Uncomment and fill in for a convex probe: the apex (u, v) in pixels (the
# transducer's centre; v < 0 above the image), the depth in millimetres and the full opening angle
# in degrees, symmetric about the depth (+v) direction.
# [image.sector]
# apex_px = [540, 0]
# depth_mm = 70
# angle_deg = 120

[top_model]
# The top-model's tip in the needle arm's flange frame (the SDA10F's right flange), millimetres
# (x, y, z): p_ER_Mtip, from the top-model's CAD and test report. E.g. [0.0, 0.0, 150.0].
tip_in_flange_mm = []
"""

MARKS_HEADER = "time,kind,tool,name\n"
IMAGES_HEADER = "time,u_px,v_px\n"

_IMAGES = """\
images.csv: time,u_px,v_px[,sample]
  One row per captured ultrasound frame with the needle tip in it.
    time    seconds on the joint log's clock (each frame listed once)
    u_px    the needle tip's column, pixels, origin at the centre of pixel (0, 0)
    v_px    the needle tip's row, pixels; u_px and v_px both empty: not annotated (skipped)
    sample  optional (add it to the header to use it): a name for the sample (unique, a plain
            token); without it the frame is paired with the nearest pose of --plan, or named
            frame<k> (the k-th frame of the file)
  Example row:
    40.250000,512.4,301.7

The files hold only their header line: add rows below it, no comment lines (a line that is not
a row is refused, naming its row).
"""

_JOINT_LOG = """\
JOINT_LOG (recorded by the robot's controller; not here)
  The joint states through the whole {what}: a CSV file with a column `time` (seconds) and one
  column per joint of the robot (radians, named as in its description), or a ROS 1/2 bag with
  sensor_msgs/JointState messages. All times below are seconds on this log's clock.
"""

README = (
    """\
A blank brachycal session: fill these files in during and after the calibration, then

  brachycal session build JOINT_LOG --marks marks.csv --images images.csv --template session.toml \\
      --out SESSION
  brachycal calibrate SESSION --out result.json

session.toml
  The set-up's values: pixel spacing and size of the frames and the top-model's tip on the
  needle arm's flange. Each key has a comment; fill in the three empty lists (or give their
  values to `session build` as --spacing-mm, --size-px and --top-model-tip-mm).

"""
    + _JOINT_LOG.format(what="session")
    + """
marks.csv: time,kind,tool,name
  One row per moment the operator marked, the robot held still for about a second around it.
    time  seconds on the joint log's clock
    kind  touch: a tool touching a reference tip; axes: a point of a tool's axes moves
    tool  touch: top_model, needle or probe; axes: needle or probe
    name  touch: the reference tip, rtip1 (calibration) or rtip2 (validation);
          axes: the point p1, p2 or p3 (p1 to p2 along the tool's y axis, p1 to p3 along its z axis)
  Every tool touches both tips equally often (trial k is the k-th touch in time); each axes point
  of needle and probe is marked once. Example row:
    12.500000,touch,needle,rtip1

"""
    + _IMAGES
)

CHECK_README = (
    """\
A blank brachycal check: before a procedure, is the stored calibration still good? Plan its
poses with `brachycal plan check --out check_plan.csv`, record them (a few minutes of robot
time), fill these files in, then

  brachycal session build JOINT_LOG --check --marks marks.csv --images images.csv \\
      --plan check_plan.csv --template session.toml --out CHECK_SESSION
  brachycal verify RESULT CHECK_SESSION --calibration-session SESSION --out check.json

where RESULT is the stored calibration and SESSION the session it was calibrated from.

session.toml
  The set-up's values, the calibration's: copy its session.toml over this one, or fill in the
  three empty lists with the same values (each key has a comment).

"""
    + _JOINT_LOG.format(what="check")
    + """
marks.csv: time,kind,tool,name
  One row per touch of a reference tip, the robot held still for about a second around it. A
  check has no top-model touches and no axes moves (the stored result located the reference
  tips and the tools): only the single touches that `brachycal plan check --touches` planned.
    time  seconds on the joint log's clock
    kind  touch
    tool  probe (the default check), and needle too with --touches both
    name  rtip1
  Example row:
    12.500000,touch,probe,rtip1
  A check planned with --touches none has no marks: leave the header alone and build with
  --touches none.

"""
    + _IMAGES.replace(
        "  One row per captured ultrasound frame with the needle tip in it.",
        "  One row per captured ultrasound frame with the needle tip in it, one at each pose of the check.",
    )
)


def write_session_template(
    folder: str | os.PathLike[str], *, force: bool = False, outputs: OutputSet | None = None, check: bool = False
) -> Path:
    """Write :data:`TEMPLATE_FILES` into ``folder`` (created if needed), all or nothing; with ``check``
    the blanks of a check recording (its README says what a check records).

    Existing files are replaced only with ``force``; with ``outputs`` (a command's set) the files
    join it.
    """
    folder = Path(folder)
    readme = CHECK_README if check else README
    contents = dict(zip(TEMPLATE_FILES, (SESSION_TOML, MARKS_HEADER, IMAGES_HEADER, readme), strict=True))
    with output_set(outputs, force=force) as out:
        for name, text in contents.items():
            with atomic_open(out.path(folder / name, make_parents=True), force=force) as f:
                f.write(text)
    return folder
