"""kronlag.animation: frames of the mechanism drawn from the model's drawing hints, and their timing."""

from __future__ import annotations

import dataclasses
import json
import re
import shutil
from types import SimpleNamespace

import numpy as np
import pytest
from helpers import FOUR_BAR_PARAMETERS, four_bar_joints, four_bar_trajectory, heavy_top_trajectory
from PIL import Image, ImageSequence

import kronlag
from kronlag.views import animation
from kronlag.views.animation import _evaluate_drawing, _Picture, _resample, animate, render_frame

CRANK_SPEED = 2 * np.pi
LINK_COLOR = np.array([31, 119, 180])  # matplotlib's C0, the colour of the first drawing line


@pytest.fixture(scope="module")
def half_turn():
    """The crank turns by pi in 0.5 s; samples every 0.1 s, so 10 fps frames fall on the samples."""
    return four_bar_trajectory(np.linspace(0.0, 0.5, 6), crank_speed=CRANK_SPEED)


def gif_frames(path) -> list[np.ndarray]:
    return [np.asarray(frame.convert("RGB")).astype(int) for frame in ImageSequence.Iterator(Image.open(path))]


def gif_delays(path) -> list[int]:
    return [frame.info["duration"] for frame in ImageSequence.Iterator(Image.open(path))]


def link_pixels_near(image: np.ndarray, pixel, radius: int = 4) -> int:
    """Pixels of the link colour within ``radius`` pixels of ``pixel`` (x, y from the top left)."""
    column, row = pixel
    window = image[row - radius:row + radius + 1, column - radius:column + radius + 1]
    return int((np.linalg.norm(window - LINK_COLOR, axis=-1) < 60).sum())


def test_gif_frames_show_the_crank_pin_where_the_geometry_puts_it(half_turn, tmp_path):
    gif = animate(half_turn, tmp_path / "four_bar.gif", fps=10, width=200)
    frames = gif_frames(gif)
    assert len(frames) == 6
    picture = _Picture(_evaluate_drawing(half_turn, half_turn.t, None), width=200, trace=True)
    assert frames[0].shape == (picture.size[1], picture.size[0], 3)
    crank_pins, _ = four_bar_joints(CRANK_SPEED * half_turn.t)  # closed-form position analysis
    pixels = picture._pixels(crank_pins)
    for frame, pin in zip(frames, pixels):
        assert link_pixels_near(frame, pin) > 5
    assert link_pixels_near(frames[0], pixels[-1]) == 0  # the pin is not there yet
    for before, after in zip(frames, frames[1:]):
        assert np.abs(before - after).sum(axis=-1).astype(bool).sum() > 100


