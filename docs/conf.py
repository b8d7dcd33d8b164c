"""Sphinx configuration of the PyGran user guide.

Build: ``sphinx-build -W --keep-going -b html docs docs/_build/html`` (``tests/test_docs.py``
does this on every test run, so a warning, a broken cross-reference or an API change that
breaks an example fails the suite). Pages are MyST Markdown; the API reference is autodoc
over the installed packages. Nothing is downloaded at build time: no intersphinx.
"""

from __future__ import annotations

from importlib.metadata import version as _version
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from docutils.nodes import Element
    from sphinx.application import Sphinx
    from sphinx.domains import Domain

project = "PyGran"
author = "PyGran developers"
copyright = "PyGran developers, GPL-2.0-or-later"
release = _version("pygran-core")
version = release

extensions = [
    "myst_parser",
    "sphinx.ext.autodoc",
    "sphinx.ext.viewcode",
]

source_suffix = {".md": "markdown", ".rst": "restructuredtext"}
root_doc = "index"
exclude_patterns = ["_build", "examples/data", "examples/**/build", "examples/**/*.egg-info"]

myst_enable_extensions = ["colon_fence", "deflist"]
myst_heading_anchors = 3

# -- autodoc ------------------------------------------------------------------------------
autodoc_member_order = "bysource"
autodoc_typehints = "description"
autodoc_typehints_format = "short"
autodoc_default_options = {"members": True, "show-inheritance": True}
# Plugin modules import their solvers (mpi4py, h5py, the LIGGGHTS library) inside the
# functions that need them, so importing every module works on any machine that has the
# packages installed; nothing needs mocking.
# The docstrings are plain reStructuredText (no Google or NumPy sections), so napoleon is
# not used: it would read a first line such as "Neighbour-list skin: ..." as a type.

nitpicky = True  # see _quiet_missing_reference below

# -- HTML ---------------------------------------------------------------------------------
html_theme = "alabaster"
html_title = f"PyGran {release} user guide"
html_static_path: list[str] = []
html_theme_options = {"description": "DEM simulation and analysis of granular materials"}


def setup(app: Sphinx) -> None:
    app.connect("warn-missing-reference", _quiet_missing_reference)


# -- cross-references -----------------------------------------------------------------------
# nitpicky is on so that every reference written in these pages must resolve. References
# that cannot resolve without intersphinx (numpy, the standard library, pluggy), and those
# inside docstrings and signatures of the API reference (type hints imported only for type
# checking, short names such as :class:`EngineError` in modules that import them), are not
# warned about: the guide's own pages are checked, the docstrings are what they are.
_EXTERNAL = (
    "numpy",
    "np.",
    "collections",
    "pathlib",
    "os.",
    "argparse",
    "abc.",
    "types.",
    "typing",
    "pluggy",
    "importlib",
    "logging",
    "concurrent",
    "subprocess",
    "mpi4py",
    "ctypes",
)


def _quiet_missing_reference(app: Sphinx, domain: Domain, node: Element) -> bool | None:
    target = node.get("reftarget", "")
    if target.startswith(_EXTERNAL) or target in ("Path", "PathLike", "ModuleType", "Any"):
        return True
    source = node.source or getattr(node.parent, "source", None) or ""
    in_docstring = "docstring of" in source or not source.endswith(".md")
    return True if in_docstring else None
