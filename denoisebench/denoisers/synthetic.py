"""Synthetic frames with a known clean image: for tests, the hard-case suite and benchmarks.

A tiny analytic "renderer" of a layered 2.5-D scene (a tilted back plane plus discs and rectangles
at different depths, optionally textured, glossy, defocused or moving) that produces everything a
rendered :class:`~denoisebench.dataset.frame.Frame` carries: per-pixel means and variances of
color, diffuse, specular and the features, per-sample data with the random parameters ``pixel``
(always), ``lens`` (depth of field only), ``time`` (motion blur only) and ``bounce`` (the uniform
numbers behind the noise factors below: U = CDF of g_d, V = CDF of g_s), and a reference.

Noise model (known variance): each sample's diffuse radiance is the clean value at the sample's
position times g_d ~ Gamma(k_d, 1/k_d) (mean 1, variance 1/k_d, shared by the three channels, as
one path carries all three), its specular radiance the clean value times an independent
g_s ~ Gamma(k_s, 1/k_s). So a sample's variance is clean²/k and the mean of S samples has variance
clean²/(kS) plus the variance from where the samples land (edges, texture, defocus, motion).
The reference is the noise-free integrand averaged over ``reference_samples`` low-discrepancy
points per pixel (Halton over pixel, lens and time, Cranley-Patterson rotated per pixel).

Depth of field is a thin lens on layers: a sample with lens point L (unit disk) at screen position
p sees layer i at p + R_i·L, where R_i = aperture·|z_i − z_focus| / z_i pixels; the first layer
(front to back) whose shape covers that point is hit. So in a defocused region the hit point and
with it position, depth, albedo depend on the lens u,v; in the focal plane they do not.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from scipy.stats import gamma as gamma_distribution

from denoisebench.dataset.frame import Frame, Sequence
from denoisebench.denoisers.lens_sampling import square_to_disk_concentric

FAMILIES = ("shapes", "textured", "glossy", "depth_of_field", "motion_blur")

_LIGHT = np.array([-0.45, -0.55, 0.70])
_LIGHT = _LIGHT / np.linalg.norm(_LIGHT)
_HALF = _LIGHT + np.array([0.0, 0.0, 1.0])
_HALF = _HALF / np.linalg.norm(_HALF)


@dataclass
class _Layer:
    kind: str  # "plane" | "disc" | "rect"
    depth: float
    albedo: np.ndarray
    cx: float = 0.0
    cy: float = 0.0
    size: float = 0.0  # disc radius, rect half extent (pixels)
    aspect: float = 1.0
    texture: str | None = None  # None | "checker" | "stripes"
    texture_scale: float = 6.0
    specular: float = 0.0
    shininess: float = 30.0
    roughness: float = 0.8
    velocity: tuple[float, float] = (0.0, 0.0)  # pixels over the shutter interval
    tilt: tuple[float, float] = (0.0, 0.0)


@dataclass
class SceneSpec:
    """A layered scene in pixel units (front to back order is by depth)."""

    width: int
    height: int
    layers: list[_Layer]
    focus_depth: float = 0.0
    aperture: float = 0.0  # circle-of-confusion scale in pixels; 0 = pinhole
    motion: bool = False
    diffuse_shape: float = 0.6  # k_d of the gamma noise
    specular_shape: float = 0.2  # k_s
    exposure: float = 1.5
    meta: dict = field(default_factory=dict)


def make_scene(family: str, width: int, height: int, seed: int = 0) -> SceneSpec:
    """A random scene of one of :data:`FAMILIES`, scaled to ``width``×``height`` pixels."""
    if family not in FAMILIES:
        raise ValueError(f"unknown synthetic family {family!r}; known: {', '.join(FAMILIES)}")
    rng = np.random.default_rng(seed)
    scale = max(min(width, height), 4)
    textured = family in ("textured", "depth_of_field")
    layers = [
        _Layer(
            "plane",
            depth=12.0,
            albedo=rng.uniform(0.35, 0.8, 3),
            texture="checker" if textured else None,
            texture_scale=max(scale / 8.0, 2.0),
            tilt=(0.0, -0.25),
            roughness=0.9,
        )
    ]
    count = 5
    for i in range(count):
        kind = "disc" if i % 2 == 0 else "rect"
        layers.append(
            _Layer(
                kind,
                depth=float(rng.uniform(3.0, 9.0)),
                albedo=rng.uniform(0.1, 0.9, 3),
                cx=float(rng.uniform(0.1, 0.9) * width),
                cy=float(rng.uniform(0.1, 0.9) * height),
                size=float(rng.uniform(0.12, 0.25) * scale),
                aspect=float(rng.uniform(0.6, 1.6)),
                texture=("stripes" if i % 2 else "checker") if textured else None,
                texture_scale=max(scale / 12.0, 1.5),
                specular=0.9 if family == "glossy" and kind == "disc" else 0.0,
                shininess=40.0,
                roughness=0.15 if family == "glossy" else 0.8,
                velocity=tuple(rng.uniform(-0.15, 0.15, 2) * scale) if family == "motion_blur" else (0.0, 0.0),
                tilt=tuple(rng.uniform(-0.4, 0.4, 2)),
            )
        )
    spec = SceneSpec(width, height, layers, motion=family == "motion_blur")
    if family == "depth_of_field":
        # focus on the front-most object; the back plane and far objects are blurred
        front = min(layers[1:], key=lambda layer: layer.depth)
        spec.focus_depth = front.depth
        spec.aperture = max(scale / 10.0, 2.0)
    spec.meta = {"family": family, "seed": seed}
    return spec


def _evaluate(scene: SceneSpec, x: np.ndarray, y: np.ndarray, lens: np.ndarray | None, t: np.ndarray | None) -> dict:
    """Noise-free buffers at continuous screen points (x, y) (pixels), lens points (unit disk), times."""
    n = x.shape[0]
    out = {
        "albedo": np.zeros((n, 3)),
        "normal": np.zeros((n, 3)),
        "depth": np.zeros((n, 1)),
        "position": np.zeros((n, 3)),
        "roughness": np.zeros((n, 1)),
        "diffuse": np.zeros((n, 3)),
        "specular": np.zeros((n, 3)),
        "motion": np.zeros((n, 2)),
    }
    remaining = np.arange(n)  # indices of points that no layer in front has hit yet
    for layer in sorted(scene.layers, key=lambda layer: layer.depth):
        if remaining.size == 0:
            break
        xs, ys = x[remaining], y[remaining]
        if lens is not None and scene.aperture > 0:
            coc = scene.aperture * abs(layer.depth - scene.focus_depth) / layer.depth
            xs = xs + coc * lens[remaining, 0]
            ys = ys + coc * lens[remaining, 1]
        if t is not None:
            xs = xs - layer.velocity[0] * (t[remaining] - 0.5)
            ys = ys - layer.velocity[1] * (t[remaining] - 0.5)
        dx, dy = xs - layer.cx, ys - layer.cy
        if layer.kind == "plane":
            covers = np.ones(xs.shape[0], dtype=bool)
        elif layer.kind == "disc":
            u, v = dx / (layer.size * layer.aspect), dy / layer.size
            covers = u * u + v * v < 1.0
        else:
            covers = (np.abs(dx) < layer.size * layer.aspect) & (np.abs(dy) < layer.size)
        if not covers.any():
            continue
        take = remaining[covers]
        remaining = remaining[~covers]
        xs, ys, dx, dy = xs[covers], ys[covers], dx[covers], dy[covers]
        m = take.shape[0]
        tx, ty = layer.tilt
        flat = np.array([tx, ty, 1.0]) / np.linalg.norm([tx, ty, 1.0])
        if layer.kind == "plane":
            normal = np.broadcast_to(flat, (m, 3))
            depth = layer.depth + 4.0 * (ys / max(scene.height, 1) - 0.5)
        elif layer.kind == "disc":
            u, v = dx / (layer.size * layer.aspect), dy / layer.size
            nz = np.sqrt(np.clip(1.0 - u * u - v * v, 0.0, 1.0))
            normal = np.stack([u, v, nz + 1e-3], axis=1)
            normal /= np.linalg.norm(normal, axis=1, keepdims=True)
            depth = layer.depth - 0.5 * nz
        else:
            normal = np.broadcast_to(flat, (m, 3))
            depth = layer.depth + 0.3 * (tx * dx + ty * dy) / max(layer.size, 1.0)
        albedo = np.broadcast_to(layer.albedo, (m, 3))
        if layer.texture == "checker":
            s = layer.texture_scale
            check = (np.floor(xs / s) + np.floor(ys / s)) % 2
            albedo = albedo * (0.3 + 0.7 * check)[:, None]
        elif layer.texture == "stripes":
            s = layer.texture_scale
            albedo = albedo * (0.55 + 0.45 * np.sin(2 * np.pi * (xs + 0.5 * ys) / (2 * s)))[:, None]
        n_dot_l = np.clip(normal @ _LIGHT, 0.0, None)
        shade = (0.15 + 0.85 * n_dot_l) * scene.exposure
        # a soft light falloff so that irradiance varies smoothly over the frame
        fx, fy = xs / max(scene.width, 1) - 0.3, ys / max(scene.height, 1) - 0.3
        shade = shade * (0.6 + 0.4 * np.exp(-(fx * fx + fy * fy)))
        out["diffuse"][take] = albedo * shade[:, None]
        if layer.specular > 0:
            n_dot_h = np.clip(normal @ _HALF, 0.0, None)
            out["specular"][take] = (layer.specular * n_dot_h**layer.shininess * scene.exposure * 4.0)[:, None]
        width = max(scene.width, 1)
        out["position"][take] = np.stack(
            [(xs - scene.width / 2) * depth / width, (ys - scene.height / 2) * depth / width, depth], axis=1
        )
        out["albedo"][take] = albedo
        out["normal"][take] = normal
        out["depth"][take, 0] = depth
        out["roughness"][take] = layer.roughness
        out["motion"][take] = -np.array(layer.velocity)
    return out


def _halton(count: int, base: int) -> np.ndarray:
    result = np.zeros(count)
    for i in range(count):
        f, r, k = 1.0, 0.0, i + 1
        while k > 0:
            f /= base
            r += f * (k % base)
            k //= base
        result[i] = r
    return result


def _disk(u: np.ndarray) -> np.ndarray:
    """[0,1)² → the unit disk with the renderer's concentric map (so lens samples mean the same)."""
    return square_to_disk_concentric(u)


