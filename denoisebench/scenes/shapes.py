"""A procedural shape library richer than primitives, for cluttered scenes (SBMC-style training data).

Every builder returns a :class:`~denoisebench.scenes.geometry.MeshData` of quads (and pole triangles)
on a parametric (u, v) grid: smooth vertex normals (area-weighted face normals, seams welded), ``st``
in [0, 1]², centred on the origin with its lowest point at ``y = 0`` (ready to stand on a ground
plane), plus ``extra["radius"]``: the radius of its footprint circle on the ground (x, z), used for
non-overlapping placement. Resolution is modest (``segments`` ≤ 32), so 50 objects stay a few tens
of thousands of triangles.

Kinds (:data:`SHAPES`): ``superquadric`` (Barr's, exponents 0.3-3), ``torus``, ``rock``
(noise-displaced sphere), ``vase`` (a revolved random profile), ``bevelled_box`` (a superquadric
with small exponents), ``twisted_box``, ``rod`` (thin cylinder, leaning), ``leaf`` (a thin curved
blade). Pitfall: thin shapes (rods, leaves) are sub-pixel at small resolutions, on purpose.
"""

from __future__ import annotations

import numpy as np

from denoisebench.scenes.geometry import MeshData


def _signed_power(x, e):
    return np.sign(x) * np.abs(x) ** e


def _grid_mesh(points: np.ndarray, wrap_u: bool, caps: bool) -> MeshData:
    """A (rows × cols × 3) point grid → quads, with welded normals; rows run along v, columns along u.

    ``wrap_u``: the last column repeats the first (a closed loop; vertices duplicated for ``st``).
    ``caps``: the first and last rows collapse to poles (triangles there)."""
    rows, cols = points.shape[:2]
    pts = points.reshape(-1, 3)
    faces = []
    for j in range(rows - 1):
        for i in range(cols - 1):
            a = j * cols + i
            quad = [a, a + cols, a + cols + 1, a + 1]
            if caps and j == 0:
                quad = [a, a + cols, a + cols + 1]
            elif caps and j == rows - 2:
                quad = [a, a + cols, a + 1]
            faces.append(quad)
    counts = np.asarray([len(f) for f in faces])
    indices = np.asarray([i for f in faces for i in f])
    # Area-weighted face normals summed at welded positions (seams and poles share one normal).
    key = np.round(pts, 6)
    _, weld = np.unique(key, axis=0, return_inverse=True)
    weld = weld.reshape(-1)
    accum = np.zeros((weld.max() + 1, 3))
    for face in faces:
        p = pts[face]
        n = np.zeros(3)
        for k in range(len(face)):  # Newell's method: robust for quads and degenerate corners
            n += np.cross(p[k], p[(k + 1) % len(face)])
        for vertex in face:
            accum[weld[vertex]] += n
    normals = accum[weld]
    length = np.linalg.norm(normals, axis=1, keepdims=True)
    normals = np.where(length > 1e-12, normals / np.maximum(length, 1e-12), np.array([0.0, 1.0, 0.0]))
    u = np.linspace(0.0, 1.0, cols)
    v = np.linspace(0.0, 1.0, rows)
    st = np.stack(np.meshgrid(u, v), axis=-1).reshape(-1, 2)
    return MeshData(pts, counts, indices, normals, "vertex", st, "vertex")


def _finish(mesh: MeshData) -> MeshData:
    """Stand the mesh on y = 0, centred in x and z; record its footprint radius."""
    pts = mesh.points.copy()
    pts[:, 1] -= pts[:, 1].min()
    centre = 0.5 * (pts[:, [0, 2]].min(0) + pts[:, [0, 2]].max(0))
    pts[:, 0] -= centre[0]
    pts[:, 2] -= centre[1]
    out = MeshData(pts, mesh.counts, mesh.indices, mesh.normals, "vertex", mesh.st, "vertex")
    out.extra["radius"] = float(np.sqrt(np.max(pts[:, 0] ** 2 + pts[:, 2] ** 2)))
    out.extra["height"] = float(pts[:, 1].max())
    return out


def _sphere_grid(segments: int, rings: int):
    theta = np.linspace(0.0, np.pi, rings + 1)[:, None]  # from the top pole
    phi = np.linspace(0.0, 2.0 * np.pi, segments + 1)[None, :]
    return theta, phi


