"""The ``brachycal-result/1`` schema (``calibration/session/result_schema.py``) and the bounded JSON reader.

Every result the writer produces passes it and reads back to the numbers it holds; a single number
anywhere made NaN, or made a string where the writer puts a number, is refused naming its place.
"""

from __future__ import annotations

import copy
import json
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from conftest import ROOT
from hostile import run_cli

from brachycal.calibration import read_result, validate_result_document
from brachycal.data.json_files import MAX_JSON_DEPTH, check_json_tree, json_place, read_json
from brachycal.errors import InputError

SESSION = ROOT / "examples" / "twin_session"

#: Each kind of result ``brachycal calibrate`` writes: the options that make it.
KINDS = {
    "sequential": [],
    "chain": ["--solve", "chain"],
    "chain-joint-offsets": ["--solve", "chain", "--joint-offsets"],
    "chain-identify-robot": ["--solve", "chain", "--identify-robot"],
}


@pytest.fixture(scope="module")
def results(tmp_path_factory) -> dict[str, Path]:
    folder = tmp_path_factory.mktemp("results")
    out = {}
    for kind, options in KINDS.items():
        path = folder / f"{kind}.json"
        outcome = run_cli(["calibrate", str(SESSION), *options, "--out", str(path), "--quiet"])
        assert outcome.code == 0, outcome.err
        out[kind] = path
    return out


def leaves(value: Any, place: str = "") -> Iterator[tuple[str, tuple[str | int, ...]]]:
    """``(place, keys)`` of every number in a JSON value (``place`` as the refusals name it)."""
    stack: list[tuple[Any, str, tuple[str | int, ...]]] = [(value, place, ())]
    while stack:
        node, where, keys = stack.pop()
        if isinstance(node, dict):
            stack.extend((v, json_place(where, k), (*keys, k)) for k, v in node.items())
        elif isinstance(node, list):
            stack.extend((v, json_place(where, k), (*keys, k)) for k, v in enumerate(node))
        elif isinstance(node, int | float) and not isinstance(node, bool):
            yield where, keys


def replaced(document: dict, keys: tuple[str | int, ...], value: object) -> dict:
    """A copy of ``document`` with ``value`` at ``keys``."""
    out = copy.deepcopy(document)
    node: Any = out
    for key in keys[:-1]:
        node = node[key]
    node[keys[-1]] = value
    return out


@contextmanager
def one_leaf(document: dict, keys: tuple[str | int, ...], value: object) -> Iterator[dict]:
    """``document`` itself with ``value`` at ``keys`` for the block's time (put back after)."""
    node: Any = document
    for key in keys[:-1]:
        node = node[key]
    kept = node[keys[-1]]
    node[keys[-1]] = value
    try:
        yield document
    finally:
        node[keys[-1]] = kept


@pytest.mark.slow
@pytest.mark.parametrize("kind", KINDS)
def test_every_result_the_writer_produces_passes_and_reads_back(kind, results):
    path = results[kind]
    document = json.loads(path.read_text())
    assert validate_result_document(document, path) is document
    stored = read_result(path)
    transforms = document["transforms"]
    np.testing.assert_array_equal(stored.T_ER_Ntip, transforms["ER_T_Ntip"])
    np.testing.assert_array_equal(stored.T_EL_Ptip, transforms["EL_T_Ptip"])
    assert list(stored.image) == list(transforms["Ptip_T_I"])
    for method, image in stored.image.items():
        np.testing.assert_array_equal(image.T_Ptip_I, transforms["Ptip_T_I"][method])
        np.testing.assert_allclose(image.spacing_m, np.array(document["spacing_mm"][method]) * 1e-3, rtol=1e-15)
    chain = document.get("chain", {})
    assert stored.joint_offsets_rad == chain.get("joint_offsets_rad", {})
    assert set(stored.joint_origins) == set(chain.get("robot_joint_origins", {}))
    assert stored.image_size_px == tuple(document["image"]["size_px"])
    assert stored.robot is not None and stored.robot.joint_names == tuple(document["robot"]["joint_names"])


@pytest.mark.slow
def test_the_kinds_hold_what_they_are_for(results):
    # The round trip above covers joint offsets and corrected joint origins only if they are there.
    offsets = json.loads(results["chain-joint-offsets"].read_text())["chain"]
    identified = json.loads(results["chain-identify-robot"].read_text())["chain"]
    assert offsets["joint_offsets_rad"] and offsets["robot_joint_origins"]
    assert identified["robot_identification"]["corrections"] and identified["robot_joint_origins"]


def test_a_verify_update_and_a_refused_block_pass(tmp_path):
    outcome = run_cli(["verify", "--demo", str(tmp_path / "demo")])
    assert outcome.code == 0, outcome.err
    demo = tmp_path / "demo"
    update = tmp_path / "updated.json"
    argv = ["verify", str(demo / "result.json"), str(demo / "check_probe_remounted"), "--out", str(tmp_path / "r.json")]
    outcome = run_cli([*argv, "--calibration-session", str(demo / "session"), "--update", str(update)])
    assert update.is_file(), outcome.out + outcome.err
    document = json.loads(update.read_text())
    assert "update" in document and "nominal_spacing_mm" in document
    validate_result_document(document, update)
    document["refused"] = {"similarity": "too few samples", "scaled_uv": "the spacing is not determined"}
    validate_result_document(document, update)


@pytest.mark.slow
@pytest.mark.parametrize("kind", KINDS)
def test_any_number_made_nan_is_refused_naming_its_place(kind, results):
    document = json.loads(results[kind].read_text())
    places = list(leaves(document))
    assert len(places) > 500  # every transform entry, error and figure of the file
    for place, keys in places:
        with one_leaf(document, keys, float("nan")) as edited, pytest.raises(InputError) as refused:
            validate_result_document(edited, "r.json")
        assert refused.value.column == place, place
    assert json.loads(results[kind].read_text()) == document  # every leaf was put back


