"""The chain's parameter vector and image models: one layout that names every unknown, one table of
image models that every model-dependent step reads (no comparisons of model names elsewhere)."""

from __future__ import annotations

import ast
from pathlib import Path

import numpy as np
import pytest

from brachycal.calibration.chain import IMAGE_MODELS, MODELS, ParameterLayout, image_model
from brachycal.errors import InputError

SOURCE = Path(__file__).parents[1] / "src" / "brachycal"
NOMINAL_M = np.array([1.9e-4, 1.9e-4])  # the paper's 0.19 mm/pixel


@pytest.mark.parametrize("name", MODELS)
def test_an_image_model_starts_from_the_scale_that_gave_the_spacing(name):
    model = IMAGE_MODELS[name]
    scale = 1.0 + 0.01 * np.arange(1, model.n_scale + 1)
    spacing = model.spacing(NOMINAL_M, scale)
    # A ratio of two doubles and its mean: exact to a few units of rounding (1e-16 relative).
    assert np.allclose(model.start_scale(spacing / NOMINAL_M), scale, rtol=1e-14, atol=0)


@pytest.mark.parametrize("name", MODELS)
def test_an_image_models_spacing_columns_are_the_derivative_of_its_image_points(name):
    model = IMAGE_MODELS[name]
    uv = np.array([[0.0, 0.0], [640.0, 10.0], [13.0, 480.0]])
    scale = np.full(model.n_scale, 1.03)
    step = 1e-6

    def points(s: np.ndarray) -> np.ndarray:
        return np.column_stack([uv * model.spacing(NOMINAL_M, s), np.zeros(len(uv))])

    for k, column in enumerate(model.spacing_columns(uv, NOMINAL_M)):
        e = np.eye(model.n_scale)[k]
        numeric = (points(scale + step * e) - points(scale - step * e)) / (2 * step)
        # The points are linear in the scale: central differences are exact to rounding (~1e-10 of
        # the 0.1 m entries after dividing by the step); a wrong axis would be off by its whole size.
        assert np.allclose(column, numeric, rtol=0, atol=1e-9), (name, k)


def test_the_models_that_scale_the_depth_imply_a_speed_of_sound():
    for model in IMAGE_MODELS.values():
        implied = model.sound_speed_m_s(model.spacing(NOMINAL_M, np.full(model.n_scale, 1.02)), NOMINAL_M)
        if model.measures_sound_speed:
            assert implied == pytest.approx(1540.0 * 1.02, rel=1e-12)
        else:
            assert implied is None
    assert [m.name for m in IMAGE_MODELS.values() if m.scale_is_sound_speed] == ["sound_speed"]
    assert (
        IMAGE_MODELS["rigid"].complexity < IMAGE_MODELS["sound_speed"].complexity < IMAGE_MODELS["scaled_uv"].complexity
    )


@pytest.mark.parametrize("name", MODELS)
@pytest.mark.parametrize("joints", [(), (1, 4, 9)])
def test_the_layout_names_every_entry_of_the_vector_once(name, joints):
    layout = ParameterLayout(name, joints)
    covered = np.concatenate([np.arange(s.start, s.stop) for s in layout.blocks().values()])
    assert np.array_equal(covered, np.arange(layout.size))  # in order, no gap, no overlap
    assert layout.blocks()["scale"].stop - layout.blocks()["scale"].start == IMAGE_MODELS[name].n_scale
    assert [layout.block_of(k) for k in range(layout.size)].count("joint_offsets") == len(joints)


def test_an_unknown_image_model_is_refused_with_the_choices():
    with pytest.raises(InputError, match="unknown image model 'affine'; choose from rigid, similarity"):
        image_model("affine")
    with pytest.raises(InputError, match="unknown image model"):
        ParameterLayout("affine")


def _compared_strings(tree: ast.AST) -> list[tuple[int, str]]:
    """(line, string) of every string constant a comparison (==, !=, in, not in) tests against."""
    found = []
    for node in ast.walk(tree):
        if isinstance(node, ast.Compare):
            for operand in [node.left, *node.comparators]:
                items = operand.elts if isinstance(operand, ast.Tuple | ast.List | ast.Set) else [operand]
                found += [(node.lineno, c.value) for c in items if isinstance(c, ast.Constant)]
    return found


def test_no_code_that_uses_the_chain_compares_image_model_names():
    # The sequential registrations have methods of the same names (image_to_probe, registration;
    # registration borrows the chain's solver, not its models): only the other modules that use
    # the chain are held to the table.
    sequential_family = {"image_models.py", "registration.py", "image_to_probe.py"}
    offenders = []
    for path in sorted(SOURCE.rglob("*.py")):
        text = path.read_text()
        if "calibration.chain" not in text or path.name in sequential_family:
            continue
        offenders += [
            f"{path.relative_to(SOURCE)}:{line} {value!r}"
            for line, value in _compared_strings(ast.parse(text))
            if value in MODELS
        ]
    assert offenders == [], "look the model up in brachycal.calibration.chain.IMAGE_MODELS"
