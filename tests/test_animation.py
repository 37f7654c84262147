"""kronlag.animation: frames of the mechanism drawn from the model's drawing hints."""

from __future__ import annotations

import dataclasses
import re
from types import SimpleNamespace

import numpy as np
import pytest
from matplotlib.animation import FFMpegWriter
from PIL import Image, ImageSequence
from synthetic_trajectories import FOUR_BAR_PARAMETERS, four_bar_joints, four_bar_trajectory, heavy_top_trajectory

import kronlag
from kronlag.animation import _resample, animate, render_frame

CRANK_SPEED = 2 * np.pi
LINK_COLOR = np.array([31, 119, 180])  # matplotlib's C0, the colour of the first drawing line


@pytest.fixture(scope="module")
def half_turn():
    """The crank turns by pi in 0.5 s; samples every 0.1 s, so 10 fps frames fall on the samples."""
    return four_bar_trajectory(np.linspace(0.0, 0.5, 6), crank_speed=CRANK_SPEED)


def _gif_frames(path) -> list[np.ndarray]:
    return [np.asarray(frame.convert("RGB")).astype(int) for frame in ImageSequence.Iterator(Image.open(path))]


def _link_pixels_near(image: np.ndarray, figure, point, radius: int = 4) -> int:
    """Pixels of the link colour within ``radius`` pixels of a model point in a frame saved from ``figure``."""
    x, y = figure.axes[0].transData.transform(point)
    row, column = round(image.shape[0] - y), round(x)
    window = image[row - radius:row + radius + 1, column - radius:column + radius + 1]
    return int((np.linalg.norm(window - LINK_COLOR, axis=-1) < 60).sum())


def test_gif_frames_show_the_crank_pin_where_the_geometry_puts_it(half_turn, tmp_path):
    gif = animate(half_turn, tmp_path / "four_bar.gif", fps=10, dpi=50)
    frames = _gif_frames(gif)
    assert len(frames) == 6
    # render_frame lays out the same figure (same limits: its frames are the same samples).
    figure = render_frame(half_turn, 0, tmp_path / "frame.png", dpi=50)
    assert frames[0].shape == np.asarray(Image.open(tmp_path / "frame.png")).shape[:2] + (3,)
    crank_pins, _ = four_bar_joints(CRANK_SPEED * half_turn.t)
    for frame, pin in zip(frames, crank_pins):
        assert _link_pixels_near(frame, figure, pin) > 5
    assert _link_pixels_near(frames[0], figure, crank_pins[-1]) == 0  # the pin is not there yet
    for before, after in zip(frames, frames[1:]):
        assert np.abs(before - after).sum(axis=-1).astype(bool).sum() > 100


def test_frame_count_follows_fps_and_duration(half_turn, tmp_path):
    gif = animate(half_turn, tmp_path / "slow.gif", fps=6, duration=0.5, trace=False, dpi=30)
    assert len(_gif_frames(gif)) == round(0.5 * 6) + 1


def test_resampling_interpolates_with_the_velocities(half_turn):
    times = np.linspace(0.0, 0.5, 23)
    q = _resample(half_turn, times)
    np.testing.assert_allclose(q[:, 0], CRANK_SPEED * times, atol=1e-12)  # exact for a linear q1
    pins, couplers = four_bar_joints(CRANK_SPEED * times)
    p = FOUR_BAR_PARAMETERS
    coupler_tips = pins + p["l2"] * np.column_stack([np.cos(q[:, 1]), np.sin(q[:, 1])])
    np.testing.assert_allclose(coupler_tips, couplers, atol=0.02)


def test_html_page_is_self_contained(half_turn, tmp_path):
    path = animate(half_turn, tmp_path / "four_bar.html", fps=10, duration=0.2, dpi=30)
    page = path.read_text(encoding="utf-8")
    assert page.startswith("<!DOCTYPE html>") and "<title>four_bar</title>" in page
    assert page.count("data:image/png;base64,") == 3
    assert not re.search(r"https?://|<link|<[a-z]+\s[^>]*\bsrc\s*=", page)  # no URL, no file to fetch


def test_animate_without_a_path_returns_the_page(half_turn):
    page = half_turn.animate(fps=2, dpi=20)  # Trajectory.animate delegates to animate
    assert isinstance(page, str) and page.count("data:image/png;base64,") == 2


def test_heavy_top_is_drawn_in_3d(tmp_path):
    top = heavy_top_trajectory(np.linspace(0.0, 0.2, 3))
    figure = render_frame(top, -1, tmp_path / "top.png", dpi=40)
    assert figure.axes[0].name == "3d"
    image = np.asarray(Image.open(tmp_path / "top.png").convert("RGB")).astype(int)
    assert (np.linalg.norm(image - LINK_COLOR, axis=-1) < 60).sum() > 20
    assert len(_gif_frames(animate(top, tmp_path / "top.gif", fps=10, dpi=30))) == 3


def test_parameters_override_the_model_and_may_vary_in_time(half_turn, tmp_path):
    figure = render_frame(half_turn, 0, tmp_path / "long.png", dpi=20, parameters={"l4": lambda time: 6.0})
    assert figure.axes[0].get_xlim()[1] > 6.0


def test_real_numeric_model_with_a_time_varying_parameter(half_turn, tmp_path):
    equations = kronlag.derive(kronlag.models.four_bar())
    model = equations.numeric({**FOUR_BAR_PARAMETERS, "tau": lambda time: 2.0 * time}, backend="numpy")
    assert model.time_varying
    render_frame(dataclasses.replace(half_turn, model=model), 3, tmp_path / "real.png", dpi=20)
    render_frame(half_turn, 3, tmp_path / "stand-in.png", dpi=20)
    real, stand_in = (np.asarray(Image.open(tmp_path / name)) for name in ("real.png", "stand-in.png"))
    assert np.array_equal(real, stand_in)


def test_model_without_drawing_hints_is_refused(half_turn, tmp_path):
    x, = kronlag.coordinates("x")
    model = SimpleNamespace(equations=SimpleNamespace(system=kronlag.System([x])))
    with pytest.raises(ValueError, match="no drawing hints"):
        animate(dataclasses.replace(half_turn, model=model), tmp_path / "nothing.gif")


@pytest.mark.parametrize("name", ["four_bar.avi", "four_bar"])
def test_unsupported_extension_is_refused(half_turn, tmp_path, name):
    with pytest.raises(ValueError, match="extension must be one of .gif, .mp4, .html"):
        animate(half_turn, tmp_path / name)


@pytest.mark.parametrize("options", [{"fps": 0}, {"duration": -1.0}])
def test_fps_and_duration_must_be_positive(half_turn, tmp_path, options):
    with pytest.raises(ValueError, match="must be positive"):
        animate(half_turn, tmp_path / "four_bar.gif", **options)


def test_render_frame_index_out_of_range(half_turn, tmp_path):
    with pytest.raises(IndexError, match="6 samples"):
        render_frame(half_turn, 6, tmp_path / "frame.png")


def test_mp4_without_ffmpeg_is_a_clear_error(half_turn, tmp_path, monkeypatch):
    monkeypatch.setattr(FFMpegWriter, "isAvailable", classmethod(lambda cls: False))
    with pytest.raises(RuntimeError, match="needs ffmpeg"):
        animate(half_turn, tmp_path / "four_bar.mp4")


@pytest.mark.skipif(not FFMpegWriter.isAvailable(), reason="ffmpeg is not installed")
def test_mp4_with_ffmpeg(half_turn, tmp_path):
    path = animate(half_turn, tmp_path / "four_bar.mp4", fps=10, dpi=30)
    assert path.stat().st_size > 1000
