"""Crops show something: on a planted scene, a night sky with small lamps (the reference mostly black)
beside a lit wall with blotchy error, relMSE's worst window is in the sky (a crop there is black on
nearly every pixel); the report's window is the worst one a reader can see into, on the wall."""

from __future__ import annotations

import numpy as np

from denoisebench.metrics import relmse_map
from denoisebench.reports import crop_choice
from denoisebench.reports.images import crop
from denoisebench.results.crops import MIN_CONTENT, worst_windows


def _planted():
    rng = np.random.default_rng(7)
    ref = np.zeros((32, 32, 3), np.float32)
    ref[:, 16:] = 2.0 + 0.5 * rng.random((32, 16, 1)).astype(np.float32)  # the lit wall, textured
    lamps = np.zeros((32, 16), bool)
    lamps[2::6, 3::5] = True  # small lamps in the night sky
    ref[:, :16][lamps] = 5.0
    out = ref.copy()
    out[:, 16:] *= 1.0 + 0.6 * (rng.random((32, 16, 1)) - 0.5).astype(np.float32)  # blotchy error, ±30 %
    halo = np.roll(lamps, 1, axis=0) | np.roll(lamps, 1, axis=1)
    out[:, :16][halo] = 0.4  # each lamp smeared into its black neighbours
    return out, ref


def test_visible_error_picks_the_lit_region_where_relmse_picks_black():
    out, ref = _planted()
    size = 8
    # the peer rule (relMSE, the report's old choice) lands in the black half: its tiles show nothing
    (top, left), *_ = worst_windows(relmse_map(out, ref).reshape(32, 32, -1).mean(axis=-1), size, count=1)
    assert left + size <= 16 and not crop_choice.shows_something(crop(ref, top, left, size))
    windows = crop_choice.crop_windows([out], ref, size, count=2)
    assert len(windows) == 2
    for top, left in windows:
        # at least half of each window on the wall (x ≥ 16): the rule's MIN_CONTENT
        assert left + size - 16 >= size * MIN_CONTENT, windows
        assert crop_choice.shows_something(crop(ref, top, left, size))
    a, b = windows  # not overlapping
    assert abs(a[0] - b[0]) >= size or abs(a[1] - b[1]) >= size


def test_a_perfect_denoiser_still_gets_a_window_with_content():
    _, ref = _planted()
    windows = crop_choice.crop_windows([ref.copy()], ref, 8, count=1)
    assert windows and crop_choice.shows_something(crop(ref, *windows[0], 8))  # no error anywhere
    assert not crop_choice.shows_something(np.zeros((2, 8, 8, 3)))
    assert crop_choice.shows_something(np.full((2, 8, 8, 3), 0.05))
    # an image with nothing visible anywhere: the error alone decides (a window is still given)
    dark = np.zeros((16, 16, 3), np.float32)
    assert len(crop_choice.crop_windows([dark + 1e-4], dark, 4, count=2)) == 2
