"""A crop shows something: windows (comparison crops and the frame strip's) are the worst among those
covering at least MIN_CONTENT of the reference's visible pixels, wherever any window does.

The planted frames are a night sky with small lamps (reference black but for the lamps) beside a lit
wall: the noisy input flickers most around the lamps, where a crop is black on nearly every pixel.
"""

from __future__ import annotations

import numpy as np

from denoisebench.results import crops


def _sky_and_wall(frames: int = 4):
    rng = np.random.default_rng(11)
    ref = np.zeros((frames, 32, 32, 3))
    ref[:, :, 16:] = 1.5 + 0.3 * rng.random((1, 32, 16, 1))  # the wall
    lamps = np.zeros((32, 16), bool)
    lamps[2::6, 3::5] = True
    ref[:, :, :16][:, lamps] = 5.0
    noisy = ref * (1.0 + 0.2 * (rng.random(ref.shape) - 0.5))
    halo = np.roll(lamps, 1, axis=0) | np.roll(lamps, 1, axis=1)
    noisy[:, :, :16][:, halo] = rng.random((frames, int(halo.sum()), 1)) * 0.5  # lamps flicker into the black
    return noisy, ref


def test_content_map_is_the_share_of_visible_pixels():
    _, ref = _sky_and_wall()
    share = crops.content_map(ref)
    assert share.shape == (32, 32)
    assert share[:, 16:].min() == 1.0 and share[:, :16].mean() < 0.1
    assert crops.content_map(ref[0]).shape == (32, 32)


def test_the_strip_window_shows_the_wall_not_the_black_sky_around_the_lamps():
    noisy, ref = _sky_and_wall()
    side = crops.strip_side(width=32, height=32)
    # without the content rule the flicker alone points at the sky
    error = crops.temporal_relmse_map(noisy, ref).mean(axis=0)
    ((top, left),) = crops.worst_windows(error, side, count=1)
    assert crops.content_map(ref[:, top : top + side, left : left + side]).mean() < crops.MIN_CONTENT
    top, left, side = crops.choose_window(noisy, ref)
    window = ref[:, top : top + side, left : left + side]
    assert crops.content_map(window).mean() >= crops.MIN_CONTENT


def test_without_any_visible_window_the_error_alone_decides():
    error = np.zeros((16, 16))
    error[12, 3] = 1.0
    dark = np.zeros((16, 16))
    assert crops.worst_windows(error, 4, count=1, content=dark) == crops.worst_windows(error, 4, count=1)
