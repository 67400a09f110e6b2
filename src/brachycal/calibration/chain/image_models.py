"""The image models of the whole chain: one table, :data:`IMAGE_MODELS`.

An image model says how the pixel spacing ``(s_u, s_v)`` (metres per pixel) follows from the
scanner's nominal spacing and the model's scale factors (the ``scale`` block of the parameter
vector). Each scale factor multiplies the nominal spacing along some image axes (0: u, columns;
1: v, rows, the depth): that one fact gives the spacing, its derivative for the Jacobian, the
starting value from a sequential fit and whether the model measures the speed of sound. Every
place that depends on the model looks it up here (no comparisons of model names elsewhere).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from brachycal.errors import InputError
from brachycal.imaging import SCANNER_SOUND_SPEED_M_S
from brachycal.se3 import FloatArray

SCANNER_SOUND_SPEED = SCANNER_SOUND_SPEED_M_S  # one home: brachycal.imaging
#: Image axis of the depth (rows, v): the axis along which the speed of sound stretches the image.
DEPTH_AXIS = 1


@dataclass(frozen=True)
class ImageModel:
    """One image model.

    Attributes:
        name: the name users pass (``--model``, :func:`~brachycal.calibration.chain.fit_chain`).
        description: one line a person reads.
        scaled_axes: per scale factor, the image axes (0: u, 1: v) whose nominal spacing it
            multiplies; empty for the scanner's own spacing.
    """

    name: str
    description: str
    scaled_axes: tuple[tuple[int, ...], ...]

    @property
    def n_scale(self) -> int:
        """Number of scale factors (unknowns of the ``scale`` block)."""
        return len(self.scaled_axes)

    @property
    def complexity(self) -> int:
        """Free parameters beyond a rigid image (the model choice prefers the fewest)."""
        return self.n_scale

    @property
    def measures_sound_speed(self) -> bool:
        """Whether the fitted depth spacing implies a speed of sound ``c = 1540 m/s · s_v / s_v,nominal``
        (every model that scales the depth)."""
        return any(DEPTH_AXIS in axes for axes in self.scaled_axes)

    @property
    def scale_is_sound_speed(self) -> bool:
        """Whether the model's one scale factor is ``c / 1540 m/s`` itself (it scales the depth alone),
        so that its interval is the speed of sound's."""
        return self.scaled_axes == ((DEPTH_AXIS,),)

    def sound_speed_m_s(self, spacing: FloatArray, nominal_spacing: FloatArray) -> float | None:
        """The speed of sound (m/s) that the fitted depth spacing implies (the scanner assumes
        1540 m/s); None for a model that does not scale the depth."""
        if not self.measures_sound_speed:
            return None
        return float(SCANNER_SOUND_SPEED * spacing[DEPTH_AXIS] / nominal_spacing[DEPTH_AXIS])

    def factors(self, scale: FloatArray) -> FloatArray:
        """``(2,)`` per-axis factors on the nominal spacing from the scale factors ``(n_scale,)``."""
        out = [1.0, 1.0]  # plain floats: called at every residual evaluation
        for value, axes in zip(scale, self.scaled_axes, strict=True):
            for axis in axes:
                out[axis] = float(value)
        return np.array(out)

    def spacing(self, nominal_spacing: FloatArray, scale: FloatArray) -> FloatArray:
        """``(2,)`` pixel spacing (metres per pixel) from the nominal one and the scale factors."""
        return nominal_spacing * self.factors(scale) if self.scaled_axes else nominal_spacing

    def spacing_columns(self, uv_px: FloatArray, nominal_spacing: FloatArray) -> list[FloatArray]:
        """Per scale factor, ``(N, 3)``: how the image points ``(u s_u, v s_v, 0)`` (metres, in
        ``us_image``) of pixels ``uv_px (N, 2)`` move per unit of that factor."""
        columns = []
        for axes in self.scaled_axes:
            d = np.zeros((len(uv_px), 3))
            d[:, list(axes)] = uv_px[:, list(axes)] * nominal_spacing[list(axes)]
            columns.append(d)
        return columns

    def start_scale(self, ratio: FloatArray) -> FloatArray:
        """``(n_scale,)`` starting scale factors from a sequential fit's spacing over the nominal one
        ``(2,)``: each factor the mean ratio over its axes."""
        return np.array([ratio[list(axes)].mean() for axes in self.scaled_axes])


#: The image models, simplest first (name → model).
IMAGE_MODELS: dict[str, ImageModel] = {
    m.name: m
    for m in (
        ImageModel("rigid", "the scanner's spacing", ()),
        ImageModel("similarity", "one scale on both axes", ((0, 1),)),
        ImageModel("scaled_uv", "a scale per image axis", ((0,), (1,))),
        ImageModel(
            "sound_speed",
            "lateral spacing as the scanner says, depth spacing times c / 1540 m/s (c estimated)",
            ((DEPTH_AXIS,),),
        ),
    )
}
MODELS = tuple(IMAGE_MODELS)
#: Free parameters of each model beyond a rigid image.
COMPLEXITY = {name: m.complexity for name, m in IMAGE_MODELS.items()}


def image_model(name: str) -> ImageModel:
    """The model called ``name``.

    Raises:
        InputError: no such model.
    """
    if name not in IMAGE_MODELS:
        raise InputError(f"unknown image model {name!r}; choose from {', '.join(MODELS)}")
    return IMAGE_MODELS[name]
