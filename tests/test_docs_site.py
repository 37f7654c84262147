"""The documentation site: Sphinx builds it with warnings as errors (docs/conf.py), every guide page,
public name and example is on it, its internal links resolve, and headless Chromium shows the home
page and a gallery page with the example's figure.

The build reads a copy of docs/ and examples/ in a temporary directory, so that it writes nothing into
the repository.  Skipped without the ``docs`` extra; the browser checks are skipped without Chromium
(``.ci/run`` installs it from the system packages).
"""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
import time
from html.parser import HTMLParser
from pathlib import Path
from urllib.parse import unquote, urlsplit

import numpy as np
import pytest
from PIL import Image

import kronlag

for module in ("sphinx", "myst_parser", "sphinx_gallery", "numpydoc", "furo"):
    pytest.importorskip(module, reason="the docs extra is not installed")

ROOT = Path(__file__).resolve().parents[1]
CHROMIUM = next(filter(None, map(shutil.which, ("chromium", "chromium-browser", "google-chrome"))), None)
needs_chromium = pytest.mark.skipif(CHROMIUM is None, reason="Chromium is not installed")
pytestmark = pytest.mark.slow

#: the gallery page the browser opens: a short example whose figure is a trajectory plot
GALLERY_PAGE = "pendulum_cartesian"
PLOT_LINE_COLOR = np.array([31, 119, 180])  # matplotlib's first line colour, which text and theme do not use


def guide_pages() -> list[str]:
    return sorted(path.stem for path in (ROOT / "docs").glob("*.md") if path.stem != "index")


def gallery_examples() -> list[Path]:
    """The example scripts the gallery shows: those of examples/ and of its subfolders with a README."""
    folders = [ROOT / "examples"] + [readme.parent for readme in (ROOT / "examples").glob("*/README.rst")]
    return sorted(script for folder in folders for script in folder.glob("*.py"))


@pytest.fixture(scope="module")
def site(tmp_path_factory) -> Path:
    """The site built from a copy of the sources; its build time is printed (``pytest -s`` shows it)."""
    work = tmp_path_factory.mktemp("site")
    shutil.copytree(ROOT / "docs", work / "docs", ignore=shutil.ignore_patterns("_build", "gallery", "api"))
    shutil.copytree(ROOT / "examples", work / "examples",
                    ignore=shutil.ignore_patterns("__pycache__", "*.png", "*.gif"))
    environment = dict(os.environ, PYTHONPATH=os.pathsep.join(
        filter(None, [str(Path(kronlag.__file__).parents[1]), os.environ.get("PYTHONPATH")])))
    start = time.perf_counter()
    build = subprocess.run([sys.executable, "-m", "sphinx", "-W", "--keep-going", "-q", "-b", "html",
                            str(work / "docs"), str(work / "html")],
                           cwd=work, env=environment, capture_output=True, text=True, check=False)
    print(f"\nsite built in {time.perf_counter() - start:.0f} s")
    assert build.returncode == 0, f"sphinx failed:\n{build.stderr[-6000:]}"
    return work / "html"


def test_every_page_public_name_and_example_is_on_the_site(site):
    for page in guide_pages():
        assert (site / f"{page}.html").is_file(), page
    home = (site / "index.html").read_text()
    assert all(f'href="{page}.html"' in home for page in guide_pages())  # the home page's toctree
    api = (site / "api" / "index.html").read_text()
    for name in kronlag.__all__:  # a page of its own, or (a symbol) its entry on the API page
        assert (site / "api" / "generated" / f"kronlag.{name}.html").is_file() or f'id="kronlag.{name}"' in api, name
    gallery = (site / "gallery" / "index.html").read_text()
    for script in gallery_examples():
        page = site / "gallery" / script.parent.relative_to(ROOT / "examples") / f"{script.stem}.html"
        assert page.is_file() and f"{script.stem}.html" in gallery, script
        text = page.read_text()
        assert f"sphx_glr_{script.stem}_001." in text  # a picture the example wrote ...
        assert f"{script.stem}.py" in text and f"{script.stem}.ipynb" in text  # ... and its downloads
    animation = (site / "gallery" / "four_bar.html").read_text()
    assert "sphx_glr_four_bar_002.gif" in animation  # the animation the example writes plays on its page


class _Links(HTMLParser):
    """The targets of a page's href and src attributes, and its element ids."""

    def __init__(self) -> None:
        super().__init__()
        self.targets: list[str] = []
        self.ids: set[str] = set()

    def handle_starttag(self, tag, attrs) -> None:
        for name, value in attrs:
            if name in ("href", "src") and value:
                self.targets.append(value)
            elif name == "id" and value:
                self.ids.add(value)


def test_no_broken_internal_links(site):
    pages = {path: _Links() for path in site.rglob("*.html")}
    for path, links in pages.items():
        links.feed(path.read_text())
    broken = []
    for path, links in pages.items():
        for target in links.targets:
            parts = urlsplit(target)
            if parts.scheme or parts.netloc:  # http(s), mailto, data: not this site's files
                continue
            file = (path.parent / unquote(parts.path)).resolve() if parts.path else path
            if not file.exists():
                broken.append(f"{path.relative_to(site)}: {target}")
            elif parts.fragment and file.suffix == ".html" and unquote(parts.fragment) not in pages[file].ids:
                broken.append(f"{path.relative_to(site)}: {target} (no such anchor)")
    assert not broken, "\n".join(broken)


def screenshot(page: Path, tmp_path: Path, size=(1280, 1600)) -> np.ndarray:
    """The page in headless Chromium, as RGB pixels (rows, columns, 3)."""
    shot = tmp_path / f"{page.stem}.png"
    subprocess.run([CHROMIUM, "--headless", "--no-sandbox", "--disable-gpu", "--no-first-run",
                    "--disable-background-networking", "--disable-component-update", "--disable-sync",
                    "--force-device-scale-factor=1", f"--user-data-dir={tmp_path / 'profile'}",
                    f"--screenshot={shot}", f"--window-size={size[0]},{size[1]}", "--virtual-time-budget=3000",
                    page.as_uri()], check=True, capture_output=True, timeout=120)
    return np.asarray(Image.open(shot).convert("RGB")).astype(int)


@needs_chromium
def test_home_page_renders_in_chromium(site, tmp_path):
    image = screenshot(site / "index.html", tmp_path)
    ink = (image < 200).all(axis=-1)  # dark pixels: the text
    assert ink.sum() > 5000
    _, columns = np.nonzero(ink)
    assert columns.min() < image.shape[1] // 4 < columns.max()  # the navigation on the left, the text beside it


@needs_chromium
def test_gallery_page_shows_the_figure_in_chromium(site, tmp_path):
    image = screenshot(site / "gallery" / f"{GALLERY_PAGE}.html", tmp_path)
    lines = np.linalg.norm(image - PLOT_LINE_COLOR, axis=-1) < 40
    assert lines.sum() > 500  # the figure's curves are painted
    rows, columns = np.nonzero(lines)
    figure = image[rows.min():rows.max() + 1, columns.min():columns.max() + 1]
    assert figure.shape[0] > 100 and figure.shape[1] > 200
    assert (figure.sum(axis=-1) < 3 * 250).mean() > 0.02 and figure.std() > 20  # drawn, not a blank box
