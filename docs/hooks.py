"""MkDocs hooks.

- The notebooks live in ``notebooks/`` (beside their README), not under ``docs/``; this adds them to
  the site as ``notebooks/<name>.ipynb`` so mkdocs-jupyter renders them.
- Docstrings cross-reference with Sphinx roles (``:func:`name```); the API pages show the name as
  code, without the role, and a leading ``~`` keeps the last component only, as Sphinx does.
"""

from __future__ import annotations

import re
from pathlib import Path

from mkdocs.config.defaults import MkDocsConfig
from mkdocs.plugins import event_priority
from mkdocs.structure.files import File, Files
from mkdocs.structure.pages import Page

NOTEBOOKS = Path(__file__).resolve().parent.parent / "notebooks"


@event_priority(100)  # before mkdocs-jupyter's on_files, which turns .ipynb files into pages
def on_files(files: Files, config: MkDocsConfig) -> Files:
    for notebook in sorted(NOTEBOOKS.glob("*.ipynb")):
        files.append(
            File(
                f"notebooks/{notebook.name}",
                src_dir=str(NOTEBOOKS.parent),
                dest_dir=config["site_dir"],
                use_directory_urls=config["use_directory_urls"],
            )
        )
    return files


#: A Sphinx role before a rendered code span: ``:func:<code>``, ``:py:class:<code>``, ...
ROLE = re.compile(r":(?:py:)?(?:func|class|mod|meth|data|attr|exc|obj|const|term):(?=<code>)")
#: A code span naming ``~a.b.c``: shown as ``c``.
TILDE = re.compile(r"<code>~(?:[\w]+\.)*([\w]+)(\(\))?</code>")


def on_page_content(html: str, page: Page, config: MkDocsConfig, files: Files) -> str:
    return TILDE.sub(r"<code>\1\2</code>", ROLE.sub("", html))