def render(
    scene: SceneSpec,
    spp: int = 4,
    seed: int = 0,
    *,
    samples: bool = True,
    reference_samples: int = 16,
    index: int = 0,
    offset: tuple[float, float] = (0.0, 0.0),
) -> Frame:
    """Render ``scene`` at ``spp`` samples per pixel into a Frame with variances, samples and reference.

    ``offset`` moves the camera by that many pixels (for sequences).
    """
    if spp < 1:
        raise ValueError("spp must be at least 1")
    h, w = scene.height, scene.width
    rng = np.random.default_rng(seed)
    grid_y, grid_x = np.meshgrid(np.arange(h, dtype=np.float64), np.arange(w, dtype=np.float64), indexing="ij")
    dof = scene.aperture > 0
    motion = scene.motion

    # ---- noisy samples
    pixel = rng.random((spp, h, w, 2))
    lens = rng.random((spp, h, w, 2)) if dof else None
    time = rng.random((spp, h, w, 1)) if motion else None
    x = (grid_x[None] + pixel[..., 0] + offset[0]).reshape(-1)
    y = (grid_y[None] + pixel[..., 1] + offset[1]).reshape(-1)
    values = _evaluate(scene, x, y, _disk(lens).reshape(-1, 2) if dof else None, time.reshape(-1) if motion else None)
    per_sample = {name: value.reshape(spp, h, w, -1) for name, value in values.items()}
    g_d = rng.gamma(scene.diffuse_shape, 1.0 / scene.diffuse_shape, (spp, h, w, 1))
    g_s = rng.gamma(scene.specular_shape, 1.0 / scene.specular_shape, (spp, h, w, 1))
    per_sample["diffuse"] = per_sample["diffuse"] * g_d
    per_sample["specular"] = per_sample["specular"] * g_s
    per_sample["color"] = per_sample["diffuse"] + per_sample["specular"]

    buffers: dict[str, np.ndarray] = {}
    for name in ("color", "diffuse", "specular", "albedo", "normal", "depth", "position", "roughness", "motion"):
        data = per_sample[name]
        buffers[name] = data.mean(axis=0).astype(np.float32)
        if name != "motion":
            var = data.var(axis=0, ddof=1) / spp if spp > 1 else np.zeros_like(data[0])
            buffers[f"{name}_var"] = var.astype(np.float32)
    normal = buffers["normal"]
    norm = np.linalg.norm(normal, axis=-1, keepdims=True)
    buffers["normal"] = np.where(norm > 1e-6, normal / np.maximum(norm, 1e-6), normal).astype(np.float32)

    sample_data = None
    if samples:
        sample_data = {
            name: per_sample[name].astype(np.float32)
            for name in ("color", "diffuse", "specular", "albedo", "normal", "depth", "position", "roughness")
        }
        sample_data["pixel"] = pixel.astype(np.float32)
        if dof:
            sample_data["lens"] = lens.astype(np.float32)
        if motion:
            sample_data["time"] = time.astype(np.float32)
        # the uniform numbers that drew the noise (g = Gamma quantile of u), as a renderer's bounce
        # random numbers drive its path noise: U the diffuse factor's, V the specular factor's
        sample_data["bounce"] = np.concatenate(
            [
                gamma_distribution.cdf(g_d, scene.diffuse_shape, scale=1.0 / scene.diffuse_shape),
                gamma_distribution.cdf(g_s, scene.specular_shape, scale=1.0 / scene.specular_shape),
            ],
            axis=-1,
        ).astype(np.float32)

    # ---- reference: noise-free integrand over rotated Halton points
    n_ref = max(int(reference_samples), 1)
    points = np.stack([_halton(n_ref, b) for b in (2, 3, 5, 7, 11)], axis=1)  # n_ref × 5
    shift = np.random.default_rng(seed + 7919).random((h, w, 5))
    pts = (points[:, None, None, :] + shift[None]) % 1.0  # n_ref × h × w × 5
    rx = (grid_x[None] + pts[..., 0] + offset[0]).reshape(-1)
    ry = (grid_y[None] + pts[..., 1] + offset[1]).reshape(-1)
    ref_values = _evaluate(
        scene, rx, ry, _disk(pts[..., 2:4]).reshape(-1, 2) if dof else None, pts[..., 4].reshape(-1) if motion else None
    )
    reference = (ref_values["diffuse"] + ref_values["specular"]).reshape(n_ref, h, w, 3).mean(axis=0)

    meta = dict(scene.meta)
    meta.update(
        synthetic=True,
        diffuse_noise_shape=scene.diffuse_shape,
        specular_noise_shape=scene.specular_shape,
        aperture=scene.aperture,
        focus_depth=scene.focus_depth,
    )
    return Frame(
        buffers=buffers,
        spp=spp,
        scene=str(scene.meta.get("family", "synthetic")),
        index=index,
        reference=reference.astype(np.float32),
        samples=sample_data,
        meta=meta,
    )


