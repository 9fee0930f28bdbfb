"""The closed vocabulary of rendering effects, and where a stage declares the ones it exercises.

A scene family declares its effects in the stage's ``customLayerData`` (see :data:`METADATA_KEY`);
the translator also infers them from the stage and reports a mismatch. Extend the vocabulary
deliberately, with a test: the render plan (``denoisebench.generator.contract.render_plan``) decides what to
simulate from these names.
"""

from __future__ import annotations

EFFECTS: tuple[str, ...] = (
    "depth_of_field",  # camera fStop > 0: thin lens, lens u,v channels
    "motion_blur",  # open shutter with an animated camera: time channel
    "glossy",  # rough specular lobes (0 < roughness < ~0.4 with metallic/specular)
    "specular",  # delta lobes (roughness ~0: mirrors, smooth dielectrics)
    "transmission",  # opacity < 1: refraction through a dielectric
    "textures",  # UsdUVTexture inputs
    "area_lights",  # Rect / Sphere / Disk lights, emissive geometry
    "environment",  # Dome light
    "indirect",  # multi-bounce light transport matters
    "media",  # participating media (fog, smoke, subsurface): the volumetric tracer (render/volpath.py)
)

#: Effects no stage can show by itself (multi-bounce transport matters): only ever declared.
DECLARED_ONLY: tuple[str, ...] = ("indirect",)

#: Key under the root layer's customLayerData holding denoisebench metadata:
#: ``{"family": str, "seed": int, "effects": [str, ...], "frames": int}``.
METADATA_KEY = "denoisebench"


def validate_effects(names) -> tuple[str, ...]:
    """Return ``names`` sorted in vocabulary order; raise ValueError naming any unknown effect."""
    names = list(names)
    unknown = sorted(set(names) - set(EFFECTS))
    if unknown:
        raise ValueError(f"unknown effect(s) {', '.join(unknown)}; known: {', '.join(EFFECTS)}")
    return tuple(e for e in EFFECTS if e in names)
