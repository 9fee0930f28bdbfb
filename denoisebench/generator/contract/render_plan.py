"""The render plan: what a scene's effects call for, and nothing more.

docs/architecture.md, "Effects and the render plan", states the rule this module implements.

:func:`make_render_plan` is a pure function of the effects and the user's :class:`RenderOptions`.
No depth of field means a pinhole camera and no lens channels; no motion blur means no time
sampling; no non-diffuse BSDF means no lobe-split evaluation. The plan is written into the dataset
manifest for every scene, so a reader knows which channels exist and why.

**The plan prunes work, never light.** It may skip only what leaves the expected image unchanged
(the pinhole, the missing time and lens samples, the lobe split, channels that do not exist). Light
transport is complete by default: ``max_depth = -1`` (unbounded) with Russian roulette from depth
``rr_depth = 5``, exactly Mitsuba's ``path`` integrator at its defaults, whatever the scene's
effects (``indirect`` is an effect name for per-effect breakdowns only; it does not decide depth).

Transport is restricted only on purpose, and the plan says who asked (``max_depth_source``):

* ``"user"``: :attr:`RenderOptions.max_depth` (``--max-depth N`` on ``generate-dataset`` and
  ``scenes preview``); it wins over the stage;
* ``"stage"``: the stage's own metadata, ``customLayerData["denoisebench"]["maxDepth"] = N``
  (:data:`STAGE_MAX_DEPTH_KEY`, read by the translator);
* ``"default"``: neither: unbounded.

Pitfall: a restricted depth changes the expected image (``max_depth 2`` is direct light only); such
a reference is the image *of that restriction*, and reports show it next to the scene.
"""

from __future__ import annotations

import json
from dataclasses import asdict, dataclass, field

from denoisebench.scenes.effects import validate_effects

#: Path depth in Mitsuba's convention (1 = emitters only, 2 = direct light, -1 = unbounded).
UNBOUNDED_DEPTH = -1
#: Mitsuba ``path``'s default Russian roulette start depth.
DEFAULT_RR_DEPTH = 5
#: Key of a stage's ``customLayerData["denoisebench"]`` that restricts its path depth.
STAGE_MAX_DEPTH_KEY = "maxDepth"
#: Random numbers of a path's first vertex (RPF's "random parameters" of the bounce), per sample
BOUNCE_RANDOM_PARAMETERS = ("light", "bounce")
#: Per-sample features of where the first bounce lands (RPF's second-hit features)
SECOND_HIT_FEATURES = ("position2", "normal2")


def paths_bounce(max_depth: int) -> bool:
    """Paths go past the camera's first hit (light sampling and a bounce happen): unbounded depth or
    ``max_depth`` > 1 (render_integrator's ``KernelOptions.bounces``)."""
    return max_depth == UNBOUNDED_DEPTH or max_depth > 1


def check_max_depth(value, what: str = "max_depth") -> int:
    """``value`` as a path depth: -1 (unbounded) or >= 1; ValueError naming ``what`` otherwise."""
    if isinstance(value, bool) or not isinstance(value, int) and not (isinstance(value, float) and value.is_integer()):
        raise ValueError(f"{what} must be an integer >= 1, or -1 for unbounded (got {value!r})")
    value = int(value)
    if value != UNBOUNDED_DEPTH and value < 1:
        raise ValueError(f"{what} must be >= 1, or -1 for unbounded (got {value})")
    return value


@dataclass(frozen=True)
class RenderOptions:
    """User choices that shape a plan.

    Attributes:
        max_depth: the user's restriction of path depth (None: the stage's, else unbounded;
            -1: unbounded even when the stage restricts it).
        per_sample: write per-sample data (features and random parameters, one EXR part per sample).
        aperture_scale: multiplies the lens radius; ignored without depth of field.
        shutter_scale: multiplies the shutter interval; ignored without motion blur.
        rr_depth: depth at which Russian roulette starts.
    """

    max_depth: int | None = None
    per_sample: bool = False
    aperture_scale: float = 1.0
    shutter_scale: float = 1.0
    rr_depth: int = DEFAULT_RR_DEPTH

    def __post_init__(self) -> None:
        if self.max_depth is not None:
            check_max_depth(self.max_depth)
        if self.rr_depth < 1:
            raise ValueError(f"rr_depth must be >= 1 (got {self.rr_depth})")
        if self.aperture_scale < 0 or self.shutter_scale < 0:
            raise ValueError("aperture_scale and shutter_scale must be >= 0")


