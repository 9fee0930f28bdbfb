"""Participating media on USD gprims: denoisebench's documented encoding (USD has no standard for one).

A gprim (Mesh, Sphere, Cube, ...) carrying ``denoisebench:medium:type`` is a **medium boundary**: its
interior holds a participating medium, rendered by the volumetric tracer (render/volpath.py; the
``media`` effect). Attributes (custom, on the gprim):

=====================================  ===========  =====================================================
attribute                              type         meaning
=====================================  ===========  =====================================================
``denoisebench:medium:type``           token        ``homogeneous`` or ``heterogeneous``
``denoisebench:medium:sigmaT``         color3f      extinction per stage unit (default 1, 1, 1)
``denoisebench:medium:albedo``         color3f      single-scattering albedo (default 0.8, 0.8, 0.8)
``denoisebench:medium:g``              float        Henyey-Greenstein anisotropy in (-1, 1); 0: isotropic
``denoisebench:medium:density``        float[]      heterogeneous: density grid, x fastest, then y, then z;
                                                    it multiplies ``sigmaT``
``denoisebench:medium:densityDims``    int3         heterogeneous: the grid's (x, y, z) sample counts
``denoisebench:medium:boundary``       token        ``null`` (default): an invisible boundary, the bound
                                                    material is not rendered (fog, smoke); ``surface``:
                                                    the bound material is the boundary's surface (a glass
                                                    material: subsurface scattering)
=====================================  ===========  =====================================================

The attributes may instead sit on a **Material** prim: every gprim bound to it (its own binding;
GeomSubsets are not read) bounds that medium, with ``surface`` as the default boundary (the material
is the surface of, e.g., skin or jade); a gprim's own attributes win. The density grid spans the
gprim's local extent (its bounding box in its own space), so it moves and scales with the gprim. Media nest: a closed boundary inside another's medium gets that medium as its
exterior (render/media.py ``enclosing_media``), so a ray leaving smoke inside fog is in the fog again;
boundaries should not otherwise intersect. ``denoisebench.scenes.media``
authors these attributes. Bad values (a negative extinction, an albedo outside [0, 1], a
grid whose size does not match its dims) are one-line errors, never a crash.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from denoisebench.errors import UserInputError
from denoisebench.generator.contract.scene_parts import MediumRecord

PREFIX = "denoisebench:medium:"
TYPES = ("homogeneous", "heterogeneous")
BOUNDARIES = ("null", "surface")


def _get(prim, name: str, default=None):
    attr = prim.GetAttribute(PREFIX + name)
    if not attr or not attr.HasAuthoredValue():
        return default
    return attr.Get()


def _triple(value, what: str, path: str) -> list[float]:
    out = [float(v) for v in value]
    if len(out) != 3 or not all(np.isfinite(out)):
        raise UserInputError(f"{path}: {PREFIX}{what} must be three finite numbers")
    return out


def read_medium(prim, to_mitsuba: np.ndarray, local_to_world: np.ndarray, source=None) -> MediumRecord | None:
    """The medium record of gprim ``prim`` (None without ``denoisebench:medium:type``); module docstring.

    ``to_mitsuba``: stage → Mitsuba world (its scale converts the extinction per stage unit to per
    meter); ``local_to_world``: the gprim's local → Mitsuba world matrix (the grid's placement).
    ``source``: the prim holding the attributes when it is not ``prim`` (its bound material: then the
    boundary defaults to ``surface``); the grid always spans ``prim``'s extent.
    """
    holder = prim if source is None else source
    kind = _get(holder, "type")
    if kind is None:
        return None
    path = str(holder.GetPath())
    kind = str(kind)
    if kind not in TYPES:
        raise UserInputError(f"{path}: {PREFIX}type {kind!r} is not one of {', '.join(TYPES)}")
    meters = abs(float(np.linalg.det(np.asarray(to_mitsuba, dtype=np.float64)[:3, :3]))) ** (1.0 / 3.0)
    sigma_t = _triple(_get(holder, "sigmaT", (1.0, 1.0, 1.0)), "sigmaT", path)
    albedo = _triple(_get(holder, "albedo", (0.8, 0.8, 0.8)), "albedo", path)
    if min(sigma_t) < 0:
        raise UserInputError(f"{path}: {PREFIX}sigmaT must be >= 0")
    if not all(0.0 <= a <= 1.0 for a in albedo):
        raise UserInputError(f"{path}: {PREFIX}albedo must lie in [0, 1]")
    boundary = str(_get(holder, "boundary", "null" if source is None else "surface"))
    if boundary not in BOUNDARIES:
        raise UserInputError(f"{path}: {PREFIX}boundary {boundary!r} is not one of {', '.join(BOUNDARIES)}")
    g = float(_get(holder, "g", 0.0))
    if not -1.0 < g < 1.0:
        raise UserInputError(f"{path}: {PREFIX}g must lie in (-1, 1)")
    record = MediumRecord(
        kind=kind,
        sigma_t=tuple(s / max(meters, 1e-30) for s in sigma_t),
        albedo=tuple(albedo),
        g=g,
        null_boundary=boundary == "null",
    )
    if kind == "heterogeneous":
        dims = _get(holder, "densityDims")
        values = _get(holder, "density")
        if dims is None or values is None:
            raise UserInputError(f"{path}: a heterogeneous medium needs {PREFIX}density and {PREFIX}densityDims")
        nx, ny, nz = (int(v) for v in dims)
        density = np.asarray(values, dtype=np.float32)
        if min(nx, ny, nz) < 1 or density.size != nx * ny * nz:
            raise UserInputError(
                f"{path}: {PREFIX}density has {density.size} values, densityDims {nx}x{ny}x{nz} asks for {nx * ny * nz}"
            )
        if not np.all(np.isfinite(density)) or density.min() < 0:
            raise UserInputError(f"{path}: {PREFIX}density must be finite and >= 0")
        low, high = _local_extent(prim)
        grid = np.eye(4)
        grid[:3, :3] = np.diag(np.maximum(high - low, 1e-9))
        grid[:3, 3] = low
        record = replace(
            record,
            density=density.reshape(nz, ny, nx),
            grid_to_world=np.asarray(local_to_world, dtype=np.float64) @ grid,
        )
    return record


def _bound_material_prim(prim):
    """The prim of the material bound to ``prim`` (the gprim's own binding; GeomSubsets are not read), or None."""
    from pxr import UsdShade

    material, _ = UsdShade.MaterialBindingAPI(prim).ComputeBoundMaterial()
    return material.GetPrim() if material else None


def _local_extent(prim) -> tuple[np.ndarray, np.ndarray]:
    from pxr import Usd, UsdGeom

    box = UsdGeom.Imageable(prim).ComputeLocalBound(Usd.TimeCode.Default(), UsdGeom.Tokens.default_).GetRange()
    low, high = np.array(box.GetMin(), dtype=np.float64), np.array(box.GetMax(), dtype=np.float64)
    if box.IsEmpty() or not (np.all(np.isfinite(low)) and np.all(np.isfinite(high))):
        raise UserInputError(f"{prim.GetPath()}: a heterogeneous medium needs a gprim with an extent")
    return low, high


def attach_media(prim, parts: list, to_mitsuba: np.ndarray, local_to_world: np.ndarray) -> list:
    """``parts`` (``[(record, material)]`` of ``prim``) with each record given its ``medium`` when ``prim`` is a
    medium boundary: its own ``denoisebench:medium:*`` attributes, else its bound material's."""
    medium = read_medium(prim, to_mitsuba, local_to_world)
    if medium is None:
        material = _bound_material_prim(prim)
        if material is not None and _get(material, "type") is not None:
            medium = read_medium(prim, to_mitsuba, local_to_world, source=material)
    if medium is None:
        return parts
    return [(replace(record, medium=medium), material) for record, material in parts]


def refuse_volume(prim) -> None:
    """A UsdVol ``Volume``: a one-line UserInputError (rendering it without its medium would drop light).

    Its fields are files (OpenVDB ``.vdb``, Field3D) that this build does not read: the ``openvdb``
    Python module is not in the environment (Debian ships it as ``python3-openvdb``, for the system
    Python only). The error names the fields and points at the ``denoisebench:medium:*`` encoding.
    """
    from pxr import UsdVol

    fields = UsdVol.Volume(prim).GetFieldPaths()
    kinds = sorted({str(prim.GetStage().GetPrimAtPath(path).GetTypeName()) or "?" for path in fields.values()})
    try:
        import openvdb  # noqa: F401

        reason = "reading their fields is not implemented"
    except ImportError:
        reason = "the openvdb Python module is not installed (Debian: python3-openvdb)"
    listed = ", ".join(f"{name} ({kind})" for name, kind in zip(sorted(fields), kinds)) if fields else "no fields"
    raise UserInputError(
        f"{prim.GetPath()}: UsdVol volumes are not rendered ({listed}; {reason}); bind the medium to a gprim "
        f"with {PREFIX}* attributes instead (docs/scenes.md, 'Participating media')"
    )
