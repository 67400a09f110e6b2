"""The documentation site builds with warnings as errors, its notebooks executed, its pages whole.

`make docs` runs the same build (mkdocs.yml: strict); this is its test. Building executes the
notebooks (mkdocs-jupyter, errors not allowed, no cache), so this is also the notebooks' test.
"""

from __future__ import annotations

import os
import re
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
pytestmark = pytest.mark.slow  # the whole site, notebooks executed: about 20 s

NOTEBOOKS = sorted(p.stem for p in (ROOT / "notebooks").glob("*.ipynb"))


def test_the_site_builds_clean_with_every_page(tmp_path: Path) -> None:
    site = tmp_path / "site"
    env = {**os.environ, "BRACHYCAL_DOCS_EXECUTE": "true", "NO_MKDOCS_2_WARNING": "1"}
    run = subprocess.run(
        [
            sys.executable,
            "-m",
            "mkdocs",
            "build",
            "--strict",
            "--config-file",
            str(ROOT / "mkdocs.yml"),
            "--site-dir",
            str(site),
        ],
        cwd=tmp_path,
        env=env,
        capture_output=True,
        text=True,
        timeout=900,
    )
    assert run.returncode == 0, run.stderr[-4000:]
    for page in ("index.html", "procedure/index.html", "conventions/index.html", "robots/index.html"):
        assert (site / page).is_file(), page
    # Each notebook is a page with its figures, executed now: an image in its outputs.
    assert len(NOTEBOOKS) >= 5
    for name in NOTEBOOKS:
        html = (site / "notebooks" / name / "index.html").read_text(encoding="utf-8")
        assert "data:image/png;base64" in html, f"{name}: no figure rendered"
    # The API reference is read from the docstrings, through the packages' lazy re-exports.
    api = (site / "api" / "calibration" / "index.html").read_text(encoding="utf-8")
    for symbol in ("brachycal.calibration.calibrate", "brachycal.calibration.identify_robot"):
        assert f'id="{symbol}"' in api, symbol
    assert not (tmp_path / ".cache").exists()  # no cached notebook pages: they would hide a failure
    # No raw Sphinx role (":func:") or "~" path left on any page.
    raw = {
        str(path.relative_to(site)): hits
        for path in site.rglob("*.html")
        if (hits := len(re.findall(r":(?:func|class|mod|meth|data|attr|exc|obj):<code>|<code>~\w", path.read_text())))
    }
    assert raw == {}, raw
