"""The typed parts of a :class:`~denoisebench.generator.contract.translated_scene.TranslatedScene`.

Plain, picklable data in Mitsuba world space (Y-up, meters): frozen, slotted dataclasses whose
optional parts are ``None`` (or empty) when absent. ``generator.usd`` builds them, ``generator.render``
turns them into Mitsuba objects; Ray ships them between processes, so they hold only NumPy arrays,
numbers, strings and tuples.

Pitfalls:

* Frozen is shallow: the arrays inside a record are shared, never written to. A step that changes a
  record (binding a material, attaching per-frame vertices) makes a new one with
  :func:`dataclasses.replace`.
* Records compare by identity (``eq=False``): they hold arrays, whose ``==`` is elementwise.
* ``kind`` is a class attribute (``"mesh"``, ``"sphere"``, ``"curves"``; an emitter's is Mitsuba's plugin
  name), not a field: it names the class, for counts and messages; code branches with ``isinstance``.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import ClassVar

import numpy as np

Vector3 = tuple[float, float, float]


@dataclass(frozen=True, slots=True, kw_only=True, eq=False)
class AreaEmitter:
    """A shape's area light: constant RGB ``radiance`` over its surface (Mitsuba's ``area``)."""

    radiance: Vector3


@dataclass(frozen=True, slots=True, kw_only=True, eq=False)
class MediumRecord:
    """The participating medium inside a boundary shape (generator/usd/media.py documents the encoding).

    ``kind`` is ``"homogeneous"`` or ``"heterogeneous"``; ``sigma_t`` is the extinction per meter,
    ``albedo`` the single-scattering albedo, ``g`` the Henyey-Greenstein anisotropy (0: isotropic).
    ``null_boundary``: the boundary itself is invisible (fog, smoke) unless a material is bound.
    A heterogeneous medium also holds ``density`` (Z×Y×X float32, multiplying ``sigma_t``) and
    ``grid_to_world`` (4×4: the unit cube of the grid to Mitsuba world).
    """

    kind: str
    sigma_t: Vector3
    albedo: Vector3
    g: float
    null_boundary: bool
    density: np.ndarray | None = None
    grid_to_world: np.ndarray | None = None


@dataclass(frozen=True, slots=True, kw_only=True, eq=False)
class ShutterMotion:
    """The poses of a rigid shape that moves while the shutter is open (object motion blur).

    ``times``: K key times in frames (uniform, ``SHUTTER_SUBSTEPS`` per frame, covering every frame's
    shutter); ``to_world``: K×4×4 world-from-object poses at those times; ``from_record``: 4×4
    object-from-record matrix (the inverse of the pose the record's positions are baked at)."""

    times: np.ndarray
    to_world: np.ndarray
    from_record: np.ndarray


@dataclass(frozen=True, slots=True, kw_only=True, eq=False)
class _Shape:
    """What every shape record has: its prim ``name``, its ``bsdf`` id (a key of the scene's ``bsdfs``;
    None for a light's own geometry, rendered black), and the optional parts a gprim or light gives it:
    an area ``emitter``, the UsdLux type when it is a ``light``'s geometry, and the ``medium`` it bounds."""

    name: str
    bsdf: str | None = None
    emitter: AreaEmitter | None = None
    light: str | None = None
    medium: MediumRecord | None = None


@dataclass(frozen=True, slots=True, kw_only=True, eq=False)
class MeshShape(_Shape):
    """A triangle mesh: float32 N×3 ``positions`` (the first frame's), uint32 M×3 ``faces``, optional
    float32 ``normals`` (N×3) and ``uvs`` (N×2, v pointing down the image as Mitsuba's do).

    A mesh that moves between frames holds ``frame_positions`` (F×N×3, and ``frame_normals`` when it has
    normals); a rigid one that moves while the shutter is open also holds ``shutter_motion``. Its
    ``positions`` stay the first frame's, so that renderers without motion still work."""

    kind: ClassVar[str] = "mesh"
    positions: np.ndarray
    faces: np.ndarray
    normals: np.ndarray | None = None
    uvs: np.ndarray | None = None
    frame_positions: np.ndarray | None = None
    frame_normals: np.ndarray | None = None
    shutter_motion: ShutterMotion | None = None


@dataclass(frozen=True, slots=True, kw_only=True, eq=False)
class SphereShape(_Shape):
    """An analytic sphere (uniformly scaled, never moving: a moving sphere is tessellated into a mesh)."""

    kind: ClassVar[str] = "sphere"
    center: Vector3
    radius: float


@dataclass(frozen=True, slots=True, kw_only=True, eq=False)
class CurvesShape(_Shape):
    """Curves (generator/usd/curves.py): ``basis`` ``"bspline"`` or ``"linear"``, ``points`` M×4 float32
    (x, y, z, radius), ``counts`` the control points of each curve (int64)."""

    kind: ClassVar[str] = "curves"
    basis: str
    points: np.ndarray
    counts: np.ndarray


ShapeRecord = MeshShape | SphereShape | CurvesShape


@dataclass(frozen=True, slots=True, kw_only=True, eq=False)
class PointEmitter:
    """A point light: ``position`` and RGB ``intensity`` (W/sr); ``prim`` names the light it came from."""

    kind: ClassVar[str] = "point"
    prim: str
    position: Vector3
    intensity: Vector3


@dataclass(frozen=True, slots=True, kw_only=True, eq=False)
class SpotEmitter:
    """A spot light shining along ``to_world``'s +Z (4×4, orthonormal, at the light's position)."""

    kind: ClassVar[str] = "spot"
    prim: str
    to_world: np.ndarray
    intensity: Vector3
    cutoff_angle: float
    beam_width: float


@dataclass(frozen=True, slots=True, kw_only=True, eq=False)
class DirectionalEmitter:
    """A distant light travelling along ``direction`` (unit) with RGB ``irradiance``."""

    kind: ClassVar[str] = "directional"
    prim: str
    direction: Vector3
    irradiance: Vector3


@dataclass(frozen=True, slots=True, kw_only=True, eq=False)
class EnvmapEmitter:
    """An environment image: ``data`` H×W×3 float32 (latitude-longitude), ``scale``, and the 3×3
    ``rotation`` that orients it."""

    kind: ClassVar[str] = "envmap"
    prim: str
    data: np.ndarray
    scale: float
    rotation: np.ndarray


@dataclass(frozen=True, slots=True, kw_only=True, eq=False)
class ConstantEmitter:
    """A uniform environment of RGB ``radiance``."""

    kind: ClassVar[str] = "constant"
    prim: str
    radiance: Vector3


EmitterRecord = PointEmitter | SpotEmitter | DirectionalEmitter | EnvmapEmitter | ConstantEmitter


@dataclass(frozen=True, slots=True, kw_only=True, eq=False)
class InstanceGroup:
    """Static instances of one PointInstancer prototype (generator/usd/instancers.py): its ``shapes``
    in prototype space, stored once, placed by each of ``to_world``'s K×4×4 world-from-prototype poses."""

    name: str
    shapes: tuple[ShapeRecord, ...]
    to_world: np.ndarray


@dataclass(frozen=True, slots=True, kw_only=True, eq=False)
class MitsubaXmlSource:
    """A scene whose shapes live in a Mitsuba XML file (generator/mitsuba_xml.py): its ``path``, and
    ``transport_origin``, which of its integrators restricts transport ("" when none does)."""

    path: str
    transport_origin: str = ""
