"""The ``mdas`` sampler: multidimensional adaptive sampling and reconstruction.

Hachisuka, T., Jarosz, W., Weistroffer, R. P., Dale, K., Humphreys, G., Zwicker, M. and Jensen,
H. W. (2008), "Multidimensional adaptive sampling and reconstruction for ray tracing", ACM
Transactions on Graphics 27(3). Samples live in the joint space of the render plan's random
parameters: screen ``x, y`` plus lens ``u, v`` with depth of field plus shutter time ``t`` with
motion blur (:attr:`~denoisebench.sampling.harness.RoundHandle.dimensions`). A k-d tree over that
space is refined where the samples' contrast is high, new samples go to the leaves in proportion to
their error, and a pixel's value integrates, over the non-screen dimensions, the leaves that lie in
it, each leaf valued by an anisotropic neighbourhood of samples. :mod:`denoisebench.generator.render.placed`
renders the samples at the positions chosen here.

Algorithm (per frame):

1. **Initial round**: ``initial_share`` of the budget, the same count in every pixel (counts differ by
   one at most), each sample uniform in its pixel × lens × shutter.
2. **Tree**: the top of the tree is the pixel grid; each pixel's cell is split at the midpoint of its
   longest side (screen sides in pixels, the others in units of ``1 / scale``) until every leaf holds
   at most one sample (empty leaves stay: they are regions no sample fell in).
3. **Error**: a leaf's contrast is read from the ``neighbours`` samples nearest its centre: by default
   (``contrast="gradient"``) the relative luminance change their least-squares gradient predicts
   across their radius; ``contrast="mitchell"`` is the paper's ``(max − min) / (max + min)`` (largest
   over the colour channels), which Monte Carlo noise nearly saturates (on the synthetic light field
   at 4 spp it sent 1.2× the samples per pixel to the defocused edge, the gradient rule 1.9×, and
   relMSE 0.027 against 0.021). Its error is ``contrast · volume``; a round's samples are allocated to leaves in proportion to error (largest
   remainder) and put uniformly inside their leaf. ``rounds`` such rounds spend what is left.
4. **Reconstruction** (:meth:`MDAS.reconstruct`): the final tree's leaves are valued by an anisotropic
   neighbour filter, the mean of the ``filter_size`` samples nearest the leaf centre in the metric
   ``|Δ|² / r² + (ĝ · Δ)² / c₀²``, ``r`` the distance to the ``neighbours``-th nearest sample, ``ĝ``
   the luminance gradient (least squares over those neighbours) relative to their mean luminance and
   ``c₀ = 0.25``: neighbours are taken along the directions where the image does not change, not
   across edges (the paper's structure tensor, rank one). A pixel's ``color`` (and ``diffuse``,
   ``specular``, with the same weights, so that their sum stays ``color``) is the sum over its leaves
   of leaf value × leaf volume: the integral over the non-screen dimensions and the pixel's area.

Notes
-----
* **Differences from the paper.** The paper places samples one at a time in the leaf of largest error
  and splits the leaf around the new sample; here a round is placed at once, allocated in proportion
  to error, and the tree is rebuilt from all samples after each round (the same tree shape rule: at
  most one sample per leaf). The tree's top levels are the pixel grid, so no leaf straddles a pixel
  (the paper's leaves may span several pixels in flat regions): integration is exact per pixel, and a
  flat region's leaves borrow their value from neighbours across pixels instead. The paper's
  anisotropic filter uses the full structure tensor of gradients; this uses the rank-one tensor of
  the local gradient. The error rule has no special treatment of noise: Monte Carlo noise reads as
  contrast, as in the paper.
* **Bias.** The reconstruction is a filter: it trades variance for bias at edges, texture and
  defocus boundaries; the renderer's side is unbiased per sample (placed.py). The bias is measured
  in tests/sampling/test_mdas.py on a synthetic defocused light field with known integral
  (:mod:`denoisebench.sampling.synthetic_lightfield`) and stated in ``sampling/mdas_card.md``.
  Adaptive placement adds a bias of its own: a bright outlier reads as contrast, draws new samples
  around it, and those dilute it (in its pixel's mean and in the neighbourhoods that value the
  leaves), so heavy-tailed noise comes out dark. On a rendered depth-of-field stage (16 px, 24
  draws) the image mean was 10.8 % ± 2.7 % (4 spp) and 10.4 % ± 1.6 % (16 spp) low with placement
  reading raw luminance; placement therefore reads luminance clamped at :data:`PLACEMENT_CLAMP`
  times its neighbourhood's median (the reconstruction still uses every sample as it is), which
  brought it to −2.8 % ± 3.4 % at 16 spp (uniform-only placement: −2.1 % ± 3.6 %).
* **Frames that cannot place samples** (synthetic count frames:
  ``rounds.dimensions`` is None) get the image-space tree of ``hachisuka2008`` and no reconstruction,
  so ``mdas`` still spends its budget and passes the convergence check there. Run in a plugin worker
  (``--isolation all``) it places samples through the worker's proxy, but the proxy forwards no
  reconstruction: the pixel means of its samples are scored.
* The random numbers of the positions come from ``numpy.random.default_rng(seed)``: a run is
  deterministic per seed.
"""

