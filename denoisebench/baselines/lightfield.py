"""``lightfield``: temporal light field reconstruction of defocus and motion blur (Lehtinen et al. 2011).

Lehtinen, J., Aila, T., Chen, J., Laine, S. and Durand, F. (2011), "Temporal light field
reconstruction for rendering distribution effects", ACM Transactions on Graphics 30(4). Each input
sample is a point of the light field at screen ``(x, y)``, lens ``(u, v)`` and time ``t``; the
surface point it saw stays on a known *trajectory* as the lens point and the time change, so one
sample stands for the radiance along a whole line of the (x, y, u, v, t) space. A few samples per
pixel, reprojected along their trajectories, reconstruct the image a great many would.

Per frame (``needs`` = {"samples"}: ``color``, ``depth``, ``position``, ``pixel`` and, where the plan
has them, ``lens`` and ``time``):

1. **Trajectories.** A thin lens moving through the shutter projects a world point ``P`` at camera
   depth ``z`` seen through lens point ``L`` (the unit-disk point of the stored square sample) at time
   ``τ = t − ½`` to ``x·z = m_x·[P, 1] + Σ_q (a_q + b_q z)·q`` for ``q ∈ (L_x, L_y, τ)``, and likewise
   for ``y``: perspective (``m``), the circle of confusion (``a/z + b`` per unit of lens: 0 at the
   focus distance) and camera motion linearised over the shutter (translation ``a/z``, rotation
   ``b``). The denoiser knows no camera: it fits those coefficients by least squares to the samples
   themselves (their screen position, depth, world position, lens and time). A sample's trajectory
   is then ``X(q') = X + J·(q' − q)`` with ``J = (a + b z) / z`` per screen axis and parameter.
2. **Reconstruction points.** ``points`` per pixel (default: the input's spp, at least 8): stratified
   sub-pixel positions with lens and time points from a fixed random stream.
3. **Gather.** For each point ``(x, y, q)``, every sample within ``window`` pixels (what the largest
   trajectory can travel, capped at ``max_window``) is reprojected to the point's ``q``; those that
   land within ``radius`` pixels are its hits (``radius`` = √(hits / (π·spp)), about ``hits``
   expected hits, at least half a pixel; ``hits`` 16). Measured on synthetic 32 px defocus frames at
   4 spp (3 draws, relMSE): 4 points 0.32, 8 points 0.14 at 8 hits; 16 hits and 8 points 0.10,
   12-16 points or 32 hits no better.
4. **Visibility: SameSurface.** The hit nearest the camera names the front surface; another hit
   belongs to it when their trajectories do not cross anywhere in the lens × shutter domain (the
   slides' rule: trajectories of samples from one apparent surface never intersect), tested at the
   domain's corners against their offset at the point. The front surface is the point's visible
   one when it *covers* the point: at least two hits whose mean offset from the point is under
   half the radius (samples on both sides, not the fringe of an occluder); otherwise the hits
   behind it are.
5. The point's radiance is the mean colour of its visible hits; a pixel is the mean of its points
   that had hits (its input mean where none had).

Notes
-----
* **Differences from the paper.** The paper takes camera and motion from the renderer and stores
  per-sample motion vectors; here the thin-lens and camera-motion model is fitted to the samples
  (step 1). The fit cannot express objects that move on their own within the shutter: where its
  residual is over :data:`MAX_FIT_RESIDUAL` pixels at the median the time terms are dropped (the
  lens terms too if they do not fit), and samples whose own residual exceeds it keep still
  trajectories. The paper finds hits through a hierarchy over trajectories and resolves visibility
  per point with a coverage test over surface spans; here the gather is a window scan and coverage
  is the mean-offset test of step 4. The paper's filter weights hits by their reprojected
  distance; here hits within the radius weigh the same.
* **Fireflies stay in their pixel.** A sample over :data:`FIREFLY` times the local median sample
  luminance (per-pixel medians averaged over 5×5 pixels) is not reprojected: it keeps its share
  ``1/spp`` of its own pixel, whose other ``1 − k/spp`` is the reconstruction; spread along its
  trajectory it would paint a bright streak (the hard-case suite's fireflies: 784× the input's
  robust mean without this rule). In expectation this is the pixel's own estimate of that sample.
* Every output is a mean of input sample colours (or the input's pixel mean): finite and
  non-negative where the samples are. Non-finite sample values count as zero.
* Each point keeps its :data:`KEEP` nearest reprojected candidates before the visibility test, so
  that test costs per hit, not per candidate; with the default 16 expected hits, more than 64 within
  the radius is a tail event. Cost grows with ``points × window² × spp`` per pixel; the window is what the scene's defocus and
  motion need, capped at ``max_window``.
"""

