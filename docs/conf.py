"""Sphinx configuration of kronlag's documentation site.

Build it with ``python -m sphinx -W --keep-going -b html docs docs/_build/html`` (tests/test_docs_site.py
does, into a temporary directory).  Three parts:

- the Markdown pages of ``docs/`` read by MyST (they are also the doctests ``pytest docs`` runs);
- the API reference: one autosummary page for each name of ``kronlag.__all__``, listed from ``__all__``
  itself when the build starts (``write_api_index``), so that a new public name needs no change here;
- the gallery: every script of ``examples/`` (and of a subfolder with a ``README.rst``) run by
  sphinx-gallery at build time and shown with the pictures it writes (``_ext/written_pictures.py``).

What the build generates in ``docs/`` (``api/``, ``gallery/``) is ignored by git.
"""

from __future__ import annotations

import inspect
import shutil
import sys
import time
from pathlib import Path

import kronlag

DOCS = Path(__file__).resolve().parent
EXAMPLES = DOCS.parent / "examples"
sys.path.insert(0, str(DOCS / "_ext"))

project = "kronlag"
author = "the kronlag authors"
copyright = f"{time.gmtime().tm_year}, {author}"
release = version = kronlag.__version__

extensions = [
    "myst_parser",
    "sphinx.ext.autodoc",
    "sphinx.ext.autosummary",
    "numpydoc",
    "sphinx_gallery.gen_gallery",
]
source_suffix = {".rst": "restructuredtext", ".md": "markdown"}
root_doc = "index"
templates_path = ["_templates"]
exclude_patterns = ["_build", "_ext", "Thumbs.db", ".DS_Store"]

html_theme = "furo"
html_title = f"kronlag {release}"
html_static_path = ["_static"]

# The pages: GitHub-flavoured Markdown, with heading anchors for the links between pages (`units.md#dimensions`).
myst_heading_anchors = 3

# The API reference from the numpydoc docstrings.  Each class page shows its members itself (the template
# _templates/autosummary/class.rst), so numpydoc adds no member tables of its own.
autosummary_generate = True
autodoc_typehints = "none"  # the docstrings' Parameters sections give the types
numpydoc_show_class_members = False
numpydoc_xref_param_type = False

API = DOCS / "api"
API_INTRO = """\
API reference
=============

The public names of the package, ``kronlag.__all__``: what ``import kronlag`` gives.  Each page is
generated from the name's docstring.

.. currentmodule:: kronlag
"""


def public_names() -> dict[str, list[str]]:
    """The names of ``kronlag.__all__`` by kind, each kind in the order of ``__all__``."""
    kinds: dict[str, list[str]] = {"Functions": [], "Classes": [], "Exceptions": [], "Warnings": [],
                                   "Modules": [], "Symbols": []}
    for name in kronlag.__all__:
        value = getattr(kronlag, name)
        if inspect.ismodule(value):
            kind = "Modules"
        elif inspect.isclass(value):
            kind = ("Warnings" if issubclass(value, Warning) else
                    "Exceptions" if issubclass(value, BaseException) else "Classes")
        else:
            kind = "Functions" if callable(value) else "Symbols"
        kinds[kind].append(name)
    return {kind: names for kind, names in kinds.items() if names}


def write_api_index() -> None:
    """Write ``api/index.rst`` afresh: an autosummary table with stub pages for each kind of public name.

    It is written before Sphinx looks for its sources, so that autosummary generates the stubs; the stubs
    of an earlier build go with it (a name no longer public would leave a page outside every toctree).
    """
    shutil.rmtree(API, ignore_errors=True)
    API.mkdir()
    sections = [API_INTRO]
    for kind, names in public_names().items():
        template = "   :template: data.rst\n" if kind == "Symbols" else ""
        entries = "".join(f"   {name}\n" for name in names)
        sections.append(f"{kind}\n{'-' * len(kind)}\n\n.. autosummary::\n   :toctree: generated\n{template}\n{entries}")
    (API / "index.rst").write_text("\n".join(sections))


# The gallery.  sphinx-gallery runs each script in the folder it reads it from, and the scripts write their
# pictures into their working directory: it reads a fresh copy of examples/ in the build's doctree folder,
# so that a build writes nothing into the repository's examples/.
sphinx_gallery_conf = {
    "examples_dirs": [str(EXAMPLES)],  # replaced by its copy when the builder starts (copy_examples)
    "gallery_dirs": ["gallery"],
    "filename_pattern": r"\.py$",  # run every example: each takes a few seconds
    "image_scrapers": ("written_pictures.scraper",),
    "capture_repr": (),  # a script's last line returns a figure or a path: nothing to show
    "write_computation_times": False,
    "download_all_examples": False,
    "within_subsection_order": "FileNameSortKey",
}


def copy_examples(app) -> None:
    """Point sphinx-gallery at a fresh copy of examples/ in the build's doctree folder (see above)."""
    copy = Path(app.doctreedir) / "examples"
    shutil.rmtree(copy, ignore_errors=True)
    shutil.copytree(EXAMPLES, copy, ignore=shutil.ignore_patterns("__pycache__", "*.png", "*.gif", "*.jpg", "*.svg"))
    app.config.sphinx_gallery_conf["examples_dirs"] = [str(copy)]


def setup(app) -> None:
    write_api_index()
    app.connect("builder-inited", copy_examples, priority=100)  # before sphinx-gallery reads the examples (500)
