"""UsdPreviewSurface → Mitsuba ``principled`` (data only; Mitsuba objects are built later).

Mapping (UsdPreviewSurface input → principled parameter):

==================  ==========================================================================
diffuseColor        base_color (a UsdUVTexture → ``bitmap``, sRGB-decoded unless ``raw``)
roughness           roughness (texture: its red channel, raw)
metallic            metallic (texture: raw)
ior                 eta (ior ≤ 1 → specular 0: no dielectric reflection)
opacity             spec_trans = 1 − opacity (a smooth or rough dielectric, not an alpha cut-out)
clearcoat           clearcoat; clearcoatRoughness → clearcoat_gloss = 1 − clearcoatRoughness
emissiveColor       an ``area`` emitter on the shape with this radiance
==================  ==========================================================================

Opaque materials are wrapped in ``twosided``: USD renders single-sided gprims from both sides in
practice, while Mitsuba's BSDFs are black from behind. Anything else (normal maps, displacement,
occlusion, specular workflow, other shading models) is skipped with one warning naming the prim.
Texture coordinates: USD's ``st`` has v up from the image's bottom; the translator flips v for
Mitsuba, whose bitmaps put (0, 0) at the top-left.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from denoisebench.generator.usd_stage import check_finite

DEFAULT_GREY = (0.18, 0.18, 0.18)
_SKIPPED_INPUTS = ("normal", "displacement", "occlusion", "opacityThreshold")


@dataclass
class MaterialInfo:
    """One translated material: the BSDF dict, its emission, and what effect inference needs."""

    bsdf: dict
    emission: tuple[float, float, float] | None = None
    roughness: float = 0.5
    metallic: float = 0.0
    opacity: float = 1.0
    textured: bool = False
    source: str = ""
    texture_files: list[str] = field(default_factory=list)


def default_material(display_color=None) -> MaterialInfo:
    """A grey (or displayColor) diffuse, as USD renderers show unbound gprims."""
    color = DEFAULT_GREY if display_color is None else tuple(float(c) for c in display_color)
    return MaterialInfo(bsdf={"type": "twosided", "bsdf": {"type": "diffuse", "reflectance": _rgb(color)}}, roughness=1.0)


def _rgb(values) -> dict:
    return {"type": "rgb", "value": [float(v) for v in values]}


def _connected_shader(shader_input):
    """(shader, output name) feeding this input, or (None, None)."""
    from pxr import UsdShade

    if not shader_input.HasConnectedSource():
        return None, None
    sources = shader_input.GetConnectedSources()[0]
    if not sources:
        return None, None
    info = sources[0]
    return UsdShade.Shader(info.source.GetPrim()), str(info.sourceName)


def _shader_id(shader) -> str:
    return str(shader.GetIdAttr().Get() or "") if shader else ""


def _texture_dict(texture_shader, raw_default: bool, warnings: list[str], owner: str):
    """A UsdUVTexture → Mitsuba ``bitmap`` dict, or None (with a warning) when unusable."""
    path = str(texture_shader.GetPath())
    file_input = texture_shader.GetInput("file")
    asset = file_input.Get() if file_input else None
    if asset is None:
        warnings.append(f"{path}: UsdUVTexture without inputs:file; texture skipped on {owner}")
        return None
    resolved = asset.resolvedPath or ""
    if not resolved or not Path(resolved).is_file():
        warnings.append(f"{path}: texture file '{asset.path}' not found; texture skipped on {owner}")
        return None
    color_space_input = texture_shader.GetInput("sourceColorSpace")
    color_space = str(color_space_input.Get()) if color_space_input and color_space_input.Get() else "auto"
    raw = raw_default if color_space == "auto" else color_space == "raw"
    wrap_input = texture_shader.GetInput("wrapS")
    wrap = str(wrap_input.Get()) if wrap_input and wrap_input.Get() else "repeat"
    wrap_mode = {"repeat": "repeat", "mirror": "mirror", "clamp": "clamp", "black": "clamp"}.get(wrap, "repeat")
    for name in ("scale", "bias"):
        value = texture_shader.GetInput(name)
        if value and value.Get() is not None:
            default = (1, 1, 1, 1) if name == "scale" else (0, 0, 0, 0)
            if tuple(value.Get()) != default:
                warnings.append(f"{path}: inputs:{name} is not supported; ignored")
    return {"type": "bitmap", "filename": resolved, "raw": raw, "wrap_mode": wrap_mode, "filter_type": "bilinear"}


def translate_material(material, warnings: list[str]) -> MaterialInfo:
    """UsdShade.Material → MaterialInfo (default grey diffuse, with a warning, when unsupported)."""
    path = str(material.GetPath())
    shader = material.ComputeSurfaceSource()[0] if material else None
    if not shader or _shader_id(shader) != "UsdPreviewSurface":
        kind = _shader_id(shader) or "no surface shader"
        warnings.append(f"{path}: surface '{kind}' is not UsdPreviewSurface; grey diffuse used")
        return default_material()

    def value(name, default):
        shader_input = shader.GetInput(name)
        if not shader_input:
            return default, None
        source, output = _connected_shader(shader_input)
        if source is not None:
            if _shader_id(source) == "UsdUVTexture":
                return default, (source, output)
            warnings.append(f"{path}: inputs:{name} is driven by '{_shader_id(source)}'; its value is used")
        got = shader_input.Get()
        if got is None:
            return default, None
        check_finite(got, str(shader.GetPath()), f"inputs:{name}")
        return got, None

    for name in _SKIPPED_INPUTS:
        shader_input = shader.GetInput(name)
        if shader_input and (shader_input.HasConnectedSource() or (name != "opacityThreshold" and shader_input.Get() is not None)):
            warnings.append(f"{path}: inputs:{name} is not supported; skipped")
    use_specular = shader.GetInput("useSpecularWorkflow")
    if use_specular and use_specular.Get():
        warnings.append(f"{path}: specular workflow is not supported; metallic workflow used")

    info = MaterialInfo(bsdf={}, source=path)
    principled: dict = {"type": "principled"}

    diffuse, diffuse_texture = value("diffuseColor", DEFAULT_GREY)
    principled["base_color"] = _rgb(np.clip(diffuse, 0, 1))
    if diffuse_texture:
        bitmap = _texture_dict(diffuse_texture[0], raw_default=False, warnings=warnings, owner=path)
        if bitmap:
            principled["base_color"] = bitmap
            info.textured = True
            info.texture_files.append(bitmap["filename"])

    for name, key, default in (("roughness", "roughness", 0.5), ("metallic", "metallic", 0.0)):
        number, texture = value(name, default)
        number = float(np.clip(number, 0.0, 1.0))
        principled[key] = number
        setattr(info, key, number)
        if texture:
            bitmap = _texture_dict(texture[0], raw_default=True, warnings=warnings, owner=path)
            if bitmap:
                principled[key] = bitmap
                info.textured = True
                info.texture_files.append(bitmap["filename"])

    ior, _ = value("ior", 1.5)
    ior = float(ior)
    if ior > 1.0 + 1e-4:
        principled["eta"] = ior
    else:
        principled["specular"] = 0.0
    opacity, opacity_texture = value("opacity", 1.0)
    if opacity_texture:
        warnings.append(f"{path}: textured opacity is not supported; constant {float(opacity):g} used")
    info.opacity = float(np.clip(opacity, 0.0, 1.0))
    if info.opacity < 1.0:
        principled["spec_trans"] = 1.0 - info.opacity
        principled.setdefault("eta", 1.5)
    clearcoat, _ = value("clearcoat", 0.0)
    if float(clearcoat) > 0:
        principled["clearcoat"] = float(np.clip(clearcoat, 0, 1))
        coat_roughness, _ = value("clearcoatRoughness", 0.01)
        principled["clearcoat_gloss"] = float(np.clip(1.0 - float(coat_roughness), 0, 1))
    emissive, emissive_texture = value("emissiveColor", (0.0, 0.0, 0.0))
    if emissive_texture:
        warnings.append(f"{path}: textured emissiveColor is not supported; constant value used")
    emissive = tuple(max(0.0, float(c)) for c in emissive)
    if max(emissive) > 0:
        info.emission = emissive

    info.bsdf = principled if info.opacity < 1.0 else {"type": "twosided", "bsdf": principled}
    return info


def bound_material(prim, cache: dict, warnings: list[str]) -> MaterialInfo:
    """The material bound to ``prim`` (full-purpose binding), translated once per material path."""
    from pxr import UsdGeom, UsdShade

    material = UsdShade.MaterialBindingAPI(prim).ComputeBoundMaterial()[0]
    if material:
        key = str(material.GetPath())
        if key not in cache:
            cache[key] = translate_material(material, warnings)
        return cache[key]
    display = UsdGeom.Gprim(prim).GetDisplayColorPrimvar() if prim.IsA(UsdGeom.Gprim) else None
    color = None
    if display and display.HasAuthoredValue():
        values = display.Get()
        if values is not None and len(values) > 0:
            color = np.clip(np.asarray(values[0], dtype=np.float64), 0, 1)
    key = f"__default__{None if color is None else tuple(np.round(color, 6))}"
    if key not in cache:
        cache[key] = default_material(color)
    return cache[key]
