"""A PLUS brachytherapy-stepper device set: the stepper's axis calibration and the needle template.

Two parts of PLUS's iCal device set (a TRUS probe on a stepper, a needle-guide template):

- ``Device[@Type='BrachyTracker']/StepperCalibration``: the probe's and the template's translation
  axes as PLUS writes them, ``(Tx, Ty, 1)`` (the lateral drift per millimetre of travel) and the
  rotation encoder's scale. PLUS's ``vtkPlusBrachyTracker`` moves the probe by ``axis · d`` for an
  encoder reading ``d`` when it compensates; a device set without the element has straight axes
  ``(0, 0, 1)``.
- ``TemplateModel``: the template's holes (``HolePositions/Hole[@ID][@PositionXYZ]``, millimetres in
  the template's own frame, which the device set calls ``TemplateHome``), placed on the phantom by
  the coordinate definitions ``TemplateHolder → TemplateHome`` and ``TemplateHolder → Phantom``.

Millimetres in the file, metres here (the field names say so).
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from brachycal.data.formats.plus_files import find_section, parse_xml, read_coordinate_definitions
from brachycal.data.json_schema import Where, array, number
from brachycal.errors import InputError
from brachycal.se3 import FloatArray, inverse
from brachycal.validate import check_transform, numbers_from_text

MM = 1e-3
#: The template frame's name in PLUS's device set (hole positions are in it).
TEMPLATE_FRAME = "TemplateHome"
HOLDER_FRAME = "TemplateHolder"
PHANTOM_FRAME = "Phantom"
#: Largest lateral drift ``hypot(Tx, Ty)`` of a plausible axis ``(Tx, Ty, 1)`` (about 11 degrees off z).
MAX_AXIS_DRIFT = 0.2
#: Range of a plausible rotation encoder scale.
ENCODER_SCALE_RANGE = (0.5, 2.0)


def is_stepper_axis(axis: FloatArray) -> bool:
    """``axis`` is PLUS's ``(Tx, Ty, 1)``: finite, its z 1, within :data:`MAX_AXIS_DRIFT` of the stepper's z."""
    return bool(np.all(np.isfinite(axis)) and axis[2] == 1.0 and np.hypot(axis[0], axis[1]) <= MAX_AXIS_DRIFT)


def is_encoder_scale(scale: float) -> bool:
    """``scale`` is a rotation encoder scale within :data:`ENCODER_SCALE_RANGE` (NaN is not)."""
    return ENCODER_SCALE_RANGE[0] <= scale <= ENCODER_SCALE_RANGE[1]


def stepper_axis(value: Any, where: Where) -> None:
    """Schema check (:mod:`brachycal.data.json_schema`): PLUS's axis ``Tx Ty 1`` (:func:`is_stepper_axis`)."""
    array(number(), length=3)(value, where)
    if not is_stepper_axis(np.array(value, dtype=float)):
        raise where.refuse(
            f"must be PLUS's axis 'Tx Ty 1' within {MAX_AXIS_DRIFT:g} of the stepper's z (about 11 degrees), "
            f"got {value}"
        )


#: Schema check of a rotation encoder scale (:func:`is_encoder_scale`).
encoder_scale = number(*ENCODER_SCALE_RANGE)


@dataclass(frozen=True)
class StepperAxes:
    """The stepper's axis calibration, PLUS's form.

    Attributes:
        probe_translation: ``(3,)`` ``(Tx, Ty, 1)``: the probe moves by ``probe_translation · d``
            for a translation encoder reading ``d`` (dimensionless).
        template_translation: ``(3,)`` the same for the template.
        rotation_encoder_scale: the probe rotation is ``scale · θ`` for a reading ``θ``.
        source: where they were read (``"PlusConfiguration//StepperCalibration"``), or
            ``"straight axes"`` when the device set states none.
    """

    probe_translation: FloatArray
    template_translation: FloatArray
    rotation_encoder_scale: float = 1.0
    source: str = "straight axes"

    @property
    def straight(self) -> bool:
        """Both translation axes are ``(0, 0, 1)`` and the scale is 1: poses need no correction."""
        return (
            bool(np.all(self.probe_translation == [0, 0, 1]))
            and bool(np.all(self.template_translation == [0, 0, 1]))
            and self.rotation_encoder_scale == 1.0
        )


#: Axes that change nothing: what a stepper without an axis calibration reports.
STRAIGHT_AXES = StepperAxes(np.array([0.0, 0.0, 1.0]), np.array([0.0, 0.0, 1.0]))


def _axis(text: str | None, place: str, path: Path) -> FloatArray:
    values = numbers_from_text(text or "") if text is not None and text.strip() else None
    if values is None or len(values) != 3 or not np.all(np.isfinite(values)):
        raise InputError(f"{place}: expected three numbers 'Tx Ty 1', got {text!r}", file=path)
    axis = np.array(values, dtype=float)
    if not is_stepper_axis(axis):
        raise InputError(
            f"{place}: expected an axis 'Tx Ty 1' within 0.2 of the stepper's z (about 11 degrees), got {text!r}",
            file=path,
        )
    return axis


