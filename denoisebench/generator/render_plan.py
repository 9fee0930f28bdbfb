"""The render plan: what a scene's effects call for, and nothing more (DESIGN.md, "Effects").

:func:`make_render_plan` is a pure function of the effects and the user's :class:`RenderOptions`.
No depth of field means a pinhole camera and no lens channels; no motion blur means no time
sampling; no indirect-lighting effect means paths stop after direct light (plus the bounces that
delta and transmissive surfaces need to show what lies behind them). The plan is written into the
dataset manifest for every scene, so a reader knows which channels exist and why.
"""

from __future__ import annotations

import json
from dataclasses import asdict, dataclass, field

from denoisebench.scenes.effects import validate_effects

#: Path depth (Mitsuba's convention: 1 = emitters only, 2 = direct light) per kind of transport.
DIRECT_ONLY_DEPTH = 2
# Mirrors and glass need a few delta bounces to show what they reflect or refract (in, out, hit, light).
DELTA_CHAIN_DEPTH = 6
DEFAULT_INDIRECT_DEPTH = 8


@dataclass(frozen=True)
class RenderOptions:
    """User choices that shape a plan.

    Attributes:
        max_depth: path depth to use instead of the one the effects imply (None: derive it).
        indirect_depth: depth for scenes with the ``indirect`` effect.
        per_sample: write per-sample data (features and random parameters, one EXR part per sample).
        aperture_scale: multiplies the lens radius; ignored without depth of field.
        shutter_scale: multiplies the shutter interval; ignored without motion blur.
        rr_depth: depth at which Russian roulette starts.
    """

    max_depth: int | None = None
    indirect_depth: int = DEFAULT_INDIRECT_DEPTH
    per_sample: bool = False
    aperture_scale: float = 1.0
    shutter_scale: float = 1.0
    rr_depth: int = 5

    def __post_init__(self) -> None:
        if self.max_depth is not None and self.max_depth < 1:
            raise ValueError(f"max_depth must be >= 1 (got {self.max_depth})")
        if self.indirect_depth < DIRECT_ONLY_DEPTH:
            raise ValueError(f"indirect_depth must be >= {DIRECT_ONLY_DEPTH} (got {self.indirect_depth})")
        if self.aperture_scale < 0 or self.shutter_scale < 0:
            raise ValueError("aperture_scale and shutter_scale must be >= 0")


@dataclass(frozen=True)
class RenderPlan:
    """Everything the renderer needs to know about *what* to simulate for one scene.

    Attributes:
        effects: the scene's effects (vocabulary order).
        camera_model: ``"pinhole"`` or ``"thin_lens"``.
        time_sampling: sample a time per ray within the shutter (camera motion blur).
        max_depth: maximum path depth (Mitsuba's convention).
        rr_depth: Russian roulette start depth.
        lobe_split: render diffuse and specular separately (the scene has non-diffuse lobes);
            without it the specular buffer is identically zero and diffuse equals color.
        random_parameters: per-sample random parameter channels: ``pixel`` always, ``lens`` with
            depth of field, ``time`` with motion blur.
        features: feature buffers written for every frame.
        per_sample: per-sample data is written.
        aperture_scale, shutter_scale: the user's lens and shutter multipliers, already reset to
            1.0 when the scene lacks the effect (so the option cannot change such a scene).
        pixel_filter: ``"box"`` (one pixel): neighbouring pixels get independent noise.
    """

    effects: tuple[str, ...]
    camera_model: str
    time_sampling: bool
    max_depth: int
    rr_depth: int
    lobe_split: bool
    random_parameters: tuple[str, ...]
    features: tuple[str, ...]
    per_sample: bool
    aperture_scale: float = 1.0
    shutter_scale: float = 1.0
    pixel_filter: str = "box"
    notes: tuple[str, ...] = field(default_factory=tuple)

    def to_json(self) -> str:
        return json.dumps(self.to_dict(), indent=2, sort_keys=True)

    def to_dict(self) -> dict:
        out = asdict(self)
        for key, value in out.items():
            if isinstance(value, tuple):
                out[key] = list(value)
        return out

    @classmethod
    def from_dict(cls, data: dict) -> "RenderPlan":
        fields = {k: tuple(v) if isinstance(v, list) else v for k, v in data.items()}
        return cls(**fields)


def make_render_plan(effects, options: RenderOptions | None = None) -> RenderPlan:
    """Derive the render plan of a scene from its effects and the user's options (pure)."""
    options = options or RenderOptions()
    effects = validate_effects(effects)
    present = set(effects)
    notes = []

    depth_of_field = "depth_of_field" in present
    motion_blur = "motion_blur" in present
    if options.max_depth is not None:
        max_depth = options.max_depth
        notes.append(f"max_depth {max_depth} set by the user")
    elif "indirect" in present:
        max_depth = options.indirect_depth
    elif present & {"specular", "transmission"}:
        max_depth = DELTA_CHAIN_DEPTH
        notes.append("no indirect effect: paths end after direct light, except through delta/transmissive chains")
    else:
        max_depth = DIRECT_ONLY_DEPTH
        notes.append("no indirect effect: direct lighting only")

    random_parameters = ("pixel",) + (("lens",) if depth_of_field else ()) + (("time",) if motion_blur else ())
    features = ("albedo", "normal", "depth", "position", "roughness", "motion")
    return RenderPlan(
        effects=effects,
        camera_model="thin_lens" if depth_of_field else "pinhole",
        time_sampling=motion_blur,
        max_depth=max_depth,
        rr_depth=options.rr_depth,
        lobe_split=bool(present & {"glossy", "specular", "transmission"}),
        random_parameters=random_parameters,
        features=features,
        per_sample=options.per_sample,
        aperture_scale=options.aperture_scale if depth_of_field else 1.0,
        shutter_scale=options.shutter_scale if motion_blur else 1.0,
        notes=tuple(notes),
    )