from __future__ import annotations

import numpy as np
from scipy.spatial import cKDTree

from denoisebench.sampling.allocation import LUMINANCE_WEIGHTS, allocate
from denoisebench.sampling.hachisuka import Hachisuka2008
from denoisebench.sampling.schedule import round_size, uniform

EPSILON = 1e-4
#: Relative luminance change that counts as one neighbourhood radius in the anisotropic metric.
CONTRAST_SCALE = 0.25
#: Placement reads luminance clamped at this many times its neighbourhood's median (module Notes, "Bias").
PLACEMENT_CLAMP = 4.0
#: Deepest split of a pixel's cell (coincident samples would otherwise split forever).
MAX_DEPTH = 48


class SampleSpace:
    """The sample space of a frame: ``dims`` = ``("x", "y", *extra)``, screen in pixels, the rest in [0, 1)."""

    def __init__(self, width: int, height: int, extra: tuple[str, ...], scale: float):
        self.width, self.height = int(width), int(height)
        self.names = ("x", "y") + tuple(name for name in ("lens", "time") if name in extra)
        self.extra = tuple(name for name in ("lens", "time") if name in extra)
        self.dims = 2 + 2 * ("lens" in extra) + ("time" in extra)
        self.scale = np.array([1.0, 1.0] + [float(scale)] * (self.dims - 2))

    def split_request(self, points: np.ndarray) -> dict:
        """``points`` (N×D) as the keyword arguments of ``render_placed``."""
        out = {"film": points[:, :2], "lens": None, "time": None}
        at = 2
        if "lens" in self.extra:
            out["lens"] = points[:, at : at + 2]
            at += 2
        if "time" in self.extra:
            out["time"] = points[:, at]
        return out

    def pixel_of(self, points: np.ndarray) -> np.ndarray:
        return np.floor(points[:, 1]).astype(np.int64) * self.width + np.floor(points[:, 0]).astype(np.int64)

    def clip(self, points: np.ndarray) -> np.ndarray:
        """Points nudged inside the half-open space (a uniform draw at a leaf's top edge rounds up in float32)."""
        upper = np.array([self.width, self.height] + [1.0] * (self.dims - 2))
        return np.minimum(np.maximum(points, 0.0), np.nextafter(upper, 0.0) - 1e-6 * np.maximum(upper, 1.0))


def build_tree(space: SampleSpace, points: np.ndarray):
    """Leaves ``(lo, hi)`` (L×D each) of the tree over ``points`` (module docstring, step 2), and each point's leaf.

    Vectorised level by level: every leaf with more than one point splits at the midpoint of its
    longest scaled side.
    """
    w, h = space.width, space.height
    ys, xs = np.divmod(np.arange(w * h), w)
    lo = np.zeros((w * h, space.dims))
    hi = np.ones((w * h, space.dims))
    lo[:, 0], lo[:, 1], hi[:, 0], hi[:, 1] = xs, ys, xs + 1, ys + 1
    leaf = space.pixel_of(points)
    for _ in range(MAX_DEPTH):
        occupancy = np.bincount(leaf, minlength=len(lo))
        crowded = np.flatnonzero(occupancy > 1)
        if crowded.size == 0:
            break
        extent = (hi[crowded] - lo[crowded]) * space.scale
        axis = np.argmax(extent, axis=1)
        mid = 0.5 * (lo[crowded, axis] + hi[crowded, axis])
        new = np.arange(len(lo), len(lo) + crowded.size)
        new_lo, new_hi = lo[crowded].copy(), hi[crowded].copy()
        new_lo[np.arange(crowded.size), axis] = mid
        hi[crowded, axis] = mid
        lo = np.concatenate([lo, new_lo])
        hi = np.concatenate([hi, new_hi])
        # points of a crowded leaf at or above the midpoint move to its new upper half
        where = np.full(len(occupancy), -1)
        where[crowded] = np.arange(crowded.size)
        slot = where[leaf]
        moving = slot >= 0
        moving[moving] = points[moving, axis[slot[moving]]] >= mid[slot[moving]]
        leaf = np.where(moving, new[np.maximum(slot, 0)], leaf)
    return lo, hi, leaf


def _luminance(color: np.ndarray) -> np.ndarray:
    return np.asarray(color, dtype=np.float64) @ LUMINANCE_WEIGHTS