def read_stepper_axes(path: str | os.PathLike[str]) -> StepperAxes | None:
    """The ``StepperCalibration`` of a PLUS device set's stepper, or None if it has none (its axes
    are then unknown: not the stepper's z, which a real stepper's axes are 1-3 degrees off).

    Attributes left empty take PLUS's defaults (``0 0 1``, scale 1).

    Raises:
        InputError: unreadable XML, or an axis that is not ``Tx Ty 1`` within 0.2 (about 11°) of
            the stepper's z, or a scale that is not a positive number (naming the attribute).
    """
    path = Path(path)
    root = parse_xml(path)
    element, place = find_section(root, "StepperCalibration")
    if element is None:
        return None
    axes = []
    for name in ("ProbeTranslationAxisOrientation", "TemplateTranslationAxisOrientation"):
        text = element.get(name)
        axes.append(np.array([0.0, 0.0, 1.0]) if not (text or "").strip() else _axis(text, f"{place}/@{name}", path))
    scale_text = (element.get("ProbeRotationEncoderScale") or "").strip()
    scale_values = numbers_from_text(scale_text) if scale_text else [1.0]
    if scale_values is None or len(scale_values) != 1 or not is_encoder_scale(scale_values[0]):
        raise InputError(
            f"{place}/@ProbeRotationEncoderScale: expected a positive scale near 1, got {scale_text!r}", file=path
        )
    return StepperAxes(axes[0], axes[1], float(scale_values[0]), place)


@dataclass(frozen=True)
class TemplateGrid:
    """A needle-guide template: its holes and where it sits on the phantom.

    Attributes:
        holes: hole ID (``"D4"``) → ``(3,)`` its centre in the template frame, metres.
        T_phantom_template: ``(4, 4)`` the template frame in the phantom frame, metres (from the
            device set's ``TemplateHolder → Phantom`` and ``TemplateHolder → TemplateHome``).
        source: the device set it was read from (for messages), None if built in code.
    """

    holes: dict[str, FloatArray]
    T_phantom_template: FloatArray
    source: str | None = None

    def hole(self, hole_id: str) -> FloatArray:
        """``(3,)`` hole ``hole_id``'s centre in the template frame, metres.

        Raises:
            InputError: naming the device set, when the template has no such hole.
        """
        if hole_id not in self.holes:
            ids = list(self.holes)
            shown = ", ".join([*ids[:3], "...", *ids[-2:]]) if len(ids) > 6 else ", ".join(ids)
            raise InputError(f"no template hole {hole_id!r}: the template's holes are {shown}", file=self.source)
        return self.holes[hole_id]


def _definition(definitions: dict[tuple[str, str], FloatArray], frm: str, to: str, top: str, path: Path) -> FloatArray:
    place = f"{top}/CoordinateDefinitions/Transform[@From='{frm}'][@To='{to}']"
    if (frm, to) in definitions:
        M = definitions[frm, to]
    elif (to, frm) in definitions:
        M = inverse(definitions[to, frm])
    else:
        raise InputError(f"no template registration: missing {place} (where the template sits)", file=path)
    try:
        T = check_transform(M, "matrix", tolerance=1e-4).copy()
    except InputError as exc:
        raise InputError(f"{place}: {exc.problem}", file=path) from None
    T[:3, 3] *= MM
    return T


def read_template(path: str | os.PathLike[str]) -> TemplateGrid:
    """The ``TemplateModel`` of a PLUS device set: its holes, placed on the phantom.

    Raises:
        InputError: unreadable XML, no ``TemplateModel/HolePositions/Hole``, a hole without an ID
            or with an ID used twice, a position that is not three numbers, or no template
            registration (``TemplateHolder → TemplateHome`` or ``TemplateHolder → Phantom`` missing
            from ``CoordinateDefinitions``) — each naming the element.
    """
    path = Path(path)
    root = parse_xml(path)
    model, place = find_section(root, "TemplateModel")
    if model is None:
        raise InputError(f"no needle template: missing {root.tag}/TemplateModel", file=path)
    elements = model.findall("HolePositions/Hole")
    if not elements:
        raise InputError(f"no template holes: missing {place}/HolePositions/Hole", file=path)
    holes: dict[str, FloatArray] = {}
    for k, element in enumerate(elements):
        hole_id = (element.get("ID") or "").strip()
        where = f"{place}/HolePositions/Hole[@ID='{hole_id}']" if hole_id else f"{place}/HolePositions/Hole[{k + 1}]"
        if not hole_id:
            raise InputError(f"{where}: a hole needs an ID", file=path)
        if hole_id in holes:
            raise InputError(f"{where}: hole ID used twice", file=path)
        values = numbers_from_text(element.get("PositionXYZ") or "")
        if values is None or len(values) != 3 or not np.all(np.abs(values) <= 1e4):
            raise InputError(
                f"{where}/@PositionXYZ: expected three numbers (mm), got {element.get('PositionXYZ')!r}", file=path
            )
        holes[hole_id] = np.array(values, dtype=float) * MM
    definitions = read_coordinate_definitions(path)
    T_home_holder = _definition(definitions, HOLDER_FRAME, TEMPLATE_FRAME, root.tag, path)
    T_phantom_holder = _definition(definitions, HOLDER_FRAME, PHANTOM_FRAME, root.tag, path)
    return TemplateGrid(holes, T_phantom_holder @ inverse(T_home_holder), str(path))