def synthetic_frame(
    family: str = "shapes",
    width: int = 64,
    height: int = 64,
    spp: int = 4,
    seed: int = 0,
    *,
    samples: bool = True,
    reference_samples: int = 16,
) -> Frame:
    """One noisy frame of a random scene of ``family`` (see :data:`FAMILIES`)."""
    return render(
        make_scene(family, width, height, seed), spp, seed + 1, samples=samples, reference_samples=reference_samples
    )


def synthetic_sequence(
    family: str = "shapes",
    width: int = 64,
    height: int = 64,
    spp: int = 4,
    frames: int = 3,
    seed: int = 0,
    *,
    samples: bool = False,
    pan: tuple[float, float] = (1.5, 0.5),
) -> Sequence:
    """``frames`` frames of one scene with the camera panning by ``pan`` pixels a frame."""
    scene = make_scene(family, width, height, seed)
    out = []
    for i in range(frames):
        frame = render(scene, spp, seed + 101 * (i + 1), samples=samples, index=i, offset=(pan[0] * i, pan[1] * i))
        if i > 0:
            frame.buffers["motion"] = np.broadcast_to(
                np.array([pan[0], pan[1]], np.float32), frame.color.shape[:2] + (2,)
            ).copy()
        out.append(frame)
    return Sequence(scene=out[0].scene, spp=spp, frames=out)