@dataclass(frozen=True)
class RenderPlan:
    """Everything the renderer needs to know about *what* to simulate for one scene.

    Attributes:
        effects: the scene's effects (vocabulary order).
        camera_model: ``"pinhole"`` or ``"thin_lens"``.
        time_sampling: sample a time per ray within the shutter (camera motion blur).
        max_depth: maximum path depth (Mitsuba's convention; -1: unbounded, the default).
        max_depth_source: who decided it: ``"default"`` (unbounded), ``"user"`` or ``"stage"``.
        rr_depth: Russian roulette start depth.
        lobe_split: render diffuse and specular separately (the scene has non-diffuse lobes);
            without it the specular buffer is identically zero and diffuse equals color.
        random_parameters: per-sample random parameter channels: ``pixel`` always, ``lens`` with
            depth of field, ``time`` with motion blur, and ``light`` and ``bounce`` (the first vertex's
            light-sample and bounce-direction random numbers, :data:`BOUNCE_RANDOM_PARAMETERS`) when
            paths bounce (``max_depth`` unbounded or > 1: :func:`paths_bounce`, the rule the
            feature renderer writes them by); ``medium`` with participating media (the number that drew
            the path's first free flight in a medium, render/volpath.py). Like ``lens`` and ``time`` they
            are written only with per-sample data (``per_sample``).
        sample_features: feature channels only the per-sample data holds: the second hit's
            ``position2`` and ``normal2`` (:data:`SECOND_HIT_FEATURES`) when paths bounce, else empty.
            Plans stored before this field existed read back with it empty.
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
    max_depth_source: str = "default"
    notes: tuple[str, ...] = field(default_factory=tuple)
    sample_features: tuple[str, ...] = ()

    def to_json(self) -> str:
        return json.dumps(self.to_dict(), indent=2, sort_keys=True)

    def to_dict(self) -> dict:
        out = asdict(self)
        for key, value in out.items():
            if isinstance(value, tuple):
                out[key] = list(value)
        return out

    @classmethod
    def from_dict(cls, data: dict) -> RenderPlan:
        fields = {k: tuple(v) if isinstance(v, list) else v for k, v in data.items()}
        return cls(**fields)

    @property
    def transport_restricted(self) -> bool:
        """True when paths are cut at a finite depth (the expected image lacks some light)."""
        return self.max_depth != UNBOUNDED_DEPTH

    def transport_line(self) -> str:
        """One line for reports: ``full transport (...)`` or the restriction and who asked for it."""
        if not self.transport_restricted:
            return f"full transport (unbounded depth, Russian roulette from depth {self.rr_depth})"
        who = {"user": "the user (--max-depth)", "stage": "the stage's metadata"}.get(
            self.max_depth_source, self.max_depth_source
        )
        return f"restricted transport: max_depth {self.max_depth}, set by {who}"


def make_render_plan(effects, options: RenderOptions | None = None, stage_max_depth: int | None = None) -> RenderPlan:
    """Derive the render plan of a scene from its effects, the user's options and the stage's own
    depth restriction (``customLayerData["denoisebench"]["maxDepth"]``, None when absent); pure.

    Depth: the user's ``options.max_depth`` wins, then ``stage_max_depth``, else unbounded.
    """
    options = options or RenderOptions()
    effects = validate_effects(effects)
    present = set(effects)
    notes = []

    depth_of_field = "depth_of_field" in present
    motion_blur = "motion_blur" in present
    if options.max_depth is not None:
        max_depth, source = options.max_depth, "user"
    elif stage_max_depth is not None:
        max_depth, source = check_max_depth(stage_max_depth, f"stage metadata {STAGE_MAX_DEPTH_KEY}"), "stage"
    else:
        max_depth, source = UNBOUNDED_DEPTH, "default"
    if max_depth != UNBOUNDED_DEPTH:
        notes.append(f"transport restricted to max_depth {max_depth} by the {source}")

    bounce = paths_bounce(max_depth)
    random_parameters = ("pixel",) + (("lens",) if depth_of_field else ()) + (("time",) if motion_blur else ())
    random_parameters += ("medium",) if "media" in present else ()
    random_parameters += BOUNCE_RANDOM_PARAMETERS if bounce else ()
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
        max_depth_source=source,
        notes=tuple(notes),
        sample_features=SECOND_HIT_FEATURES if bounce else (),
    )
