"""Sphinx configuration of kronlag's documentation site.

Build it with ``python -m sphinx -W --keep-going -b html docs docs/_build/html`` (tests/test_docs_site.py
does, into a temporary directory).  Three parts:

- the Markdown pages of ``docs/`` read by MyST (they are also the doctests ``pytest docs`` runs);
- the API reference: one autosummary page for each name of ``kronlag.__all__``, listed from ``__all__``
  itself when the build starts (``write_api_index``), so that a new public name needs no change here;
- the gallery: every script of ``examples/`` (and of a subfolder with a ``README.rst``) run by
  sphinx-gallery at build time and shown with the pictures it writes (``_ext/written_pictures.py``).

What the build generates in ``docs/`` (``api/``, ``gallery/``, ``_build/``) is ignored by git.
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
    """Write ``api/index.rst``: an autosummary table with stub pages for each kind of public name.

    It is written before Sphinx looks for its sources, so that autosummary generates the stubs.  A file is
    written only when its text changes (a rebuild then rereads nothing), and the stub of a name no longer
    public is removed (its page would be outside every toctree).
    """
    names = public_names()
    sections = [API_INTRO]
    for kind, kind_names in names.items():
        template = "   :template: data.rst\n" if kind == "Symbols" else ""
        entries = "".join(f"   {name}\n" for name in kind_names)
        sections.append(f"{kind}\n{'-' * len(kind)}\n\n.. autosummary::\n   :toctree: generated\n{template}\n{entries}")
    index = API / "index.rst"
    API.mkdir(exist_ok=True)
    if not index.is_file() or index.read_text() != "\n".join(sections):
        index.write_text("\n".join(sections))
    public = {f"kronlag.{name}.rst" for kind_names in names.values() for name in kind_names}
    for stub in (API / "generated").glob("*.rst"):
        if stub.name not in public:
            stub.unlink()


# The gallery.  sphinx-gallery runs each script in the folder it reads it from, and the scripts write their
# pictures into their working directory: it reads a fresh copy of examples/ (copy_examples), so that a build
# writes nothing into the repository's examples/.  It reruns an example only when its text changed.
EXAMPLES_COPY = DOCS / "_build" / "examples"


def copy_examples() -> None:
    """Copy examples/ (without pictures) to EXAMPLES_COPY, afresh."""
    shutil.rmtree(EXAMPLES_COPY, ignore_errors=True)
    shutil.copytree(EXAMPLES, EXAMPLES_COPY,
                    ignore=shutil.ignore_patterns("__pycache__", "*.png", "*.gif", "*.jpg", "*.svg"))


sphinx_gallery_conf = {
    "examples_dirs": [str(EXAMPLES_COPY)],
    "gallery_dirs": ["gallery"],
    "filename_pattern": r"\.py$",  # run every example: each takes a few seconds
    "image_scrapers": ("written_pictures.scraper",),
    "capture_repr": (),  # a script's last line returns a figure or a path: nothing to show
    "write_computation_times": False,
    "download_all_examples": False,
    "within_subsection_order": "FileNameSortKey",
}


def setup(app) -> None:
    write_api_index()
    copy_examples()