@pytest.mark.parametrize("fps", [25, 50, 30, 7])
def test_gif_delays_keep_to_simulated_time(half_turn, tmp_path, fps):
    """Frame k is shown at k / fps s (GIF delays are hundredths of a second): within 5 ms at every frame."""
    delays = gif_delays(animate(half_turn, tmp_path / "timed.gif", fps=fps, trace=False, width=60))
    assert len(delays) == int(0.5 * fps + 1e-9) + 1
    assert all(delay % 10 == 0 and delay >= 20 for delay in delays)
    starts = np.cumsum(delays)
    np.testing.assert_allclose(starts, 1000 * np.arange(1, len(delays) + 1) / fps, atol=5)
    if 100 % fps == 0:
        assert set(delays) == {1000 // fps}


@pytest.mark.parametrize("options, times", [
    ({"fps": 10}, np.arange(6) * 0.1),  # real time
    ({"fps": 10, "speed": 0.5}, np.arange(11) * 0.05),  # half speed: twice the frames
    ({"fps": 4, "duration": 2.0}, np.arange(9) * 0.0625),  # 0.5 s played in 2 s
    ({"fps": 10, "speed": 0.3}, np.arange(17) * 0.03),  # the last frame at or before the end
])
def test_frame_times_follow_fps_and_speed(options, times):
    speed = animation.playing_speed(0.5, fps=options["fps"], speed=options.get("speed"),
                                     duration=options.get("duration"))
    np.testing.assert_allclose(animation._frame_times(0.0, 0.5, fps=options["fps"], speed=speed), times,
                               atol=1e-12)


def test_speed_and_duration_together_are_refused(half_turn, tmp_path):
    with pytest.raises(ValueError, match="not both"):
        animate(half_turn, tmp_path / "x.gif", speed=0.5, duration=2.0)


def test_gif_faster_than_50_fps_is_refused(half_turn, tmp_path):
    with pytest.raises(ValueError, match="at most 50 frames per second"):
        animate(half_turn, tmp_path / "fast.gif", fps=60)


def test_resampling_interpolates_with_the_velocities(half_turn):
    times = np.linspace(0.0, 0.5, 23)
    q = _resample(half_turn, times)
    np.testing.assert_allclose(q[:, 0], CRANK_SPEED * times, atol=1e-12)  # exact for a linear q1
    pins, couplers = four_bar_joints(CRANK_SPEED * times)
    p = FOUR_BAR_PARAMETERS
    coupler_tips = pins + p["l2"] * np.column_stack([np.cos(q[:, 1]), np.sin(q[:, 1])])
    np.testing.assert_allclose(coupler_tips, couplers, atol=0.02)


def page_data(page: str) -> dict:
    return json.loads(re.search(r"const D = (\{.*\});", page)[1])


def test_html_page_is_self_contained_data_drawn_by_a_script(half_turn, tmp_path):
    path = animate(half_turn, tmp_path / "four_bar.html", fps=10, width=200)
    page = path.read_text(encoding="utf-8")
    assert page.startswith("<!DOCTYPE html>") and "<title>four_bar</title>" in page and "<canvas" in page
    assert not re.search(r"https?://|<link|<img|base64|\bsrc\s*=", page)  # no URL, no file to fetch, no image
    data = page_data(page)
    assert data["count"] == 6 and data["fps"] == 10 and data["step"] == pytest.approx(0.1)
    picture = _Picture(_evaluate_drawing(half_turn, half_turn.t, None), width=200, trace=True)
    linkage = np.array(data["lines"][0]["xy"]).reshape(6, -1, 2)
    np.testing.assert_array_equal(linkage[:, 1], picture._pixels(four_bar_joints(CRANK_SPEED * half_turn.t)[0]))


def test_animate_without_a_path_returns_the_page(half_turn):
    page = half_turn.animate(fps=2)  # Trajectory.animate delegates to animate
    assert isinstance(page, str) and page_data(page)["count"] == 2


def test_heavy_top_is_drawn_in_3d(tmp_path):
    top = heavy_top_trajectory(np.linspace(0.0, 0.2, 3))
    image = np.asarray(render_frame(top, -1, tmp_path / "top.png", width=160).convert("RGB")).astype(int)
    assert (np.linalg.norm(image - LINK_COLOR, axis=-1) < 60).sum() > 20
    drawing = _evaluate_drawing(top, top.t, None)
    picture = _Picture(drawing, width=160, trace=True)
    assert drawing.dimension == 3 and picture.axes.shape == (3, 2, 2)  # x, y, z axes drawn
    assert len(gif_frames(animate(top, tmp_path / "top.gif", fps=10, width=80))) == 3


def test_parameters_override_the_model_and_may_vary_in_time(half_turn, tmp_path):
    drawing = _evaluate_drawing(half_turn, half_turn.t, {"l4": lambda time: 6.0})
    assert [6.0, 0.0] in drawing.fixed_points.tolist()
    render_frame(half_turn, 0, tmp_path / "long.png", width=80, parameters={"l4": lambda time: 6.0})


def test_real_numeric_model_with_a_time_varying_parameter(half_turn, tmp_path):
    equations = kronlag.derive(kronlag.models.four_bar())
    model = equations.numeric({**FOUR_BAR_PARAMETERS, "tau": lambda time: 2.0 * time}, backend="python")
    assert model.time_varying
    real = render_frame(dataclasses.replace(half_turn, model=model), 3, tmp_path / "real.png", width=80)
    stand_in = render_frame(half_turn, 3, tmp_path / "stand-in.png", width=80)
    assert np.array_equal(np.asarray(real), np.asarray(stand_in))


def test_model_without_drawing_hints_is_refused(half_turn, tmp_path):
    x, = kronlag.coordinates("x")
    model = SimpleNamespace(equations=SimpleNamespace(system=kronlag.System([x])))
    with pytest.raises(ValueError, match="no drawing hints"):
        animate(dataclasses.replace(half_turn, model=model), tmp_path / "nothing.gif")


@pytest.mark.parametrize("name", ["four_bar.avi", "four_bar"])
def test_unsupported_extension_is_refused(half_turn, tmp_path, name):
    with pytest.raises(ValueError, match="extension must be one of .gif, .mp4, .html"):
        animate(half_turn, tmp_path / name)


@pytest.mark.parametrize("options", [{"fps": 0}, {"duration": -1.0}, {"speed": 0.0}])
def test_fps_speed_and_duration_must_be_positive(half_turn, tmp_path, options):
    with pytest.raises(ValueError, match="must be positive"):
        animate(half_turn, tmp_path / "four_bar.html", **options)


def test_render_frame_index_out_of_range(half_turn, tmp_path):
    with pytest.raises(IndexError, match="6 samples"):
        render_frame(half_turn, 6, tmp_path / "frame.png")


def test_mp4_without_ffmpeg_is_a_clear_error(half_turn, tmp_path, monkeypatch):
    monkeypatch.setattr(animation.shutil, "which", lambda name: None)
    with pytest.raises(RuntimeError, match="needs ffmpeg"):
        animate(half_turn, tmp_path / "four_bar.mp4")
    assert not (tmp_path / "four_bar.mp4").exists()


@pytest.mark.skipif(shutil.which("ffmpeg") is None, reason="ffmpeg is not installed")
def test_mp4_with_ffmpeg(half_turn, tmp_path):
    path = animate(half_turn, tmp_path / "four_bar.mp4", fps=10, width=100)
    assert path.stat().st_size > 1000
