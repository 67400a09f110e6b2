"""Tables of configurations streamed (``brachycal locate`` on a joint log of millions of rows):
block by block they are the table read whole, and a bad row is named by its row in the file."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from conftest import ROOT

from brachycal.data.formats.csv_log import configuration_blocks, read_configurations
from brachycal.errors import InputError
from brachycal.model import Robot

LOG = ROOT / "examples" / "joint_log.csv"


@pytest.fixture(scope="module")
def robot() -> Robot:
    return Robot.load()


def test_blocks_are_the_table_read_whole(robot):
    rows, Q = read_configurations(LOG, robot)
    blocks = list(configuration_blocks(LOG, robot, rows_per_block=7))
    assert [len(r) for r, _ in blocks[:-1]] == [7] * (len(blocks) - 1) and 1 <= len(blocks[-1][0]) <= 7
    assert [row for r, _ in blocks for row in r] == rows == list(range(2, len(rows) + 2))
    np.testing.assert_array_equal(np.concatenate([q for _, q in blocks]), Q)


def test_a_bad_row_in_a_later_block_is_named_by_its_file_row(robot, tmp_path: Path):
    lines = LOG.read_text().splitlines()
    fields = lines[20].split(",")
    fields[3] = "x"
    lines[20] = ",".join(fields)
    (tmp_path / "log.csv").write_text("\n".join(lines) + "\n")
    column = lines[0].split(",")[3]
    blocks = configuration_blocks(tmp_path / "log.csv", robot, rows_per_block=7)
    assert len(next(blocks)[0]) == 7  # the rows before the bad one are handed on
    with pytest.raises(InputError, match=rf"log.csv, row 21, column '{column}': 'x' is not a number"):
        list(blocks)


def test_a_table_without_rows_is_refused(robot, tmp_path: Path):
    (tmp_path / "empty.csv").write_text(LOG.read_text().splitlines()[0] + "\n")
    with pytest.raises(InputError, match=r"empty\.csv: no configurations"):
        list(configuration_blocks(tmp_path / "empty.csv", robot))
