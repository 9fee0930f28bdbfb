"""Procedural textures as uint8 RGB arrays, and a deterministic PNG writer.

Every generator is a pure function of its arguments (and of a seeded ``numpy.random.Generator``
where it takes one), so the same family and seed write the same bytes. Images are written with
pillow at a fixed compression level and no ancillary chunks (no timestamps, no text).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
from PIL import Image


def write_png(path: Path, rgb: np.ndarray) -> Path:
    """Write an H×W×3 uint8 (or float in [0, 1]) array as an 8-bit RGB PNG; deterministic bytes."""
    arr = np.asarray(rgb)
    if arr.dtype != np.uint8:
        arr = np.clip(np.round(np.asarray(arr, dtype=np.float64) * 255.0), 0, 255).astype(np.uint8)
    if arr.ndim == 2:
        arr = np.repeat(arr[..., None], 3, axis=2)
    if arr.ndim != 3 or arr.shape[2] != 3:
        raise ValueError(f"expected an H×W×3 image, got shape {arr.shape}")
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(f".{path.name}.tmp")
    Image.fromarray(np.ascontiguousarray(arr)).save(tmp, format="PNG", compress_level=6)
    tmp.replace(path)
    return path


def _uv(size: int, height: int | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Pixel-center coordinates u (columns) and v (rows, 0 at the top) in [0, 1)."""
    h = size if height is None else height
    u = (np.arange(size, dtype=np.float64) + 0.5) / size
    v = (np.arange(h, dtype=np.float64) + 0.5) / h
    return np.meshgrid(u, v)


def _mix(c0, c1, t: np.ndarray) -> np.ndarray:
    c0, c1 = np.asarray(c0, dtype=np.float64), np.asarray(c1, dtype=np.float64)
    return c0 + (c1 - c0) * t[..., None]


def checker(size: int, checks: int, c0=(0.9, 0.9, 0.9), c1=(0.05, 0.05, 0.05)) -> np.ndarray:
    """A ``checks``×``checks`` checkerboard, float RGB in [0, 1]."""
    u, v = _uv(size)
    t = ((np.floor(u * checks) + np.floor(v * checks)) % 2).astype(np.float64)
    return _mix(c0, c1, t)


def stripes(size: int, count: int, c0, c1, angle_deg: float = 0.0, duty: float = 0.5) -> np.ndarray:
    """``count`` hard-edged stripes across the tile at ``angle_deg``."""
    u, v = _uv(size)
    a = np.deg2rad(angle_deg)
    s = (u * np.cos(a) + v * np.sin(a)) * count
    t = ((s - np.floor(s)) < duty).astype(np.float64)
    return _mix(c0, c1, t)


def zone_plate(size: int, cycles: float, c0=(0.05, 0.05, 0.05), c1=(0.95, 0.95, 0.95)) -> np.ndarray:
    """A zone plate: cos(k r²), frequency rising to ``cycles`` per half-width at the edge (aliasing bait)."""
    u, v = _uv(size)
    r2 = (u - 0.5) ** 2 + (v - 0.5) ** 2
    k = np.pi * cycles / 0.5
    t = 0.5 + 0.5 * np.cos(k * r2 / 0.5)
    return _mix(c0, c1, t)


def value_noise(rng: np.random.Generator, size: int, octaves: int = 5, base_cells: int = 4) -> np.ndarray:
    """Tileable fractal value noise in [0, 1], H×W float (bilinear cells, smoothstep weights)."""
    out = np.zeros((size, size), dtype=np.float64)
    amp_sum = 0.0
    u, v = _uv(size)
    for o in range(octaves):
        cells = base_cells * 2**o
        grid = rng.random((cells, cells))
        x, y = u * cells, v * cells
        x0, y0 = np.floor(x).astype(int), np.floor(y).astype(int)
        fx, fy = x - x0, y - y0
        fx, fy = fx * fx * (3 - 2 * fx), fy * fy * (3 - 2 * fy)
        x0, y0 = x0 % cells, y0 % cells
        x1, y1 = (x0 + 1) % cells, (y0 + 1) % cells
        top = grid[y0, x0] * (1 - fx) + grid[y0, x1] * fx
        bot = grid[y1, x0] * (1 - fx) + grid[y1, x1] * fx
        amp = 0.5**o
        out += amp * (top * (1 - fy) + bot * fy)
        amp_sum += amp
    return out / amp_sum