def leaf_errors(space: SampleSpace, lo, hi, points, color, neighbours: int, rule: str = "gradient") -> np.ndarray:
    """Contrast × volume of every leaf (module docstring, step 3).

    ``rule`` ``"mitchell"``: the paper's contrast, ``(max − min) / (max + min)`` of the neighbours
    (largest over the colour channels); ``"gradient"``: the relative luminance change the
    least-squares gradient of the neighbours predicts across their radius, ``|ĝ| · r`` (capped at 4),
    which Monte Carlo noise moves much less than it moves the extremes of a few samples.
    """
    k = min(neighbours, len(points))
    centres = 0.5 * (lo + hi) * space.scale
    volume = np.prod(hi - lo, axis=1)
    if rule == "gradient":
        dist, _, relative = _neighbourhood(points * space.scale, _luminance(color), centres, k, clamp=PLACEMENT_CLAMP)
        return np.minimum(np.linalg.norm(relative, axis=1) * dist[:, -1], 4.0) * volume
    _, idx = cKDTree(points * space.scale).query(centres, k=k)
    idx = idx.reshape(len(centres), k)
    values = np.asarray(color, dtype=np.float64)[idx]  # L×k×3
    top, bottom = values.max(axis=1), values.min(axis=1)
    contrast = ((top - bottom) / np.maximum(top + bottom, EPSILON)).max(axis=1)
    return contrast * volume


def place(space: SampleSpace, lo, hi, errors, size: int, rng) -> np.ndarray:
    """``size`` points allocated to leaves in proportion to ``errors``, uniform inside each; most wanted first."""
    counts = allocate(errors, size)
    chosen = np.repeat(np.arange(len(lo)), counts)
    points = lo[chosen] + rng.random((chosen.size, space.dims)) * (hi[chosen] - lo[chosen])
    order = np.argsort(-errors[chosen], kind="stable")  # a cut round keeps the leaves of largest error
    return space.clip(points[order])


def _neighbourhood(scaled: np.ndarray, lum: np.ndarray, centres: np.ndarray, k: int, clamp: float | None = None):
    """The ``k`` samples nearest each centre: ``(dist, idx, relative gradient)`` (L×k, L×k, L×D).

    ``clamp``: fit the gradient to luminances clamped at ``clamp`` × the neighbourhood's median.
    """
    dist, idx = cKDTree(scaled).query(centres, k=k)
    dist, idx = dist.reshape(len(centres), k), idx.reshape(len(centres), k)
    delta = scaled[idx] - centres[:, None, :]  # L×k×D
    values = lum[idx]
    if clamp is not None:
        values = np.minimum(values, clamp * np.median(values, axis=1, keepdims=True))
    mean = values.mean(axis=1)
    radius = np.maximum(dist[:, -1], 1e-6)
    # least-squares gradient of the luminance over the neighbours (ridge-regularised at the radius)
    centred = delta - delta.mean(axis=1, keepdims=True)
    dims = scaled.shape[1]
    normal = np.einsum("lki,lkj->lij", centred, centred) + (1e-3 * radius**2)[:, None, None] * np.eye(dims)
    rhs = np.einsum("lki,lk->li", centred, values - mean[:, None])
    gradient = np.linalg.solve(normal, rhs[..., None])[..., 0]
    return dist, idx, gradient / np.maximum(np.abs(mean), EPSILON)[:, None]


