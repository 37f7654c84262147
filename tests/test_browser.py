"""The HTML animation in a real browser: headless Chromium loads the page, lets its clock run,
and takes a screenshot; the pixels must show the four-bar where its geometry puts it, mid-motion.

Skipped without Chromium (``.ci/run`` installs it from the system packages).
"""

from __future__ import annotations

import shutil
import subprocess

import numpy as np
import pytest
from helpers import four_bar_joints, four_bar_trajectory
from PIL import Image

from kronlag.views.animation import _evaluate_drawing, _Picture, animate

CHROMIUM = next(filter(None, map(shutil.which, ("chromium", "chromium-browser", "google-chrome"))), None)
pytestmark = [pytest.mark.slow, pytest.mark.skipif(CHROMIUM is None, reason="Chromium is not installed")]

CRANK_SPEED = np.pi  # one turn in 2 s
LINK_COLOR = np.array([31, 119, 180])  # the colour of the first drawing line
FPS, WIDTH = 25, 400
#: Headless Chromium sometimes never takes its screenshot (seen with very short virtual-time budgets):
#: a run that lasts HANG_GUARD seconds (about 50 times a normal run on a loaded machine) is started again.
HANG_GUARD, HANG_RETRIES = 120, 1


def screenshot(page, size: tuple[int, int], milliseconds: int, tmp_path) -> np.ndarray:
    """The page after ``milliseconds`` of the browser's virtual clock, as RGB pixels (rows, columns, 3)."""
    shot = tmp_path / f"shot-{milliseconds}.png"
    profile = tmp_path / f"profile-{milliseconds}"
    command = [CHROMIUM, "--headless", "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
               "--disable-background-networking", "--disable-component-update", "--disable-sync",
               "--force-device-scale-factor=1", f"--user-data-dir={profile}", f"--screenshot={shot}",
               f"--window-size={size[0]},{size[1]}", f"--virtual-time-budget={milliseconds}", page.as_uri()]
    for attempt in range(HANG_RETRIES + 1):
        try:
            subprocess.run(command, check=True, capture_output=True, timeout=HANG_GUARD)
            break
        except subprocess.TimeoutExpired:
            if attempt == HANG_RETRIES:
                raise
    return np.asarray(Image.open(shot).convert("RGB")).astype(int)[:size[1], :size[0]]


def link_pixels_near(image: np.ndarray, pixel, radius: int = 4) -> int:
    column, row = pixel
    window = image[row - radius:row + radius + 1, column - radius:column + radius + 1]
    return int((np.linalg.norm(window - LINK_COLOR, axis=-1) < 60).sum())


def test_html_animation_plays_in_chromium(tmp_path):
    trajectory = four_bar_trajectory(np.linspace(0.0, 2.0, 41), crank_speed=CRANK_SPEED)
    page = animate(trajectory, tmp_path / "four_bar.html", fps=FPS, width=WIDTH)
    frame_times = np.arange(2 * FPS + 1) / FPS
    picture = _Picture(_evaluate_drawing(trajectory, frame_times, None), width=WIDTH, trace=True)
    pins = picture._pixels(four_bar_joints(CRANK_SPEED * frame_times)[0])  # crank pin B, closed form

    def shown_frame(image: np.ndarray) -> int:
        """The frame whose crank pin the image shows most clearly."""
        return max(range(len(pins)), key=lambda k: link_pixels_near(image, pins[k]))

    start = screenshot(page, picture.size, 100, tmp_path)
    assert link_pixels_near(start, pins[shown_frame(start)]) > 5
    # the animation starts when the page is loaded: frame 2.5 on the virtual clock, which a loaded machine
    # lets run a few frames ahead before the screenshot is taken (frame 6 seen at load 10)
    assert shown_frame(start) <= 8

    later = screenshot(page, picture.size, 1000, tmp_path)
    linkage = np.linalg.norm(later - LINK_COLOR, axis=-1) < 60
    assert linkage.sum() > 200  # the mechanism is drawn ...
    rows, columns = np.nonzero(linkage)
    assert rows.min() >= picture._TITLE_HEIGHT and columns.max() < picture.size[0]  # ... inside its view
    assert np.abs(later - start).sum(axis=-1).astype(bool).sum() > 500  # ... and has moved
    assert link_pixels_near(later, pins[shown_frame(later)]) > 5
    assert 10 <= shown_frame(later) <= 40  # mid-motion: the crank pin is at a frame well after the start
