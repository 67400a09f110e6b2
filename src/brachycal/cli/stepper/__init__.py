"""``brachycal stepper``: calibration of a TRUS probe on a brachytherapy stepper with its needle-guide
template, one command group. ``stepper calibrate`` (the default, so ``brachycal stepper ROTATION …``
runs it): the stepper's axes, the pixel spacing and the centre of rotation from single-axis recordings.

Each sub-command is its own command of the command line: the words ``stepper calibrate`` name the
command ``stepper`` (:data:`SUBCOMMANDS`); a sub-command added to the group adds its word here.
"""

from __future__ import annotations

#: ``brachycal stepper WORD``: the command each word names (``calibrate`` is also the default).
SUBCOMMANDS = {
    "calibrate": "stepper",
    "image": "stepper-image",
    "template": "stepper-template",
    "export": "stepper-export",
}