from __future__ import annotations

import numpy as np
from scipy.ndimage import uniform_filter

from denoisebench.dataset.frame import Frame
from denoisebench.denoisers.lens_sampling import square_to_disk_concentric
from denoisebench.denoisers.protocol import DenoiserBase

#: Median fit residual (pixels) above which the camera model's lens or time terms are dropped.
MAX_FIT_RESIDUAL = 0.35
#: Depth used for samples that hit nothing (their trajectories follow the constant terms only).
FAR = 1e6
#: A sample brighter than this many times its 5×5 neighbourhood's median sample luminance is a firefly.
FIREFLY = 100.0
#: Candidates a reconstruction point keeps, nearest first (about 4× the expected hits at the default 16).
KEEP = 64
#: Most reprojected (query, candidate) pairs held at once.
CHUNK_PAIRS = 1 << 19


def _fit(x, z, position, params):
    """Least-squares ``x·z = m·[P, 1] + Σ_q (a_q + b_q·z)·q``; returns (m, a, b) and the per-sample residual in pixels."""
    design = [position, np.ones((len(z), 1))]
    for q in params.T:
        design += [q[:, None], (z * q)[:, None]]
    design = np.concatenate(design, axis=1)
    target = x * z
    coef, *_ = np.linalg.lstsq(design, target, rcond=None)
    residual = np.abs(design @ coef - target) / np.maximum(z, 1e-9)
    return coef, residual