def superquadric(size, e1: float, e2: float, segments: int = 24, rings: int = 12) -> MeshData:
    """Barr's superellipsoid with half-extents ``size`` (x, y, z) and exponents ``e1`` (latitude), ``e2``."""
    theta, phi = _sphere_grid(segments, rings)
    eta = 0.5 * np.pi - theta  # latitude
    ce, se = _signed_power(np.cos(eta), e1), _signed_power(np.sin(eta), e1)
    cw, sw = _signed_power(np.cos(phi), e2), _signed_power(np.sin(phi), e2)
    sx, sy, sz = size
    points = np.stack(np.broadcast_arrays(sx * ce * cw, sy * se, -sz * ce * sw), axis=-1)
    return _finish(_grid_mesh(points, True, True))


def torus(major: float, minor: float, segments: int = 32, rings: int = 12, upright: bool = False) -> MeshData:
    """A torus of radii ``major`` and ``minor``, lying flat (or standing, ``upright``)."""
    v = np.linspace(2.0 * np.pi, 0.0, rings + 1)[:, None]  # this direction winds the quads outwards
    u = np.linspace(0.0, 2.0 * np.pi, segments + 1)[None, :]
    ring = major + minor * np.cos(v)
    points = np.stack(np.broadcast_arrays(ring * np.cos(u), minor * np.sin(v), -ring * np.sin(u)), axis=-1)
    if upright:
        points = points[..., [0, 2, 1]] * np.array([1.0, 1.0, -1.0])
    return _finish(_grid_mesh(points, True, False))


def rock(rng: np.random.Generator, radius: float, bumpiness: float = 0.25, segments: int = 24) -> MeshData:
    """A sphere displaced along its normal by a sum of random low-frequency waves (a blob or rock)."""
    rings = segments // 2
    theta, phi = _sphere_grid(segments, rings)
    d = np.stack(np.broadcast_arrays(np.sin(theta) * np.cos(phi), np.cos(theta), -np.sin(theta) * np.sin(phi)), -1)
    displacement = np.zeros(d.shape[:2])
    for octave in range(4):
        for _ in range(3):
            axis = rng.normal(size=3)
            axis /= np.linalg.norm(axis)
            frequency = (1.5 + 1.5 * rng.random()) * 2**octave
            displacement += np.sin(frequency * (d @ axis) + rng.uniform(0, 2 * np.pi)) * 0.5**octave
    displacement *= bumpiness / 3.0
    squash = np.array([1.0, rng.uniform(0.5, 1.0), rng.uniform(0.7, 1.0)])
    points = d * (radius * (1.0 + displacement))[..., None] * squash
    return _finish(_grid_mesh(points, True, True))


def vase(rng: np.random.Generator, height: float, radius: float, segments: int = 24, rows: int = 16) -> MeshData:
    """A surface of revolution of a random smooth profile (a vase or bottle), closed at both ends."""
    knots = rng.uniform(0.35, 1.0, size=5) * radius
    t = np.linspace(0.0, 1.0, rows)
    profile = np.interp(t, np.linspace(0.0, 1.0, 5), knots)
    profile = np.convolve(np.pad(profile, 2, mode="edge"), np.ones(5) / 5.0, mode="valid")
    profile = np.concatenate([[0.0], profile, [0.0]])  # poles: base and lid
    y = np.concatenate([[0.0], t * height, [height]])[::-1]
    profile = profile[::-1]
    u = np.linspace(0.0, 2.0 * np.pi, segments + 1)[None, :]
    points = np.stack(np.broadcast_arrays(profile[:, None] * np.cos(u), y[:, None], -profile[:, None] * np.sin(u)), -1)
    return _finish(_grid_mesh(points, True, True))


