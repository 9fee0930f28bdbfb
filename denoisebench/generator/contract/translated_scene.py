"""What the USD→Mitsuba translator hands the renderer."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from denoisebench.generator.contract.camera_track import CameraTrack
from denoisebench.generator.contract.scene_parts import (
    EmitterRecord,
    InstanceGroup,
    MeshShape,
    MitsubaXmlSource,
    ShapeRecord,
)
from denoisebench.scenes.effects import DECLARED_ONLY, validate_effects

#: Pose keys per frame of a shape that moves within the shutter (``ShutterMotion.times``).
SHUTTER_SUBSTEPS = 4


def shutter_keys(frames: int, shutter_open: float, shutter_close: float) -> np.ndarray:
    """Key times (frames) covering every frame's shutter: ``[min(0, open), frames - 1 + max(0, close)]``
    every ``1 / SHUTTER_SUBSTEPS`` frame (at least two keys)."""
    lo = min(0.0, float(shutter_open))
    hi = float(frames - 1) + max(0.0, float(shutter_close))
    count = max(2, int(np.ceil((hi - lo) * SHUTTER_SUBSTEPS - 1e-9)) + 1)
    return lo + np.arange(count, dtype=np.float64) / SHUTTER_SUBSTEPS


@dataclass(slots=True)
class TranslatedScene:
    """A stage made ready for Mitsuba.

    Its scene content is typed records in Mitsuba world space (Y-up, meters;
    :mod:`~denoisebench.generator.contract.scene_parts`). No sensor and no integrator: the renderer adds
    those per frame, because the camera moves and its film, filter and sampler depend on the render plan.
    ``render.scene.build_mitsuba_scene`` turns the records into a ``mi.Scene``.

    Attributes:
        camera: the camera's poses over the sequence and its lens.
        bsdfs: ``{id: Mitsuba BSDF dict}`` (plain data: texture images as arrays), the ids shapes name.
        shapes: mesh, sphere and curves records, each with its ``bsdf`` id and optional area emitter,
            medium, per-frame vertices and shutter motion.
        emitters: lights that are not shapes (point, spot, directional, environment).
        instance_groups: static PointInstancer instances (usd/instancers.py), built as one Mitsuba
            ``shapegroup`` and K ``instance`` objects each (geometry stored once).
        mitsuba_xml: set when the scene is a Mitsuba XML file (its shapes are Mitsuba's, not records).
        effects_declared: effects the stage's metadata declares (empty for a user's own USD).
        effects_inferred: effects read off the stage itself.
        warnings: one line per prim or property that was skipped or approximated (the renderer adds
            one per object Mitsuba refuses).
        source: path of the stage file, when it came from one.
        family, seed: denoisebench metadata when a scene family authored the stage.
        variants: the stage's ``/World`` customData ``denoisebench:variants`` (shape, texture and
            environment variants of a cluttered stage and its ``pool``, ``"train"`` or ``"held_out"``:
            the dataset pins held-out scenes to the test split); empty when absent.
        max_depth: the stage's own path-depth restriction, ``customLayerData["denoisebench"]["maxDepth"]``
            (None when absent: full transport; see :mod:`~denoisebench.generator.contract.render_plan`).
        materials: how each used material was translated (the manifest's ``materials``).
    """

    camera: CameraTrack
    bsdfs: dict[str, dict] = field(default_factory=dict)
    shapes: tuple[ShapeRecord, ...] = ()
    emitters: tuple[EmitterRecord, ...] = ()
    instance_groups: tuple[InstanceGroup, ...] = ()
    mitsuba_xml: MitsubaXmlSource | None = None
    effects_declared: tuple[str, ...] = ()
    effects_inferred: tuple[str, ...] = ()
    warnings: list[str] = field(default_factory=list)
    source: str = ""
    family: str = ""
    seed: int | None = None
    max_depth: int | None = None
    variants: dict = field(default_factory=dict)
    materials: list[dict] = field(default_factory=list)

    @property
    def moving(self) -> bool:
        """Some shape moves between frames (a mesh with ``frame_positions``); build its Mitsuba scene per frame."""
        return any(isinstance(s, MeshShape) and s.frame_positions is not None for s in self.shapes)

    @property
    def shutter_moving(self) -> bool:
        """Some shape moves while the shutter is open (a mesh with ``shutter_motion``): object motion blur."""
        return any(isinstance(s, MeshShape) and s.shutter_motion is not None for s in self.shapes)

    @property
    def transport_origin(self) -> str:
        """Which integrator of a Mitsuba XML scene restricts transport ("" for a stage, or when none does)."""
        return self.mitsuba_xml.transport_origin if self.mitsuba_xml is not None else ""

    def summary(self) -> dict:
        """What was translated, for ``scenes check`` and the manifest: shape counts by kind, instances,
        and each material's translation (kind, surface, document, fallbacks)."""
        kinds: dict[str, int] = {}
        for shape in self.shapes:
            kinds[shape.kind] = kinds.get(shape.kind, 0) + 1
        return {
            "shapes": kinds,
            "instances": int(sum(len(g.to_world) for g in self.instance_groups)),
            "instance_prototypes": len(self.instance_groups),
            "materials": list(self.materials),
        }

    @property
    def effects(self) -> tuple[str, ...]:
        """The effects the render plan must honour: union of declared and inferred."""
        return validate_effects(set(self.effects_declared) | set(self.effects_inferred))

    @property
    def effects_mismatch(self) -> dict[str, list[str]]:
        """Declared-but-absent and present-but-undeclared effects (empty when they agree).

        Declared-only effects (``indirect``) are never reported missing."""
        if not self.effects_declared:
            return {}
        declared = set(self.effects_declared) - set(DECLARED_ONLY)
        inferred = set(self.effects_inferred)
        out = {}
        if declared - inferred:
            out["declared_not_found"] = sorted(declared - inferred)
        if inferred - declared:
            out["found_not_declared"] = sorted(inferred - declared)
        return out