def planks(rng: np.random.Generator, size: int, boards: int, base=(0.45, 0.28, 0.15)) -> np.ndarray:
    """Wood-floor boards: per-board tint, grain stripes, dark seams."""
    u, v = _uv(size)
    board = np.floor(v * boards).astype(int)
    tint = rng.uniform(0.75, 1.15, size=boards)
    offset = rng.uniform(0.0, 1.0, size=boards)
    grain_f = rng.uniform(20.0, 40.0, size=boards)
    fv = v * boards - board
    grain = 0.5 + 0.5 * np.sin(2 * np.pi * (grain_f[board] * fv + 3.0 * u + offset[board] * 7.0))
    noise = value_noise(rng, size, octaves=4, base_cells=8)
    shade = tint[board] * (0.8 + 0.12 * grain + 0.16 * noise)
    seam_v = (fv < 0.04) | (fv > 0.96)
    seam_u = np.abs(((u + offset[board]) * 2.0) % 1.0) < 0.006
    shade = np.where(seam_v | seam_u, 0.35, shade)
    return np.clip(np.asarray(base)[None, None, :] * shade[..., None], 0.0, 1.0)


def bricks(size: int, rows: int, cols: int, brick=(0.55, 0.22, 0.15), mortar=(0.8, 0.78, 0.72)) -> np.ndarray:
    """Running-bond bricks with thin mortar lines (high-frequency edges)."""
    u, v = _uv(size)
    r = np.floor(v * rows)
    shifted = u * cols + 0.5 * (r % 2)
    fu, fv = shifted - np.floor(shifted), v * rows - r
    line = (fu < 0.06) | (fv < 0.1)
    return _mix(brick, mortar, line.astype(np.float64))


def sky_latlong(
    width: int,
    height: int,
    sun_azimuth_deg: float,
    sun_elevation_deg: float,
    zenith=(0.25, 0.45, 0.85),
    horizon=(0.85, 0.9, 0.95),
    ground=(0.3, 0.27, 0.22),
    sun_radius_deg: float = 4.0,
) -> np.ndarray:
    """An equirectangular sky (top row = up): gradient, dark ground, a saturated sun spot.

    8-bit, so "HDR-ish" only: the sun is pure white and the dome light's intensity scales it.
    Columns map to azimuth 0..360°, rows to elevation +90..−90°.
    """
    u, v = _uv(width, height)
    elev = (0.5 - v) * np.pi
    azim = u * 2.0 * np.pi
    t = np.clip(elev / (0.5 * np.pi), 0.0, 1.0) ** 0.6
    sky = _mix(horizon, zenith, t)
    img = np.where((elev < 0.0)[..., None], _mix(horizon, ground, np.clip(-elev * 6.0, 0.0, 1.0)), sky)
    se, sa = np.deg2rad(sun_elevation_deg), np.deg2rad(sun_azimuth_deg)
    sun = np.array([np.cos(se) * np.cos(sa), np.sin(se), np.cos(se) * np.sin(sa)])
    d = np.stack([np.cos(elev) * np.cos(azim), np.sin(elev), np.cos(elev) * np.sin(azim)], axis=-1)
    ang = np.rad2deg(np.arccos(np.clip(d @ sun, -1.0, 1.0)))
    glow = np.exp(-((ang / (sun_radius_deg * 4.0)) ** 2))[..., None]
    img = img * (1.0 - 0.5 * glow) + 0.5 * glow
    img = np.where((ang < sun_radius_deg)[..., None], 1.0, img)
    return np.clip(img, 0.0, 1.0)


def studio_latlong(width: int, height: int, rng: np.random.Generator) -> np.ndarray:
    """An equirectangular studio environment: dark gradient with a few bright softbox panels."""
    u, v = _uv(width, height)
    elev = (0.5 - v) * np.pi
    base = 0.06 + 0.12 * np.clip(np.sin(elev), 0.0, 1.0)
    img = np.repeat(base[..., None], 3, axis=2) * np.array([1.0, 0.97, 0.92])
    for _ in range(3):
        cu, cv = rng.uniform(0.0, 1.0), rng.uniform(0.15, 0.4)
        hw, hh = rng.uniform(0.03, 0.07), rng.uniform(0.04, 0.1)
        du = np.abs(((u - cu + 0.5) % 1.0) - 0.5)
        panel = (du < hw) & (np.abs(v - cv) < hh)
        img = np.where(panel[..., None], 1.0, img)
    return np.clip(img, 0.0, 1.0)
