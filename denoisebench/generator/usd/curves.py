"""UsdGeom.BasisCurves → Mitsuba ``bsplinecurve`` / ``linearcurve`` records (plain data, world space).

What a curves prim means here (USD's BasisCurves schema):

* ``type = linear`` → ``linearcurve`` (polyline segments); ``type = cubic`` → ``bsplinecurve`` (Mitsuba's
  uniform cubic B-spline, the same curve USD's ``bspline`` basis describes). The other cubic bases
  are converted exactly: each ``bezier`` segment (4 points, vstep 3) and each ``catmullRom`` segment
  (vstep 1) becomes its own 4-point B-spline with control points ``Q = M_bspline⁻¹ · M_basis · P``
  (the same cubic polynomial), radii converted alike.
* ``wrap``: ``periodic`` curves repeat their first points (closing the loop); ``pinned`` B-spline and
  Catmull-Rom curves get USD's phantom end points (``2·P0 − P1``, ``2·Pn − Pn−1``) so that they reach
  their ends; Bézier curves always do.
* ``widths`` (constant, uniform, varying or vertex interpolation; default 0.01 stage units, with
  a warning) → radius = width / 2, scaled by the transform's mean axis scale. Missing widths use
  the default.
* Time-sampled points or transforms: the first frame's pose (warning): curves do not move.

The record: a :class:`~denoisebench.generator.contract.scene_parts.CurvesShape` (``basis``
``"bspline"`` or ``"linear"``, ``points`` M×4 float32 (x, y, z, radius), ``counts`` control points per
curve, int64). The renderer writes Mitsuba's
curve text file (one ``x y z r`` line per point, a blank line between curves) and loads it
(render/scene.py).

Materials: a curve takes its bound material like any gprim; a ``denoisebench_hair`` surface
(materials.py) becomes Mitsuba's ``hair`` BSDF (Chiang et al. 2016), anything else the principled
BSDF (not wrapped in ``twosided``: a curve has no back side).
"""

from __future__ import annotations

import numpy as np

from denoisebench.generator.contract.scene_parts import CurvesShape
from denoisebench.generator.usd.stage import check_finite

# Lazy imports: pxr, inside the functions that use it (generator/usd/__init__.py says why).

DEFAULT_WIDTH = 0.01

_BSPLINE = np.array([[1, 4, 1, 0], [-3, 0, 3, 0], [3, -6, 3, 0], [-1, 3, -3, 1]], dtype=np.float64) / 6.0
_BASES = {
    "bezier": np.array([[1, 0, 0, 0], [-3, 3, 0, 0], [3, -6, 3, 0], [-1, 3, -3, 1]], dtype=np.float64),
    "catmullRom": np.array([[0, 2, 0, 0], [-1, 0, 1, 0], [2, -5, 4, -1], [-1, 3, -3, 1]], dtype=np.float64) / 2.0,
}
#: control points of basis X → B-spline control points of the same cubic
TO_BSPLINE = {name: np.linalg.solve(_BSPLINE, matrix) for name, matrix in _BASES.items()}


def _per_vertex_widths(
    widths, interpolation: str, counts: np.ndarray, total: int, kind: str, basis: str, path, warnings
):
    """Widths → one width per control point."""
    if widths is None or len(widths) == 0:
        warnings.append(f"{path}: no widths; {DEFAULT_WIDTH:g} stage units used")
        return np.full(total, DEFAULT_WIDTH)
    widths = np.asarray(widths, dtype=np.float64).reshape(-1)
    if interpolation == "constant" or len(widths) == 1:
        return np.full(total, widths[0])
    if interpolation == "uniform" and len(widths) >= len(counts):
        return np.repeat(widths[: len(counts)], counts)
    if len(widths) >= total:  # vertex
        return widths[:total]
    if interpolation == "varying":
        # One width per segment end: spread over each curve's points linearly.
        out, start = [], 0
        varying = _varying_counts(counts, kind, basis)
        for count, n in zip(counts, varying):
            values = widths[start : start + n]
            start += n
            if len(values) < 2:
                out.append(np.full(count, values[0] if len(values) else DEFAULT_WIDTH))
            else:
                out.append(np.interp(np.linspace(0, 1, count), np.linspace(0, 1, len(values)), values))
        if start <= len(widths):
            return np.concatenate(out)
    warnings.append(f"{path}: {len(widths)} widths do not fit '{interpolation}'; the first width used")
    return np.full(total, widths[0])