class LightField(DenoiserBase):
    """Temporal light field reconstruction (module docstring)."""

    name = "lightfield"
    needs = frozenset({"samples"})
    temporal = False

    def __init__(self, points: int | None = None, hits: float = 16.0, max_window: int = 8, seed: int = 0):
        if points is not None and points < 1:
            raise ValueError("lightfield needs points >= 1")
        if not hits > 0 or max_window < 1:
            raise ValueError("lightfield needs hits > 0 and max_window >= 1")
        self.points = points
        self.hits = float(hits)
        self.max_window = int(max_window)
        self.seed = int(seed)
        self.last_fit: dict | None = None  # what the last frame's trajectory fit found (for reports and tests)

    # ------------------------------------------------------------------------------------ trajectories
    def trajectories(self, samples) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """Per-sample screen position (N×2), parameters q (N×Q: lens disk x, y, then τ), slopes J (N×2×Q), depth (N)."""
        color = samples["color"]
        spp, height, width = color.shape[:3]
        rows, cols = np.mgrid[0:height, 0:width]
        pixel = (
            np.nan_to_num(np.asarray(samples["pixel"], np.float64))
            if "pixel" in samples
            else np.full((spp, height, width, 2), 0.5)
        )
        screen = np.stack([cols[None] + pixel[..., 0], rows[None] + pixel[..., 1]], -1).reshape(-1, 2)
        params = []
        if "lens" in samples:
            params.append(square_to_disk_concentric(np.clip(np.nan_to_num(samples["lens"]), 0.0, 1.0)).reshape(-1, 2))
        if "time" in samples:
            params.append(np.nan_to_num(np.asarray(samples["time"], np.float64)).reshape(-1, 1) - 0.5)
        q = np.concatenate(params, axis=1) if params else np.zeros((screen.shape[0], 0))
        depth = np.nan_to_num(np.asarray(samples["depth"], np.float64), nan=0.0, posinf=0.0).reshape(-1)
        hit = depth > 0
        z = np.where(hit, depth, FAR)
        slopes = np.zeros((screen.shape[0], 2, q.shape[1]))
        self.last_fit = {"params": q.shape[1], "used": 0, "residual": None}
        if q.shape[1] == 0 or "position" not in samples or hit.sum() < 8 * (5 + 2 * q.shape[1]):
            return screen, q, slopes, z
        position = np.nan_to_num(np.asarray(samples["position"], np.float64)).reshape(-1, 3)
        pick = np.flatnonzero(hit)
        if pick.size > 20000:
            pick = np.random.default_rng(self.seed).choice(pick, 20000, replace=False)
        # try the full model, then lens terms only (a scene whose objects move on their own)
        has_lens = "lens" in samples
        tries = [np.arange(q.shape[1])]
        if has_lens and q.shape[1] == 3:
            tries.append(np.arange(2))
        for used in tries:
            coefs, residuals = [], []
            for axis in range(2):
                coef, residual = _fit(screen[pick, axis], z[pick], position[pick], q[pick][:, used])
                coefs.append(coef)
                residuals.append(residual)
            median = float(np.median(np.maximum(*residuals)))
            if median <= MAX_FIT_RESIDUAL:
                for axis, coef in enumerate(coefs):
                    a, b = coef[4::2], coef[5::2]
                    slopes[:, axis, used] = (a[None, :] + b[None, :] * z[:, None]) / z[:, None]
                # samples the model does not explain (their own motion) keep still trajectories
                full = np.zeros(screen.shape[0], bool)
                for axis, coef in enumerate(coefs):
                    design = [position, np.ones((len(z), 1))]
                    for column in q[:, used].T:
                        design += [column[:, None], (z * column)[:, None]]
                    err = np.abs(np.concatenate(design, 1) @ coef - screen[:, axis] * z) / z
                    full |= hit & (err > 2 * MAX_FIT_RESIDUAL)
                slopes[full] = 0.0
                self.last_fit = {"params": q.shape[1], "used": len(used), "residual": median}
                break
        return screen, q, slopes, z

    # ------------------------------------------------------------------------------------------ filter
    def denoise(self, frame: Frame) -> np.ndarray:
        samples = frame.samples
        if samples is None or "color" not in samples or "depth" not in samples:
            raise ValueError("lightfield needs per-sample data with 'color' and 'depth'")
        color = np.nan_to_num(np.asarray(samples["color"], np.float64), nan=0.0, posinf=0.0, neginf=0.0)
        spp, height, width = color.shape[:3]
        screen, q, slopes, z = self.trajectories(samples)
        colors = color.reshape(-1, 3)
        points = self.points or max(8, spp)
        radius = max(np.sqrt(self.hits / (np.pi * spp)), 0.5)
        travel = np.abs(slopes).sum(axis=2).max() * 2.0 if slopes.size else 0.0  # lens spans 2, time 1
        window = int(min(self.max_window, np.ceil(travel + radius)))

        rng = np.random.default_rng(self.seed)
        # reconstruction points: stratified sub-pixel positions (a points-long 1-D stratification per axis,
        # shuffled), lens and time from the stream
        strata = (np.arange(points) + rng.random((2, points))) / points
        strata[1] = rng.permutation(strata[1])
        params_q = np.zeros((points, q.shape[1]))
        at = 0
        if "lens" in samples:
            params_q[:, :2] = square_to_disk_concentric(rng.random((points, 2)))
            at = 2
        if "time" in samples:
            params_q[:, at] = rng.random(points) - 0.5

        # fireflies stay in their own pixel (Notes): flagged against the local robust level
        lum = color @ np.array([0.2126, 0.7152, 0.0722])  # S×H×W
        level = uniform_filter(np.median(lum, axis=0), size=5, mode="nearest")
        outlier = lum > FIREFLY * np.maximum(level, 1e-12)[None]
        kept = (~outlier).sum(axis=0)
        own = np.where(outlier[..., None], color, 0.0).sum(axis=0) / spp  # the outliers' share of the pixel mean
        rest = np.where(outlier[..., None], 0.0, color).sum(axis=0) / np.maximum(kept, 1)[..., None]
        share = (kept / spp)[..., None]
        outlier = outlier.reshape(-1)
        out = rest.copy()  # pixels whose points had no hits: their own samples
        offsets = np.arange(-window, window + 1)
        dy, dx = np.meshgrid(offsets, offsets, indexing="ij")
        dy, dx = dy.ravel(), dx.ravel()
        per_query = dy.size * spp
        rows_per_chunk = max(1, CHUNK_PAIRS // max(per_query * width, 1))
        pixels = height * width
        corners = self._corners(q.shape[1], "lens" in samples)
        for row0 in range(0, height, rows_per_chunk):
            rows = np.arange(row0, min(height, row0 + rows_per_chunk))
            qy, qx = np.meshgrid(rows, np.arange(width), indexing="ij")
            qy, qx = qy.ravel(), qx.ravel()  # query pixels of the chunk
            # candidate samples: pixel (qy+dy, qx+dx) clamped-out, each of its spp samples
            cy = qy[:, None] + dy[None, :]
            cx = qx[:, None] + dx[None, :]
            inside = (cy >= 0) & (cy < height) & (cx >= 0) & (cx < width)
            cand_pixel = np.where(inside, cy * width + cx, 0)
            cand = (np.arange(spp)[None, None, :] * pixels + cand_pixel[:, :, None]).reshape(len(qy), -1)
            cand_ok = np.repeat(inside, spp, axis=1) & ~outlier[cand]
            slope_c = slopes[cand]
            base = screen[cand] - np.einsum("nmaq,nmq->nma", slope_c, q[cand])  # where a trajectory is at q = 0
            gathered = (base, slope_c, z[cand], colors[cand])
            sums = np.zeros((len(qy), 3))
            used = np.zeros(len(qy))
            for k in range(points):
                point = np.stack([qx + strata[0, k], qy + strata[1, k]], 1)  # query positions
                value, found = self._point(*gathered, cand_ok, point, params_q[k], radius, corners)
                sums += value
                used += found
            pix = qy * width + qx
            have = used > 0
            flat = out.reshape(-1, 3)
            flat[pix[have]] = sums[have] / used[have, None]
        out = share * out + own
        return np.maximum(np.nan_to_num(out, nan=0.0, posinf=0.0, neginf=0.0), 0.0).astype(np.float32)

    @staticmethod
    def _corners(count: int, has_lens: bool) -> np.ndarray:
        """The corners of the parameter domain (lens square [−1, 1]², time [−½, ½]) as C×Q."""
        if count == 0:
            return np.zeros((1, 0))
        ranges = []
        if has_lens:
            ranges += [(-1.0, 1.0), (-1.0, 1.0)]
        if count > len(ranges):
            ranges.append((-0.5, 0.5))
        grids = np.meshgrid(*[np.array(r) for r in ranges], indexing="ij")
        return np.stack([g.ravel() for g in grids], 1)

    @staticmethod
    def _point(base, slopes, z, colors, near_ok, point, params, radius, corners):
        """Visible-hit mean colour for one reconstruction point per query, and 1 where it had hits.

        The candidates' arrays are gathered per query (Qn×M…): trajectory at q = 0, slopes, depth
        and colour.
        """
        offset = base + (slopes @ params) - point[:, None, :]
        distance = np.where(near_ok, (offset**2).sum(axis=2), np.inf)
        if distance.shape[1] > KEEP:  # the KEEP nearest candidates (hits beyond them are rare: Notes)
            keep = np.argpartition(distance, KEEP - 1, axis=1)[:, :KEEP]
            offset = np.take_along_axis(offset, keep[..., None], axis=1)
            distance = np.take_along_axis(distance, keep, axis=1)
            slopes = np.take_along_axis(slopes, keep[..., None, None], axis=1)
            z = np.take_along_axis(z, keep, axis=1)
            colors = np.take_along_axis(colors, keep[..., None], axis=1)
        near = distance < radius**2
        front = np.argmin(np.where(near, z, np.inf), axis=1)
        rows = np.arange(len(z))
        # SameSurface: the relative trajectory D(p) = D(point) + (J_j − J_f)(p − point) keeps the sign
        # of D(point) at every corner of the domain (the trajectories do not cross there)
        rel_now = offset - offset[rows, front][:, None, :]
        dslope = slopes - slopes[rows, front][:, None, :, :]
        same = np.ones(near.shape, bool)
        for corner in corners:
            d_corner = rel_now + np.einsum("nmaq,q->nma", dslope, corner - params)
            same &= (d_corner * rel_now).sum(axis=2) >= 0.0
        surface = near & same
        count = surface.sum(axis=1)
        centre = np.abs((offset * surface[..., None]).sum(axis=1) / np.maximum(count, 1)[:, None]).max(axis=1)
        covers = (count >= 2) & (centre < 0.5 * radius)
        behind = near & ~same
        use = np.where((covers | ~behind.any(axis=1))[:, None], surface, behind)
        weight = use.astype(np.float64)
        total = weight.sum(axis=1)
        value = np.einsum("nm,nmc->nc", weight, colors) / np.maximum(total, 1.0)[:, None]
        found = total > 0
        return value * found[:, None], found.astype(np.float64)
