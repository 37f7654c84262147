"""The sphinx-gallery image scraper of kronlag's site: the pictures each code block of an example writes.

The examples are plain scripts that save their figures to files (``trajectory.plot(path=...)`` makes
figures that pyplot does not hold, so sphinx-gallery's matplotlib scraper would see none).  After each
code block, :func:`scraper` shows the picture files the block wrote or rewrote in its working directory
(the example's folder, see ``copy_examples`` in conf.py); a GIF animation stays a GIF and plays on the
page.  A block that wrote no picture file has its open pyplot figures shown instead.  The module lives
outside conf.py because Sphinx pickles its configuration and cannot pickle what conf.py defines.
"""

from __future__ import annotations

import shutil
from pathlib import Path

PICTURE_SUFFIXES = (".png", ".gif", ".jpg", ".svg")

#: picture file -> its modification time when it was shown (a block that rewrites a file shows it again)
_shown: dict[Path, int] = {}


def scraper(block, block_vars: dict, gallery_conf: dict) -> str:
    """The reStructuredText showing the pictures the block wrote (sphinx-gallery's scraper interface)."""
    import matplotlib.pyplot as plt
    from sphinx_gallery.scrapers import figure_rst, matplotlib_scraper

    folder = Path(block_vars["src_file"]).parent
    written = sorted((path for path in folder.iterdir()
                      if path.suffix in PICTURE_SUFFIXES and _shown.get(path) != path.stat().st_mtime_ns),
                     key=lambda path: path.stat().st_mtime_ns)
    if not written:
        return matplotlib_scraper(block, block_vars, gallery_conf)
    plt.close("all")  # a figure a block saved to a file and left open is shown once, from its file
    shown = []
    for picture, image_path in zip(written, block_vars["image_path_iterator"]):
        target = Path(image_path).with_suffix(picture.suffix)
        shutil.copyfile(picture, target)
        _shown[picture] = picture.stat().st_mtime_ns
        shown.append(target)
    # one picture under the other at the page's width (figure_rst would set several side by side, small)
    return "".join(figure_rst([str(path)], gallery_conf["src_dir"], srcsetpaths=[{0: path}]) for path in shown)
