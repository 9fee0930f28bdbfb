"""Mesh builders: points, faces, normals and texture coordinates as numpy arrays.

Faces are wound counter-clockwise seen from the side their normal points to (USD's default
``rightHanded`` orientation). Flat-shaded builders give every face its own vertices, so that
per-vertex normals and texture coordinates are exact without faceVarying data; :func:`box_shared`
is the exception and uses faceVarying normals and coordinates on 8 shared corners.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np


@dataclass
class MeshData:
    points: np.ndarray  # N×3 float
    counts: np.ndarray  # F int (3 or 4 or more)
    indices: np.ndarray  # sum(counts) int
    normals: np.ndarray | None = None
    normals_interpolation: str = "vertex"  # "vertex" or "faceVarying"
    st: np.ndarray | None = None
    st_interpolation: str = "vertex"
    extra: dict = field(default_factory=dict)

    @property
    def triangles(self) -> int:
        return int(np.sum(self.counts - 2))

    def transformed(self, scale=(1.0, 1.0, 1.0), translate=(0.0, 0.0, 0.0)) -> MeshData:
        """A copy with points scaled then translated (normals rescaled for non-uniform scale)."""
        s = np.asarray(scale, dtype=np.float64)
        pts = self.points * s + np.asarray(translate, dtype=np.float64)
        nrm = None
        if self.normals is not None:
            nrm = self.normals / s
            nrm /= np.linalg.norm(nrm, axis=1, keepdims=True)
        return MeshData(pts, self.counts, self.indices, nrm, self.normals_interpolation, self.st, self.st_interpolation)


def merge(parts: list[MeshData]) -> MeshData:
    """Concatenate meshes that share the same interpolation modes (vertex data only)."""
    pts, counts, idx, nrm, st = [], [], [], [], []
    base = 0
    for p in parts:
        if p.normals_interpolation != "vertex" or p.st_interpolation != "vertex":
            raise ValueError("merge supports vertex-interpolated data only")
        pts.append(p.points)
        counts.append(p.counts)
        idx.append(p.indices + base)
        base += len(p.points)
        nrm.append(p.normals if p.normals is not None else None)
        st.append(p.st if p.st is not None else None)
    normals = np.concatenate(nrm) if all(n is not None for n in nrm) else None
    sts = np.concatenate(st) if all(s is not None for s in st) else None
    return MeshData(np.concatenate(pts), np.concatenate(counts), np.concatenate(idx), normals, "vertex", sts, "vertex")


def quad(corners, st=((0, 0), (1, 0), (1, 1), (0, 1))) -> MeshData:
    """One quad from four corners in counter-clockwise order (seen from the front)."""
    p = np.asarray(corners, dtype=np.float64)
    n = np.cross(p[1] - p[0], p[3] - p[0])
    n /= np.linalg.norm(n)
    return MeshData(
        p, np.array([4]), np.arange(4), np.repeat(n[None], 4, axis=0), "vertex", np.asarray(st, dtype=np.float64)
    )


def grid(size_u: float, size_v: float, nu: int, nv: int, axis: str = "y", st_repeat: float = 1.0) -> MeshData:
    """A flat nu×nv quad grid centered at the origin, normal along +``axis`` (x, y or z)."""
    us = np.linspace(-0.5 * size_u, 0.5 * size_u, nu + 1)
    vs = np.linspace(-0.5 * size_v, 0.5 * size_v, nv + 1)
    uu, vv = np.meshgrid(us, vs)  # rows: v
    su, sv = np.meshgrid(np.linspace(0.0, st_repeat, nu + 1), np.linspace(0.0, st_repeat, nv + 1))
    flat_u, flat_v = uu.ravel(), vv.ravel()
    zeros = np.zeros_like(flat_u)
    if axis == "y":  # u → x, v → -z so that (u, v, n) is right-handed with n = +y
        pts = np.stack([flat_u, zeros, -flat_v], axis=1)
        n = (0.0, 1.0, 0.0)
    elif axis == "z":
        pts = np.stack([flat_u, flat_v, zeros], axis=1)
        n = (0.0, 0.0, 1.0)
    elif axis == "x":  # u → -z? keep right-handed: u → y, v → z gives n = +x
        pts = np.stack([zeros, flat_u, flat_v], axis=1)
        n = (1.0, 0.0, 0.0)
    else:
        raise ValueError(f"axis must be x, y or z, got {axis!r}")
    faces = []
    for j in range(nv):
        for i in range(nu):
            a = j * (nu + 1) + i
            faces.append([a, a + 1, a + nu + 2, a + nu + 1])
    st = np.stack([su.ravel(), sv.ravel()], axis=1)
    normals = np.repeat(np.asarray(n, dtype=np.float64)[None], len(pts), axis=0)
    return MeshData(pts, np.full(len(faces), 4), np.asarray(faces).ravel(), normals, "vertex", st, "vertex")


# Unit cube faces: (normal, u axis, v axis) with u × v = normal.
_CUBE_FACES = [
    ((1, 0, 0), (0, 0, -1), (0, 1, 0)),
    ((-1, 0, 0), (0, 0, 1), (0, 1, 0)),
    ((0, 1, 0), (1, 0, 0), (0, 0, -1)),
    ((0, -1, 0), (1, 0, 0), (0, 0, 1)),
    ((0, 0, 1), (1, 0, 0), (0, 1, 0)),
    ((0, 0, -1), (-1, 0, 0), (0, 1, 0)),
]


#: Face order of :func:`box`: +X, −X, +Y, −Y, +Z, −Z.
BOX_FACES = ("+x", "-x", "+y", "-y", "+z", "-z")


def box(size=(1.0, 1.0, 1.0), center=(0.0, 0.0, 0.0), inward: bool = False, faces=BOX_FACES) -> MeshData:
    """An axis-aligned box of quads with their own vertices, faces in :data:`BOX_FACES` order.

    ``inward`` flips the faces to look inside (a room); ``faces`` keeps only the named sides.
    """
    half = 0.5 * np.asarray(size, dtype=np.float64)
    c = np.asarray(center, dtype=np.float64)
    parts = []
    for key, (n, u, v) in zip(BOX_FACES, _CUBE_FACES):
        if key not in faces:
            continue
        n, u, v = (np.asarray(x, dtype=np.float64) for x in (n, u, v))
        corners = [n - u - v, n + u - v, n + u + v, n - u + v]
        corners = [c + half * p for p in corners]
        st = ((0, 0), (1, 0), (1, 1), (0, 1))
        if inward:
            corners = corners[::-1]
            st = st[::-1]
        parts.append(quad(corners, st))
    return merge(parts)


def box_shared(size=(1.0, 1.0, 1.0)) -> MeshData:
    """A box on 8 shared corners with faceVarying normals and texture coordinates."""
    half = 0.5 * np.asarray(size, dtype=np.float64)
    corners = np.array([[x, y, z] for x in (-1, 1) for y in (-1, 1) for z in (-1, 1)], dtype=np.float64)
    idx, nrm, st = [], [], []
    for n, u, v in _CUBE_FACES:
        n, u, v = (np.asarray(x, dtype=np.float64) for x in (n, u, v))
        for du, dv, uv in ((-1, -1, (0, 0)), (1, -1, (1, 0)), (1, 1, (1, 1)), (-1, 1, (0, 1))):
            p = n + du * u + dv * v
            idx.append(int(np.argmin(np.abs(corners - p).sum(axis=1))))
            nrm.append(n)
            st.append(uv)
    return MeshData(
        corners * half,
        np.full(6, 4),
        np.asarray(idx),
        np.asarray(nrm),
        "faceVarying",
        np.asarray(st, dtype=np.float64),
        "faceVarying",
    )


def uv_sphere(radius: float, segments: int = 24, rings: int = 12, center=(0.0, 0.0, 0.0), up: str = "y") -> MeshData:
    """A UV sphere with smooth vertex normals and (u, v) = (longitude, latitude) in [0, 1]."""
    c = np.asarray(center, dtype=np.float64)
    pts, nrm, st = [], [], []
    for j in range(rings + 1):
        theta = np.pi * j / rings  # 0 at the top pole
        for i in range(segments + 1):
            phi = 2.0 * np.pi * i / segments
            d = np.array([np.sin(theta) * np.cos(phi), np.cos(theta), -np.sin(theta) * np.sin(phi)])
            if up == "z":
                d = np.array([d[0], -d[2], d[1]])
            pts.append(c + radius * d)
            nrm.append(d)
            st.append((i / segments, 1.0 - j / rings))
    faces = []
    row = segments + 1
    for j in range(rings):
        for i in range(segments):
            a = j * row + i
            # counter-clockwise seen from outside: top-left, bottom-left, bottom-right, top-right;
            # triangles at the poles, where the top (or bottom) edge collapses to a point
            if j == 0:
                faces.append([a, a + row, a + row + 1])
            elif j == rings - 1:
                faces.append([a, a + row, a + 1])
            else:
                faces.append([a, a + row, a + row + 1, a + 1])
    counts = np.asarray([len(f) for f in faces])
    indices = np.asarray([i for f in faces for i in f])
    return MeshData(
        np.asarray(pts), counts, indices, np.asarray(nrm), "vertex", np.asarray(st, dtype=np.float64), "vertex"
    )


def strip(p0, p1, width: float, side) -> MeshData:
    """A thin flat ribbon from ``p0`` to ``p1`` of ``width``, spread along ``side`` (a wire, a blade)."""
    p0, p1 = np.asarray(p0, dtype=np.float64), np.asarray(p1, dtype=np.float64)
    s = np.asarray(side, dtype=np.float64)
    s = s / np.linalg.norm(s) * 0.5 * width
    return quad([p0 - s, p0 + s, p1 + s, p1 - s])


def grass_blades(rng: np.random.Generator, count: int, area: float, height: float, up_index: int = 1) -> MeshData:
    """``count`` curved blades (two quads and a tip triangle each) scattered over an area×area patch."""
    pts, counts, idx, nrm, st = [], [], [], [], []
    base = 0
    for _ in range(count):
        x, z = rng.uniform(-0.5 * area, 0.5 * area, size=2)
        h = height * rng.uniform(0.5, 1.2)
        w = rng.uniform(0.004, 0.01)
        yaw = rng.uniform(0.0, 2.0 * np.pi)
        lean = rng.uniform(0.1, 0.5)
        side = np.array([np.cos(yaw), 0.0, np.sin(yaw)])
        bend = np.array([-np.sin(yaw), 0.0, np.cos(yaw)])
        levels = [0.0, 0.45, 0.8, 1.0]
        ring = []
        for k, t in enumerate(levels):
            centre = np.array([x, h * t, z]) + bend * lean * h * t * t
            half = 0.5 * w * (1.0 - t) if k < len(levels) - 1 else 0.0
            if k < len(levels) - 1:
                ring += [centre - side * half, centre + side * half]
            else:
                ring.append(centre)
        ring = np.asarray(ring)
        n = np.cross(side, np.array([0.0, 1.0, 0.0]))  # the winding's normal (blades are double-sided)
        if up_index == 2:
            ring = ring[:, [0, 2, 1]] * np.array([1.0, -1.0, 1.0])
            n = n[[0, 2, 1]] * np.array([1.0, -1.0, 1.0])
        pts.append(ring)
        nrm.append(np.repeat(n[None], len(ring), axis=0))
        st.append(np.array([[0, 0], [1, 0], [0, 0.45], [1, 0.45], [0, 0.8], [1, 0.8], [0.5, 1.0]]))
        counts += [4, 4, 3]
        b = base
        idx += [b + 0, b + 1, b + 3, b + 2, b + 2, b + 3, b + 5, b + 4, b + 4, b + 5, b + 6]
        base += len(ring)
    return MeshData(
        np.concatenate(pts),
        np.asarray(counts),
        np.asarray(idx),
        np.concatenate(nrm),
        "vertex",
        np.concatenate(st).astype(np.float64),
        "vertex",
    )