def bevelled_box(size, bevel: float = 0.15, segments: int = 24) -> MeshData:
    """A box with rounded edges: a superquadric with small exponents (``bevel`` in (0, 1))."""
    return superquadric(size, bevel, bevel, segments, segments // 2)


def twisted_box(size, twist_deg: float, bevel: float = 0.1, segments: int = 16) -> MeshData:
    """A bevelled box twisted about its vertical axis by ``twist_deg`` from bottom to top."""
    base = superquadric(size, bevel, bevel, segments, 2 * segments)
    pts = base.points.copy()
    h = pts[:, 1] / max(pts[:, 1].max(), 1e-12)
    angle = np.deg2rad(twist_deg) * (h - 0.5)
    c, s = np.cos(angle), np.sin(angle)
    x, z = pts[:, 0] * c - pts[:, 2] * s, pts[:, 0] * s + pts[:, 2] * c
    pts[:, 0], pts[:, 2] = x, z
    rows, cols = 2 * segments + 1, segments + 1
    return _finish(_grid_mesh(pts.reshape(rows, cols, 3), True, True))


def rod(length: float, radius: float, lean_deg: float, segments: int = 8) -> MeshData:
    """A thin capped cylinder of ``length`` leaning ``lean_deg`` from vertical (a stick, a wire)."""
    v = np.array([0.0, 0.0, 1.0, 1.0])[:, None]
    r = np.array([0.0, radius, radius, 0.0])[:, None]
    u = np.linspace(0.0, 2.0 * np.pi, segments + 1)[None, :]
    points = np.stack(np.broadcast_arrays(r * np.cos(u), v * length, -r * np.sin(u)), -1)[::-1]
    lean = np.deg2rad(lean_deg)
    c, s = np.cos(lean), np.sin(lean)
    x, y = points[..., 0] * c - points[..., 1] * s, points[..., 0] * s + points[..., 1] * c
    points = np.stack([x, y, points[..., 2]], -1)
    return _finish(_grid_mesh(points, True, True))


def leaf(rng: np.random.Generator, length: float, width: float, rows: int = 12, cols: int = 4) -> MeshData:
    """A thin curved blade (a leaf): an elliptic outline, bent along its length and across it."""
    t = np.linspace(0.0, 1.0, rows)[:, None]
    s = np.linspace(-1.0, 1.0, cols + 1)[None, :]
    half = 0.5 * width * np.sin(np.pi * np.clip(t, 0.0, 1.0)) ** 0.8 + 1e-4
    bend, cup = rng.uniform(0.2, 0.6), rng.uniform(0.05, 0.2)
    x = s * half
    y = length * t * np.cos(bend * t) + cup * width * s**2
    z = -length * t * np.sin(bend * t) * 0.5 + 0.0 * s
    points = np.stack(np.broadcast_arrays(x, y, z), axis=-1)
    return _finish(_grid_mesh(points, False, False))


#: Shape kinds of the library (the cluttered family splits them into train and held-out variants).
SHAPES = ("superquadric", "torus", "rock", "vase", "bevelled_box", "twisted_box", "rod", "leaf")


def make(kind: str, rng: np.random.Generator, scale: float) -> MeshData:
    """One random shape of ``kind`` about ``scale`` meters across (seeded by ``rng``)."""
    if kind == "superquadric":
        size = scale * 0.5 * rng.uniform(0.6, 1.0, 3)
        return superquadric(size, rng.uniform(0.3, 2.5), rng.uniform(0.3, 2.5))
    if kind == "torus":
        major = 0.35 * scale
        return torus(major, major * rng.uniform(0.2, 0.45), upright=bool(rng.random() < 0.3))
    if kind == "rock":
        return rock(rng, 0.5 * scale, rng.uniform(0.15, 0.35))
    if kind == "vase":
        return vase(rng, scale * rng.uniform(0.8, 1.4), 0.35 * scale)
    if kind == "bevelled_box":
        return bevelled_box(scale * 0.5 * rng.uniform(0.5, 1.0, 3), rng.uniform(0.08, 0.3))
    if kind == "twisted_box":
        size = scale * 0.5 * np.array([rng.uniform(0.3, 0.6), rng.uniform(0.8, 1.2), rng.uniform(0.3, 0.6)])
        return twisted_box(size, rng.uniform(45.0, 120.0) * rng.choice([-1.0, 1.0]))
    if kind == "rod":
        return rod(scale * rng.uniform(0.8, 1.5), scale * rng.uniform(0.01, 0.03), rng.uniform(0.0, 35.0))
    if kind == "leaf":
        return leaf(rng, scale * rng.uniform(0.6, 1.0), scale * rng.uniform(0.2, 0.4))
    raise ValueError(f"unknown shape kind {kind!r} (known: {', '.join(SHAPES)})")
