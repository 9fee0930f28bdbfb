"""What the USD→Mitsuba translator hands the renderer."""

from __future__ import annotations

from dataclasses import dataclass, field

from denoisebench.generator.camera_track import CameraTrack


@dataclass
class TranslatedScene:
    """A stage made ready for Mitsuba.

    Attributes:
        scene_dict: a ``mi.load_dict`` dictionary of shapes, BSDFs, emitters (Mitsuba world space:
            Y-up, meters), *without* sensor and integrator: the renderer adds those per frame,
            because the camera moves and its film, filter and sampler depend on the render plan.
        camera: the camera's poses over the sequence and its lens.
        effects_declared: effects the stage's metadata declares (empty for a user's own USD).
        effects_inferred: effects read off the stage itself.
        warnings: one line per prim or property that was skipped or approximated.
        source: path of the stage file, when it came from one.
        family, seed: denoisebench metadata when a scene family authored the stage.
    """

    scene_dict: dict
    camera: CameraTrack
    effects_declared: tuple[str, ...] = ()
    effects_inferred: tuple[str, ...] = ()
    warnings: list[str] = field(default_factory=list)
    source: str = ""
    family: str = ""
    seed: int | None = None

    @property
    def effects(self) -> tuple[str, ...]:
        """The effects the render plan must honour: union of declared and inferred."""
        from denoisebench.scenes.effects import validate_effects

        return validate_effects(set(self.effects_declared) | set(self.effects_inferred))

    @property
    def effects_mismatch(self) -> dict[str, list[str]]:
        """Declared-but-absent and present-but-undeclared effects (empty when they agree)."""
        if not self.effects_declared:
            return {}
        declared, inferred = set(self.effects_declared), set(self.effects_inferred)
        out = {}
        if declared - inferred:
            out["declared_not_found"] = sorted(declared - inferred)
        if inferred - declared:
            out["found_not_declared"] = sorted(inferred - declared)
        return out