def reconstruction_weights(space: SampleSpace, points, color, *, neighbours: int, filter_size: int):
    """The linear map from sample values to pixel values: ``(pixel, sample, weight)`` triples (module docstring, step 4).

    The samples are split in two halves (even and odd index, independent of their values); each
    leaf takes half its filter from each half, chosen in the metric whose gradient the *other* half
    estimated, so that no sample's own noise decides whether it is used (with the gradient of the
    same samples, a bright outlier steepens the gradient towards itself and is left out: a negative
    bias of about 4 % under skewed noise, measured on the synthetic light field).
    """
    lo, hi, _ = build_tree(space, points)
    scaled = points * space.scale
    centres = 0.5 * (lo + hi) * space.scale
    lum = _luminance(color)
    halves = [np.arange(0, len(points), 2), np.arange(1, len(points), 2)]
    if min(len(h) for h in halves) < 2:
        halves = [np.arange(len(points))] * 2
    found = []
    for half in halves:
        k = min(neighbours, len(half))
        dist, idx, relative = _neighbourhood(scaled[half], lum[half], centres, k)
        found.append((dist, half[idx], relative))
    members = []
    for own, other in ((found[0], found[1]), (found[1], found[0])):
        dist, idx, _ = own
        radius = np.maximum(dist[:, -1], 1e-6)
        delta = scaled[idx] - centres[:, None, :]
        metric = (dist / radius[:, None]) ** 2 + (np.einsum("lkd,ld->lk", delta, other[2]) / CONTRAST_SCALE) ** 2
        m = max(1, min(filter_size // 2, idx.shape[1]))
        nearest = np.argsort(metric, axis=1, kind="stable")[:, :m]
        members.append(np.take_along_axis(idx, nearest, axis=1))
    members = np.concatenate(members, axis=1)  # L×m samples valuing each leaf
    m = members.shape[1]
    volume = np.prod(hi - lo, axis=1)  # the leaf's share of its pixel (pixel area 1, unit non-screen ranges)
    pixel = np.floor(lo[:, 1]).astype(np.int64) * space.width + np.floor(lo[:, 0]).astype(np.int64)
    return np.repeat(pixel, m), members.ravel(), np.repeat(volume / m, m)


def integrate(space: SampleSpace, weights, values: np.ndarray) -> np.ndarray:
    """H×W×C image of per-sample ``values`` (N×C) under :func:`reconstruction_weights`."""
    pixel, sample, weight = weights
    size = space.width * space.height
    values = np.asarray(values, dtype=np.float64)
    out = np.stack([np.bincount(pixel, weight * values[sample, c], minlength=size) for c in range(values.shape[1])], 1)
    return out.reshape(space.height, space.width, values.shape[1]).astype(np.float32)


class MDAS:
    """Multidimensional adaptive sampling with its reconstruction (module docstring)."""

    name = "mdas"

    def __init__(
        self,
        initial_share: float = 0.5,
        rounds: int = 3,
        neighbours: int = 16,
        filter_size: int = 8,
        scale: float = 1.0,
        contrast: str = "gradient",
        seed: int = 0,
    ):
        if not 0 < initial_share <= 1 or rounds < 1 or neighbours < 2 or not 1 <= filter_size <= neighbours:
            raise ValueError(
                "mdas needs 0 < initial_share <= 1, rounds >= 1, neighbours >= 2, 1 <= filter_size <= neighbours"
            )
        if not scale > 0:
            raise ValueError("mdas needs scale > 0")
        self.initial_share = float(initial_share)
        self.rounds = int(rounds)
        self.neighbours = int(neighbours)
        self.filter_size = int(filter_size)
        self.scale = float(scale)
        if contrast not in ("gradient", "mitchell"):
            raise ValueError("mdas contrast is 'gradient' or 'mitchell'")
        self.contrast = contrast
        self.seed = int(seed)
        self._fallback = None
        self._space = None
        self._points = self._values = None

    def sample(self, budget, rounds) -> None:
        self._space, self._points, self._values, self._fallback = None, None, None, None
        if rounds.dimensions is None:  # a frame that cannot place samples (module Notes)
            self._fallback = Hachisuka2008()
            self._fallback.sample(budget, rounds)
            return
        rng = np.random.default_rng(self.seed)
        space = self._space = SampleSpace(rounds.width, rounds.height, rounds.dimensions, self.scale)
        left = rounds.remaining_samples()  # a seconds budget: the harness's one-sample probe
        first = left if budget.seconds is not None else min(max(round(self.initial_share * left), rounds.pixels), left)
        if first <= 0:
            return
        counts = uniform(rounds, first).ravel()
        cells = np.repeat(np.arange(rounds.pixels), counts)
        points = rng.random((cells.size, space.dims))
        points[:, 0] += cells % rounds.width
        points[:, 1] += cells // rounds.width
        self._render(rounds, space.clip(points))
        done = 0
        while not rounds.cut and (size := round_size(rounds, done, self.rounds)) > 0:
            lo, hi, _ = build_tree(space, self._points)
            errors = leaf_errors(space, lo, hi, self._points, self._values["color"], self.neighbours, self.contrast)
            self._render(rounds, place(space, lo, hi, errors, size, rng))
            done += 1

    def _render(self, rounds, points: np.ndarray) -> None:
        result = rounds.render_placed(**self._space.split_request(points))
        kept = len(next(iter(result.placed.values())))
        new = {
            name: np.asarray(result.placed[name]) for name in ("color", "diffuse", "specular") if name in result.placed
        }
        points = points[:kept]
        if self._points is None:
            self._points, self._values = points, new
        else:
            self._points = np.concatenate([self._points, points])
            self._values = {name: np.concatenate([self._values[name], new[name]]) for name in new}

    def reconstruct(self, rounds):
        """The reconstructed ``color``, ``diffuse``, ``specular`` (module docstring, step 4); None in the fallback."""
        if self._points is None or len(self._points) < 2:
            return None
        space = self._space
        weights = reconstruction_weights(
            space, self._points, self._values["color"], neighbours=self.neighbours, filter_size=self.filter_size
        )
        return {name: integrate(space, weights, values) for name, values in self._values.items()}
