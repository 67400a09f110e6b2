"""``brachycal robot identify PROTOCOL``: an arm's joint geometry identified from a calibration
protocol, each protocol a sub-command with its own options: ``touches`` (fixed points touched by
a tool on the flange, :mod:`brachycal.cli.robot.touches`), ``tracker`` (an external tracker's
measurements of a marker, :mod:`brachycal.cli.robot.tracker`), ``session`` (the dual-arm rig's
session, :mod:`brachycal.cli.robot.session`)."""

from __future__ import annotations

import argparse

from brachycal.cli.common import add_robot_option
from brachycal.cli.robot import session as session_cli
from brachycal.cli.robot import touches as touches_cli
from brachycal.cli.robot import tracker as tracker_cli

NAME = "robot"
HELP = "identify a robot's joint geometry from touches, a tracker or a dual-arm session (robot identify PROTOCOL)"
#: The protocols, each a sub-command: ``brachycal robot identify PROTOCOL ...``.
PROTOCOLS = {"touches": touches_cli, "tracker": tracker_cli, "session": session_cli}
DESCRIPTION = """\
Identifies a robot's joint geometry (every joint origin's small translation and rotation) from a
calibration protocol, with the stated accuracy as the corrections' prior, and judges it on data the
fit did not use. The protocol is the sub-command:

  brachycal robot identify touches FOLDER... --robot ARM --tool-frame FRAME --train PLACE --out DIR
                   any arm: touches of fixed points by a tool on the flange; held-out places
  brachycal robot identify tracker TABLE --columns SPEC --robot ARM --out DIR
                   any arm: a tracker's 3-D or 6-D measurements of a marker; leave-one-out postures
  brachycal robot identify session SESSION --out DIR
                   the dual-arm rig: its calibration session; K-fold held-out configurations

Each writes DIR/robot.urdf (the identified robot) and DIR/identification.json (corrections,
figures), and prints the held-out figures first, the training figures second, then which
combinations of corrections the data determine. Each protocol's --help gives its files.
"""


def add_parser(sub: argparse._SubParsersAction) -> None:
    parser = sub.add_parser(
        NAME, help=HELP, description=DESCRIPTION, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    actions = parser.add_subparsers(title="actions", metavar="ACTION", dest="action", required=True)
    identify = actions.add_parser(
        "identify",
        help="identify the robot's joint geometry (protocols: touches, tracker, session)",
        description=DESCRIPTION,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    protocols = identify.add_subparsers(title="protocols", metavar="PROTOCOL", dest="protocol", required=True)
    for name, module in PROTOCOLS.items():
        one = protocols.add_parser(
            name,
            help=module.HELP,
            description=module.DESCRIPTION,
            formatter_class=argparse.RawDescriptionHelpFormatter,
        )
        module.add_options(one)
        add_robot_option(one, any_arm=module.ANY_ARM)
        one.add_argument(
            "--out", required=True, metavar="DIR", help="folder to write robot.urdf and identification.json to"
        )
        one.add_argument("--force", action="store_true", help="replace the outputs if they exist")
        one.add_argument("--quiet", action="store_true", help="no progress bar")
        one.set_defaults(run=module.run)
