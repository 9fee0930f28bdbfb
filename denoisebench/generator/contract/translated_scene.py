"""What the USD→Mitsuba translator hands the renderer."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from denoisebench.generator.contract.camera_track import CameraTrack
from denoisebench.scenes.effects import DECLARED_ONLY, validate_effects

#: Pose keys per frame of a shape that moves within the shutter (``shutter_motion["times"]``).
SHUTTER_SUBSTEPS = 4


def shutter_keys(frames: int, shutter_open: float, shutter_close: float) -> np.ndarray:
    """Key times (frames) covering every frame's shutter: ``[min(0, open), frames - 1 + max(0, close)]``
    every ``1 / SHUTTER_SUBSTEPS`` frame (at least two keys)."""
    lo = min(0.0, float(shutter_open))
    hi = float(frames - 1) + max(0.0, float(shutter_close))
    count = max(2, int(np.ceil((hi - lo) * SHUTTER_SUBSTEPS - 1e-9)) + 1)
    return lo + np.arange(count, dtype=np.float64) / SHUTTER_SUBSTEPS


@dataclass
class TranslatedScene:
    """A stage made ready for Mitsuba.

    Attributes:
        scene_dict: plain, picklable data in Mitsuba world space (Y-up, meters):
            ``{"bsdfs": {id: Mitsuba BSDF dict}, "shapes": [record], "emitters": [Mitsuba emitter dict]}``
            where a shape record is a triangle mesh (``kind="mesh"``, numpy positions/faces/normals/uvs)
            or an analytic sphere, with a ``bsdf`` id and an optional area ``emitter``. No sensor and
            no integrator: the renderer adds those per frame, because the camera moves and its film,
            filter and sampler depend on the render plan. ``build_mitsuba_scene`` turns it into a
            ``mi.Scene``.
            A rigid shape that moves while the shutter is open also holds ``shutter_motion``:
            ``{"times": K key times in frames (uniform, SHUTTER_SUBSTEPS per frame, covering every frame's
            shutter), "to_world": K×4×4 world-from-object poses at those times, "from_record": 4×4
            object-from-record matrix (the inverse of the pose the record's positions are baked at)}``;
            its ``positions`` stay the first frame's, so that renderers without motion blur still work.
            Optional ``instance_groups`` (static PointInstancer instances, usd/instancers.py):
            ``[{"name", "shapes": [records in prototype space], "to_world": K×4×4 world-from-prototype}]``,
            built as one Mitsuba ``shapegroup`` and K ``instance`` objects (geometry stored once).
        camera: the camera's poses over the sequence and its lens.
        effects_declared: effects the stage's metadata declares (empty for a user's own USD).
        effects_inferred: effects read off the stage itself.
        warnings: one line per prim or property that was skipped or approximated.
        source: path of the stage file, when it came from one.
        family, seed: denoisebench metadata when a scene family authored the stage.
        variants: the stage's ``/World`` customData ``denoisebench:variants`` (shape, texture and
            environment variants of a cluttered stage and its ``pool``, ``"train"`` or ``"held_out"``:
            the dataset pins held-out scenes to the test split); empty when absent.
        max_depth: the stage's own path-depth restriction, ``customLayerData["denoisebench"]["maxDepth"]``
            (None when absent: full transport; see :mod:`~denoisebench.generator.contract.render_plan`).
    """

    scene_dict: dict
    camera: CameraTrack
    effects_declared: tuple[str, ...] = ()
    effects_inferred: tuple[str, ...] = ()
    warnings: list[str] = field(default_factory=list)
    source: str = ""
    family: str = ""
    seed: int | None = None
    max_depth: int | None = None
    variants: dict = field(default_factory=dict)
    materials: list[dict] = field(default_factory=list)  # how each used material was translated (manifest)

    @property
    def moving(self) -> bool:
        """Some shape moves between frames (its record holds ``frame_positions``: F×N×3 vertices per
        frame, and ``frame_normals`` when it has normals); build its Mitsuba scene per frame."""
        return any("frame_positions" in shape for shape in self.scene_dict["shapes"])

    @property
    def shutter_moving(self) -> bool:
        """Some shape moves while the shutter is open (a record holds ``shutter_motion``): object motion blur."""
        return any("shutter_motion" in shape for shape in self.scene_dict["shapes"])

    def summary(self) -> dict:
        """What was translated, for ``scenes check`` and the manifest: shape counts by kind, instances,
        and each material's translation (kind, surface, document, fallbacks)."""
        kinds: dict[str, int] = {}
        for shape in self.scene_dict.get("shapes", []):
            kinds[shape["kind"]] = kinds.get(shape["kind"], 0) + 1
        groups = self.scene_dict.get("instance_groups", [])
        return {
            "shapes": kinds,
            "instances": int(sum(len(g["to_world"]) for g in groups)),
            "instance_prototypes": len(groups),
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
