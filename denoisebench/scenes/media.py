"""Author a participating medium on a USD gprim: denoisebench's ``denoisebench:medium:*`` attributes.

The encoding (what each attribute means, units, the boundary rule) is documented where it is read:
``denoisebench.generator.usd.media``. This module only writes it (pxr, no Mitsuba), for the procedural
families and for users who build their own stages in Python.
"""

from __future__ import annotations

import numpy as np
from pxr import Gf, Sdf, Vt

PREFIX = "denoisebench:medium:"


def author_medium(
    gprim,
    kind: str = "homogeneous",
    sigma_t=(1.0, 1.0, 1.0),
    albedo=(0.8, 0.8, 0.8),
    g: float = 0.0,
    density: np.ndarray | None = None,
    boundary: str | None = None,
) -> None:
    """Make ``gprim`` (a UsdGeom gprim or its prim; or a UsdShade Material: every gprim bound to it) the
    boundary of a medium.

    ``density`` (heterogeneous only) is a z×y×x array over the gprim's local extent; it multiplies
    ``sigma_t`` (extinction per stage unit). ``boundary``: ``"null"`` (invisible) or ``"surface"`` (the
    bound material is the boundary's surface); None writes nothing: a gprim's default is ``null``, a
    material's ``surface``.
    """
    prim = gprim.GetPrim() if hasattr(gprim, "GetPrim") else gprim
    prim.CreateAttribute(PREFIX + "type", Sdf.ValueTypeNames.Token, custom=True).Set(kind)
    prim.CreateAttribute(PREFIX + "sigmaT", Sdf.ValueTypeNames.Color3f, custom=True).Set(
        Gf.Vec3f(*(float(v) for v in sigma_t))
    )
    prim.CreateAttribute(PREFIX + "albedo", Sdf.ValueTypeNames.Color3f, custom=True).Set(
        Gf.Vec3f(*(float(v) for v in albedo))
    )
    prim.CreateAttribute(PREFIX + "g", Sdf.ValueTypeNames.Float, custom=True).Set(float(g))
    if boundary is not None:
        prim.CreateAttribute(PREFIX + "boundary", Sdf.ValueTypeNames.Token, custom=True).Set(boundary)
    if density is not None:
        grid = np.asarray(density, dtype=np.float32)
        if grid.ndim != 3:
            raise ValueError(f"density must be a z×y×x array (got shape {grid.shape})")
        nz, ny, nx = grid.shape
        prim.CreateAttribute(PREFIX + "density", Sdf.ValueTypeNames.FloatArray, custom=True).Set(
            Vt.FloatArray([round(float(v), 5) for v in grid.reshape(-1)])
        )
        prim.CreateAttribute(PREFIX + "densityDims", Sdf.ValueTypeNames.Int3, custom=True).Set(Gf.Vec3i(nx, ny, nz))


def has_medium(prim) -> bool:
    """``prim`` carries a medium (the ``media`` effect)."""
    attr = prim.GetAttribute(PREFIX + "type")
    return bool(attr) and attr.HasAuthoredValue()