@pytest.mark.slow
def test_nan_written_into_the_file_is_refused_naming_its_place(results, tmp_path):
    document = json.loads(results["chain-joint-offsets"].read_text())
    path = tmp_path / "r.json"
    for place, keys in list(leaves(document))[::37]:  # a spread of places; the mechanism is one
        path.write_text(json.dumps(replaced(document, keys, float("nan"))))  # writes NaN
        with pytest.raises(InputError, match="NaN is not a finite number") as refused:
            read_result(path)
        assert refused.value.column == place and refused.value.file == str(path)


#: Numbers the writer lays out whose places are checked whole, not item by item: a wrong item
#: names the list (``image.size_px``).
CHECKED_WHOLE = ("image.size_px",)


@pytest.mark.slow
@pytest.mark.parametrize("kind", KINDS)
def test_any_number_made_a_string_is_refused_naming_its_place(kind, results):
    # The schema knows the type of every number the writer lays out.
    document = json.loads(results[kind].read_text())
    for place, keys in leaves(document):
        with one_leaf(document, keys, "1") as edited, pytest.raises(InputError) as refused:
            validate_result_document(edited, "r.json")
        named = refused.value.column
        assert named == place or (named in CHECKED_WHOLE and place.startswith(named)), (place, named)


@pytest.mark.slow
def test_a_number_out_of_its_range_is_refused(results):
    document = json.loads(results["chain-joint-offsets"].read_text())
    joint = next(iter(document["chain"]["joint_offsets_rad"]))
    for keys, value, words in [
        (("chain", "joint_offsets_rad", joint), 1e6, "rad"),
        (("chain", "joint_offsets_rad", joint), -3.2, "rad"),
        (("transforms", "EL_T_Ptip", 2, 3), 5.5, "5 m"),
        (("mechanical", "probe", "axes_angle_deg"), 181.0, "deg"),
        (("loocv", "chain", "errors_mm", 0), -1e-9, ">= 0"),
    ]:
        with pytest.raises(InputError, match=words) as refused:
            validate_result_document(replaced(document, keys, value), "r.json")
        assert refused.value.column.startswith(".".join(str(k) for k in keys[:2])), refused.value


@pytest.mark.slow
def test_unknown_keys_are_accepted_but_still_finite(results):
    document = json.loads(results["sequential"].read_text())
    validate_result_document({**document, "added_later": {"note": "x", "values": [1, 2.5]}}, "r.json")
    with pytest.raises(InputError) as refused:
        validate_result_document({**document, "added_later": {"values": [1, float("inf")]}}, "r.json")
    assert refused.value.column == "added_later.values[1]"


def test_the_reader_bounds_depth_without_recursing(tmp_path):
    deep: Any = []
    for _ in range(MAX_JSON_DEPTH):
        deep = [deep]
    check_json_tree(deep)  # MAX_JSON_DEPTH levels below the top: accepted
    with pytest.raises(InputError, match=f"nested more than {MAX_JSON_DEPTH} deep"):
        check_json_tree([deep])
    very_deep: Any = []
    for _ in range(100_000):  # deeper than Python's recursion limit: the walk is iterative
        very_deep = [very_deep]
    with pytest.raises(InputError, match="nested"):
        check_json_tree(very_deep)
    path = tmp_path / "deep.json"
    path.write_text("[" * 100_000 + "]" * 100_000)
    with pytest.raises(InputError, match=r"deep\.json: not valid JSON: nested"):
        read_json(path)


@pytest.mark.parametrize(
    "text, words",
    [
        ('{"a": NaN}', "column 'a': NaN is not a finite number"),
        ('{"a": [Infinity]}', r"column 'a\[0\]': Infinity is not a finite number"),
        ('{"a": {"b": -1e999}}', "column 'a.b': -1e999 is not a finite number"),
        ('{"a": ' + "9" * 5000 + "}", "column 'a': 999999999999... is an integer of 5000 digits"),
        ('{"a": -' + "9" * 21 + "}", "integer of 21 digits"),
    ],
)
def test_the_reader_refuses_numbers_python_would_accept(text, words, tmp_path):
    path = tmp_path / "x.json"
    path.write_text(text)
    with pytest.raises(InputError, match=words):
        read_json(path)


def test_the_reader_accepts_the_largest_integers_it_allows(tmp_path):
    path = tmp_path / "x.json"
    path.write_text('{"a": -' + "9" * 20 + ', "b": 1.5e300}')
    assert read_json(path) == {"a": -(10**20 - 1), "b": 1.5e300}


@pytest.mark.slow
def test_a_refusal_stays_one_short_line_whatever_the_file_holds(results):
    # A huge key, value or format is cut: the line names the place without carrying the data.
    document = json.loads(results["sequential"].read_text())
    for edit in (
        {"inputs": {"k" * 100_000: 5}},
        {"image": {"size_px": list(range(100_000))}},
        {"format": "x" * 100_000},
        {"loocv": {"m" * 100_000: {}}},
    ):
        with pytest.raises(InputError) as refused:
            validate_result_document({**document, **edit}, "r.json")
        assert len(str(refused.value)) < 300, str(refused.value)[:400]


@pytest.mark.parametrize(
    "value, words",
    [
        ({"a": {1: 2}}, "column 'a': key 1 is not a string"),
        ({"a": (1, 2)}, "column 'a': tuple is not a JSON value"),
        ({"a": [10**20]}, r"column 'a\[0\]': is an integer of more than 20 digits"),
    ],
)
def test_a_document_built_in_memory_is_held_to_json(value, words):
    with pytest.raises(InputError, match=words):
        check_json_tree(value)