def _varying_counts(counts, kind: str, basis: str) -> list[int]:
    """Varying values per curve: one per segment end (nonperiodic): linear c, Bézier (c − 1)/3 + 1,
    B-spline and Catmull-Rom c − 2."""
    if kind == "linear":
        return [int(c) for c in counts]
    if basis == "bezier":
        return [max((int(c) - 1) // 3 + 1, 2) for c in counts]
    return [max(int(c) - 2, 2) for c in counts]


def _cubic_segments(points: np.ndarray, basis: str, wrap: str) -> list[np.ndarray]:
    """One curve's control points (N×4) → B-spline control-point runs (each ≥ 4 points)."""
    if basis == "bspline":
        if wrap == "periodic":
            points = np.concatenate([points, points[:3]])
        elif wrap == "pinned":
            points = np.concatenate([2 * points[:1] - points[1:2], points, 2 * points[-1:] - points[-2:-1]])
        return [points] if len(points) >= 4 else []
    matrix = TO_BSPLINE[basis]
    if basis == "bezier":
        if wrap == "periodic":
            points = np.concatenate([points, points[:1]])
        starts = range(0, len(points) - 3, 3)
    else:  # catmullRom
        if wrap == "periodic":
            points = np.concatenate([points, points[:3]])
        elif wrap == "pinned":
            points = np.concatenate([2 * points[:1] - points[1:2], points, 2 * points[-1:] - points[-2:-1]])
        starts = range(0, len(points) - 3)
    return [matrix @ points[s : s + 4] for s in starts]


def read_curves(prim, to_world: np.ndarray, warnings: list[str], time: float = 0.0) -> CurvesShape | None:
    """A BasisCurves prim → a curves record (see the module docstring), or None (warning)."""
    from pxr import UsdGeom

    curves = UsdGeom.BasisCurves(prim)
    path = str(prim.GetPath())
    points = curves.GetPointsAttr().Get(time)
    counts = curves.GetCurveVertexCountsAttr().Get(time)
    if points is None or counts is None or len(points) == 0 or len(counts) == 0:
        warnings.append(f"{path}: curves without points; skipped")
        return None
    points = check_finite(points, path, "points").reshape(-1, 3)
    counts = np.asarray(counts, dtype=np.int64)
    if counts.sum() != len(points) or np.any(counts < 0):
        warnings.append(f"{path}: curveVertexCounts sum to {int(counts.sum())} for {len(points)} points; skipped")
        return None
    kind = str(curves.GetTypeAttr().Get() or "cubic")
    basis = str(curves.GetBasisAttr().Get() or "bezier")
    wrap = str(curves.GetWrapAttr().Get() or "nonperiodic")
    if kind == "cubic" and basis not in ("bspline", "bezier", "catmullRom"):
        warnings.append(f"{path}: cubic basis '{basis}' is not supported; rendered as a B-spline")
        basis = "bspline"
    widths = curves.GetWidthsAttr().Get(time)
    if widths is not None:
        widths = check_finite(widths, path, "widths")
    radii = 0.5 * _per_vertex_widths(
        widths, str(curves.GetWidthsInterpolation()), counts, len(points), kind, basis, path, warnings
    )
    world = points @ to_world[:3, :3].T + to_world[:3, 3]
    scale = float(np.mean(np.linalg.norm(to_world[:3, :3], axis=0)))
    control = np.concatenate([world, (radii * scale)[:, None]], axis=1)
    runs: list[np.ndarray] = []
    starts = np.concatenate([[0], np.cumsum(counts)[:-1]])
    for start, count in zip(starts, counts):
        one = control[start : start + count]
        if kind == "linear":
            if wrap == "periodic" and len(one) > 2:
                one = np.concatenate([one, one[:1]])
            if len(one) >= 2:
                runs.append(one)
        else:
            runs.extend(_cubic_segments(one, basis, wrap))
    if not runs:
        warnings.append(f"{path}: no curve has enough points for its basis; skipped")
        return None
    runs = [np.concatenate([r[:, :3], np.maximum(r[:, 3:], 1e-7)], axis=1) for r in runs]  # radius stays positive
    return CurvesShape(
        name=path,
        basis="linear" if kind == "linear" else "bspline",
        points=np.ascontiguousarray(np.concatenate(runs), dtype=np.float32),
        counts=np.array([len(r) for r in runs], dtype=np.int64),
    )
