"""Procedural lat-long environments for cluttered scenes: clear sky with sun, overcast, studio, sunset.

Each is ``(image, dome intensity, sun)``: an equirectangular H×W×3 image in [0, 1] (top row up,
written as a PNG, so its dynamic range comes from the dome light's intensity), and for the sunny
kinds a ``(azimuth_deg, elevation_deg, intensity, colour)`` sun that the family authors as a
``DistantLight`` (the HDR part a PNG cannot hold). :data:`KINDS` lists them; the cluttered family
keeps ``sunset`` for its held-out scenes only.
"""

from __future__ import annotations

import numpy as np

from denoisebench.scenes import textures

KINDS = ("sky_sun", "overcast", "studio", "sunset")


def _latlong(width: int, height: int):
    u, v = np.meshgrid((np.arange(width) + 0.5) / width, (np.arange(height) + 0.5) / height)
    return u, (0.5 - v) * np.pi  # azimuth fraction, elevation


def overcast(rng: np.random.Generator, width: int, height: int) -> np.ndarray:
    """A bright, nearly uniform grey sky (cos-weighted towards the zenith), a dark ground."""
    u, elev = _latlong(width, height)
    grey = rng.uniform(0.75, 0.95)
    sky = grey * (0.6 + 0.4 * np.clip(np.sin(elev), 0.0, 1.0))
    clouds = 0.08 * textures.value_noise(rng, width, octaves=4, base_cells=4)[:height, :width]
    value = np.where(elev >= 0.0, sky + clouds, 0.25 * grey)
    tint = np.array([1.0, 1.0, 1.02]) * rng.uniform(0.95, 1.0, 3)
    return np.clip(value[..., None] * tint, 0.0, 1.0)


def make(kind: str, rng: np.random.Generator, width: int = 256, height: int = 128):
    """``(image, dome intensity, sun or None)`` of an environment of ``kind``."""
    if kind == "sky_sun":
        azimuth, elevation = rng.uniform(0.0, 360.0), rng.uniform(25.0, 65.0)
        image = textures.sky_latlong(width, height, azimuth, elevation)
        return image, rng.uniform(0.8, 1.2), (azimuth, elevation, rng.uniform(2.5, 4.0), (1.0, 0.96, 0.88))
    if kind == "sunset":
        azimuth, elevation = rng.uniform(0.0, 360.0), rng.uniform(3.0, 12.0)
        image = textures.sky_latlong(
            width, height, azimuth, elevation, zenith=(0.2, 0.25, 0.5), horizon=(0.95, 0.55, 0.3), sun_radius_deg=5.0
        )
        return image, rng.uniform(0.8, 1.2), (azimuth, elevation, rng.uniform(2.0, 3.0), (1.0, 0.6, 0.35))
    if kind == "overcast":
        return overcast(rng, width, height), rng.uniform(1.0, 1.5), None
    if kind == "studio":
        return textures.studio_latlong(width, height, rng), rng.uniform(1.5, 2.5), None
    raise ValueError(f"unknown environment kind {kind!r} (known: {', '.join(KINDS)})")
