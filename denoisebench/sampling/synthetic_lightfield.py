"""A synthetic light field with known pixel integrals: the placed-round interface without a renderer.

:class:`SyntheticLightField` speaks both round interfaces of the renderer's progressive frame
(``render_round(counts)`` and ``render_placed(film, lens, time)``, ``placement_dimensions``), on a
radiance function of screen, lens and time whose pixel integrals are known, so that tests can
measure a multidimensional sampler's and its reconstruction's error and bias exactly (``mdas``).

The scene is a defocused, moving edge over in-focus stripes (1-D in the sense of the slides'
"1 scanline" figure, extended down the image):

    L(x, y, u, v, t) = g(y) · (lo + (hi − lo) · [x + coc · (u − ½) + shift · (t − ½) > edge(y)])

with ``g(y) = 1 + ½ sin(2π y / period)`` (stripes, in focus: no dependence on ``u``, ``v``, ``t``),
a step edge at ``edge(y) = W/2 + slope · (y − H/2)``, ``coc`` the circle of confusion in pixels (the
lens moves the edge) and ``shift`` the motion in pixels over the shutter (time moves it). ``v``
changes nothing (a 1-D aperture in effect), which a sampler should find out.

Each sample is ``L · γ`` with ``γ ~ Gamma(k, 1/k)``, ``k = 1 / noise²`` (mean 1, relative standard
deviation ``noise``): the skewed noise of :mod:`~denoisebench.sampling.synthetic`, the same ``γ``
for the three channels. ``diffuse`` is 0.6 of ``color``, ``specular`` the rest.

Notes
-----
* :attr:`truth` is the pixel integral by midpoint quadrature (:data:`QUADRATURE` points per pixel
  side in ``x`` and ``y``, per unit in ``u`` and ``t``): exact to about 1e-3 relative at the edge.
* A count round draws its positions uniformly (pixel × lens × shutter) from ``default_rng([seed, i])``
  for round ``i``; a placed round uses the caller's positions. Per-pixel buffers pool both kinds,
  with the renderer's conventions (mean 0 and variance inf without samples, variance 0 with one).
"""

from __future__ import annotations

import time as _time
from dataclasses import dataclass

import numpy as np

from denoisebench.generator.render.placed import PlacedMoments, check_positions

QUADRATURE = 24


@dataclass
class RoundBuffers:
    """What a round returns: the renderer's fields (``placed``: a placed round's samples in request order)."""

    buffers: dict[str, np.ndarray]
    counts: np.ndarray
    seconds: float
    samples: dict[str, np.ndarray] | None = None
    placed: dict[str, np.ndarray] | None = None


class SyntheticLightField:
    """The defocused moving edge of the module docstring, ``width``×``height`` pixels."""

    def __init__(
        self,
        width: int = 32,
        height: int = 16,
        *,
        coc: float = 6.0,
        shift: float = 0.0,
        slope: float = 0.25,
        period: float = 5.0,
        lo: float = 0.1,
        hi: float = 1.0,
        noise: float = 0.5,
        seed: int = 0,
    ):
        self.width, self.height = int(width), int(height)
        self.coc, self.shift, self.slope, self.period = float(coc), float(shift), float(slope), float(period)
        self.lo, self.hi, self.noise, self.seed = float(lo), float(hi), float(noise), int(seed)
        self.placement_dimensions = ("lens",) + (("time",) if self.shift else ())
        self._moments = PlacedMoments(self.width, self.height, {"color": 3, "diffuse": 3, "specular": 3})
        self._rounds = 0
        self._truth = None

    def radiance(self, x, y, u, t):
        """L at the given coordinates (arrays broadcast), without noise."""
        edge = self.width / 2 + self.slope * (y - self.height / 2)
        moved = x + self.coc * (u - 0.5) + self.shift * (t - 0.5)
        stripes = 1.0 + 0.5 * np.sin(2 * np.pi * y / self.period)
        return stripes * np.where(moved > edge, self.hi, self.lo)

    @property
    def truth(self) -> np.ndarray:
        """H×W×3 pixel integrals (module Notes)."""
        if self._truth is None:
            q = (np.arange(QUADRATURE) + 0.5) / QUADRATURE
            times = q if self.shift else np.array([0.5])
            out = np.zeros((self.height, self.width))
            for row in range(self.height):
                y = row + q[:, None, None, None, None]
                x = np.arange(self.width)[None, :, None, None, None] + q[None, None, :, None, None]
                u = q[None, None, None, :, None]
                t = times[None, None, None, None, :]
                out[row] = self.radiance(x, y, u, t).mean(axis=(0, 2, 3, 4))
            self._truth = np.repeat(out[..., None], 3, axis=2)
        return self._truth

    def render_round(self, counts) -> RoundBuffers:
        """``counts`` more samples per pixel at uniform positions."""
        counts = np.asarray(counts)
        if counts.shape != (self.height, self.width) or (counts < 0).any():
            raise ValueError(f"counts must be a non-negative {self.height}×{self.width} map")
        rng = np.random.default_rng([self.seed, self._rounds, 1])
        cells = np.repeat(np.arange(self.width * self.height), counts.astype(np.int64).ravel())
        film = rng.random((cells.size, 2)) + np.stack([cells % self.width, cells // self.width], 1)
        lens = rng.random((cells.size, 2))
        time = rng.random(cells.size) if "time" in self.placement_dimensions else None
        out = self.render_placed(np.minimum(film, np.nextafter([self.width, self.height], 0)), lens, time)
        out.placed = None
        return out

    def render_placed(self, film, lens=None, time=None) -> RoundBuffers:
        """One sample at each position (``film`` N×2 pixels, ``lens`` N×2, ``time`` N in [0, 1))."""
        started = _time.perf_counter()
        film, lens, time = check_positions(
            film, lens, time, width=self.width, height=self.height, dimensions=self.placement_dimensions
        )
        rng = np.random.default_rng([self.seed, self._rounds, 0])
        self._rounds += 1
        t = time if time is not None else np.full(film.shape[0], 0.5)
        value = self.radiance(film[:, 0], film[:, 1], lens[:, 0], t)
        if self.noise > 0:
            k = 1.0 / self.noise**2
            value = value * rng.gamma(k, 1.0 / k, size=value.shape)
        color = np.repeat(value[:, None], 3, axis=1).astype(np.float32)
        placed = {"color": color, "diffuse": 0.6 * color, "specular": 0.4 * color}
        placed["pixel"] = (film - np.floor(film)).astype(np.float32)
        placed["lens"] = lens.astype(np.float32)
        if time is not None:
            placed["time"] = time[:, None].astype(np.float32)
        self._moments.add(film, placed)
        empty = {}
        for name in ("color", "diffuse", "specular"):
            empty[name] = np.zeros((self.height, self.width, 3), np.float32)
            empty[f"{name}_var"] = np.zeros((self.height, self.width, 3), np.float32)
        buffers = self._moments.merge(empty, np.zeros((self.height, self.width), np.int64))
        return RoundBuffers(
            buffers=buffers,
            counts=self._moments.counts().astype(np.int32),
            seconds=_time.perf_counter() - started,
            placed=placed,
        )
