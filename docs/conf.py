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

# The pages: GitHub-flavoured Markdown, with heading anchors for the links between pages (`units.md#dimensions`).
myst_heading_anchors = 3

# The API reference from the numpydoc docstrings.  Each class page shows its members itself (the template
# _templates/autosummary/class.rst), so numpydoc adds no member tables of its own.
autosummary_generate = True
autodoc_typehints = "none"  # the docstrings' Parameters sections give the types
numpydoc_show_class_members = False
numpydoc_xref_param_type = False


def literal_block_after_summary(app, what, name, obj, options, lines: list[str]) -> None:
    """Give a literal block announced by the summary (``Solve ... multipliers::``) a paragraph ``::`` of its own.

    numpydoc takes the first paragraph as the summary and dedents what follows, so such a block would lose
    its indentation and docutils reject it.  Runs before numpydoc's own handler (priority 500).
    """
    end = lines.index("") if "" in lines else len(lines)
    if end and lines[end - 1].endswith("::"):
        summary = lines[end - 1]
        lines[end - 1:end] = [summary[:-2].rstrip() if summary.endswith(" ::") else summary[:-1], "", "::"]


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


def symbol_comment(name: str) -> str:
    """The ``#:`` comment above the assignment of the public symbol ``name`` in the module that defines it."""
    from sphinx.pycode import ModuleAnalyzer, PycodeError

    value = getattr(kronlag, name)
    for module_name in sorted(sys.modules):
        if module_name.startswith("kronlag.") and getattr(sys.modules[module_name], name, None) is value:
            try:
                comment = ModuleAnalyzer.for_module(module_name).find_attr_docs().get(("", name))
            except PycodeError:  # an old module path (kronlag._legacy) has no source of its own
                continue
            if comment:
                return " ".join(comment).strip()
    raise ValueError(f"kronlag.{name}: no '#:' comment above its assignment")


def write_api_index() -> None:
    """Write ``api/index.rst``: an autosummary table with stub pages for each kind of public name.

    It is written before Sphinx looks for its sources, so that autosummary generates the stubs.  A file is
    written only when its text changes (a rebuild then rereads nothing), and the stub of a name no longer
    public is removed (its page would be outside every toctree).
    """
    names = public_names()
    sections = [API_INTRO]
    for kind, kind_names in names.items():
        if kind == "Symbols":  # a SymPy symbol has no docstring of its own: its comment, here
            entries = "".join(f".. py:data:: {name}\n\n   {symbol_comment(name)}\n\n" for name in kind_names)
        else:
            entries = ".. autosummary::\n   :toctree: generated\n\n" + "".join(f"   {name}\n" for name in kind_names)
        sections.append(f"{kind}\n{'-' * len(kind)}\n\n{entries}")
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
GALLERY = DOCS / "gallery"


def copy_examples() -> None:
    """Copy examples/ (without pictures) to EXAMPLES_COPY, afresh; remove the gallery pages of examples
    that are gone (sphinx-gallery leaves them, outside every toctree)."""
    shutil.rmtree(EXAMPLES_COPY, ignore_errors=True)
    shutil.copytree(EXAMPLES, EXAMPLES_COPY,
                    ignore=shutil.ignore_patterns("__pycache__", "*.png", "*.gif", "*.jpg", "*.svg"))
    for page in GALLERY.rglob("*.rst"):
        source = EXAMPLES / page.relative_to(GALLERY)
        if page.name == "index.rst":  # a folder's page: the folder has a header (README.rst or GALLERY_HEADER.rst)
            kept = any(source.parent.glob("README.*")) or any(source.parent.glob("GALLERY_HEADER.*"))
        else:
            kept = source.with_suffix(".py").is_file()
        if not kept:
            page.unlink()


sphinx_gallery_conf = {
    "examples_dirs": [str(EXAMPLES_COPY)],
    "gallery_dirs": [GALLERY.name],
    # Every example runs: each takes 2 to 18 s (flyball_governor, a stiff IFToMM problem, the longest; all of
    # them together about a minute of CPU time), none so long that leaving it out would pay.
    "filename_pattern": r"\.py$",
    "image_scrapers": ("written_pictures.scraper",),
    "capture_repr": (),  # a script's last line returns a figure or a path: nothing to show
    "write_computation_times": False,
    "download_all_examples": False,
    "within_subsection_order": "FileNameSortKey",
}


def setup(app) -> None:
    app.connect("autodoc-process-docstring", literal_block_after_summary, priority=400)
    write_api_index()
    copy_examples()
