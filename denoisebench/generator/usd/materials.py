"""UsdPreviewSurface → Mitsuba ``principled`` (data only; Mitsuba objects are built later).

Mapping (UsdPreviewSurface input → principled parameter):

==================  ==========================================================================
diffuseColor        base_color (a UsdUVTexture → ``bitmap``, sRGB-decoded unless ``raw``)
roughness           roughness (texture: the connected output's channel, raw)
metallic            metallic (texture: the connected output's channel, raw)
ior                 eta (ior ≤ 1 → specular 0: no dielectric reflection)
opacity             spec_trans = 1 − opacity (a smooth or rough dielectric), unless
                    opacityThreshold > 0: then a cut-out, Mitsuba ``mask`` with opacity 1 where
                    opacity ≥ threshold and 0 elsewhere (constant or textured, e.g. ``outputs:a``)
clearcoat           clearcoat; clearcoatRoughness → clearcoat_gloss = 1 − clearcoatRoughness
emissiveColor       an ``area`` emitter on the shape with this radiance
==================  ==========================================================================

Opaque materials are wrapped in ``twosided``: USD renders single-sided gprims from both sides in
practice, while Mitsuba's BSDFs are black from behind. Anything else (normal maps, displacement,
occlusion, specular workflow, other shading models) is skipped with one warning naming the prim.
Textures are decoded by :mod:`~denoisebench.generator.usd.textures` (channel choice, colour space,
``UsdTransform2d``, ``.usdz`` packages, unreadable files → the input's own value and a warning).
Texture coordinates: USD's ``st`` has v up from the image's bottom; the translator flips v for
Mitsuba, whose bitmaps put (0, 0) at the top-left. The primvar a material's textures read
(``varname``) is :attr:`MaterialInfo.uv_primvar`; the mesh reader takes its coordinates from it.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from denoisebench.generator.usd import materialx
from denoisebench.generator.usd.stage import check_finite
from denoisebench.generator.usd.textures import connected_shader as _connected_shader
from denoisebench.generator.usd.textures import read_texture
from denoisebench.generator.usd.textures import shader_id as _shader_id

# Lazy imports: pxr, inside the functions that use it (generator/usd/__init__.py says why).

DEFAULT_GREY = (0.18, 0.18, 0.18)
_SKIPPED_INPUTS = ("normal", "displacement", "occlusion")
#: A hair surface: a Shader with this ``info:id`` → Mitsuba's ``hair`` BSDF (Chiang et al. 2016),
#: its authored inputs passed as they are (floats; ``sigma_a`` a colour, used instead of the melanins).
#: Connected to ``outputs:denoisebench:surface`` (our render context: other renderers keep the universal
#: ``outputs:surface``, e.g. a UsdPreviewSurface fallback) or to the universal output itself.
HAIR_ID = "denoisebench_hair"
HAIR_INPUTS = ("eumelanin", "pheomelanin", "longitudinal_roughness", "azimuthal_roughness", "scale_tilt", "eta")


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
    uv_primvar: str | None = None  # the primvar the textures read (``varname``); None: st, else uv
    cutout: bool = False  # an alpha mask (opacityThreshold)
    report: dict = field(default_factory=dict)  # how it was translated (the manifest's ``materials``)


def default_material(display_color=None) -> MaterialInfo:
    """A grey (or displayColor) diffuse, as USD renderers show unbound gprims."""
    color = DEFAULT_GREY if display_color is None else tuple(float(c) for c in display_color)
    return MaterialInfo(
        bsdf={"type": "twosided", "bsdf": {"type": "diffuse", "reflectance": _rgb(color)}}, roughness=1.0
    )


def _rgb(values) -> dict:
    return {"type": "rgb", "value": [float(v) for v in values]}


def translate_material(material, warnings: list[str]) -> MaterialInfo:
    """UsdShade.Material → MaterialInfo (default grey diffuse, with a warning, when unsupported)."""
    path = str(material.GetPath())
    mtlx_shader = material.ComputeSurfaceSource("mtlx")[0] if material else None
    if mtlx_shader and _shader_id(mtlx_shader).startswith("ND_"):
        translated = materialx.translate_usd_network(mtlx_shader, warnings)
        if translated is not None:
            return _from_materialx(translated, path, "MaterialX network in USD", _shader_id(mtlx_shader), "")
    hair = material.ComputeSurfaceSource("denoisebench")[0] if material else None
    if hair and _shader_id(hair) == HAIR_ID:
        return _hair(hair, path)
    shader = material.ComputeSurfaceSource()[0] if material else None
    if shader and _shader_id(shader) == HAIR_ID:
        return _hair(shader, path)
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
                # The input's own authored value is the fallback when the texture cannot be used.
                got = shader_input.Get()
                if got is not None:
                    check_finite(got, str(shader.GetPath()), f"inputs:{name}")
                return (default if got is None else got), (source, output)
            warnings.append(f"{path}: inputs:{name} is driven by '{_shader_id(source)}'; its value is used")
        got = shader_input.Get()
        if got is None:
            return default, None
        check_finite(got, str(shader.GetPath()), f"inputs:{name}")
        return got, None

    for name in _SKIPPED_INPUTS:
        shader_input = shader.GetInput(name)
        if shader_input and (shader_input.HasConnectedSource() or shader_input.Get() is not None):
            warnings.append(f"{path}: inputs:{name} is not supported; skipped")
    use_specular = shader.GetInput("useSpecularWorkflow")
    if use_specular and use_specular.Get():
        warnings.append(f"{path}: specular workflow is not supported; metallic workflow used")

    info = MaterialInfo(bsdf={}, source=path, report={"material": path, "kind": "UsdPreviewSurface"})
    principled: dict = {"type": "principled"}

    diffuse, diffuse_texture = value("diffuseColor", DEFAULT_GREY)
    principled["base_color"] = _rgb(np.clip(diffuse, 0, 1))
    if diffuse_texture:
        texture = _use_texture(info, diffuse_texture, True, warnings, path)
        if texture:
            principled["base_color"] = texture

    for name, key, default in (("roughness", "roughness", 0.5), ("metallic", "metallic", 0.0)):
        number, texture = value(name, default)
        number = float(np.clip(number, 0.0, 1.0))
        principled[key] = number
        setattr(info, key, number)
        if texture:
            bitmap = _use_texture(info, texture, False, warnings, path)
            if bitmap:
                principled[key] = bitmap

    ior, _ = value("ior", 1.5)
    ior = float(ior)
    if ior > 1.0 + 1e-4:
        principled["eta"] = ior
    else:
        principled["specular"] = 0.0
    opacity, opacity_texture = value("opacity", 1.0)
    threshold, _ = value("opacityThreshold", 0.0)
    threshold = float(threshold)
    mask = None
    if threshold > 0:
        # A cut-out: opacity below the threshold is a hole, the rest fully opaque (no dielectric).
        texture = _use_texture(info, opacity_texture, False, warnings, path) if opacity_texture else None
        if texture is not None:
            texture["data"] = (texture["data"] >= threshold).astype(np.float32)
            texture["filter_type"] = "nearest"  # a binary mask stays binary
            mask = texture
        elif float(opacity) < threshold:
            mask = {"type": "rgb", "value": [0.0, 0.0, 0.0]}
        info.cutout = mask is not None
        opacity = 1.0
    elif opacity_texture:
        warnings.append(
            f"{path}: textured opacity without opacityThreshold is not supported; constant {float(opacity):g} used"
        )
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
    if mask is not None:
        info.bsdf = {"type": "mask", "opacity": mask, "bsdf": info.bsdf}
    return info


def _hair(shader, path: str) -> MaterialInfo:
    """A ``denoisebench_hair`` surface → Mitsuba ``hair`` (a rough, glossy fibre: effect ``glossy``)."""
    bsdf: dict = {"type": "hair"}
    for name in HAIR_INPUTS:
        shader_input = shader.GetInput(name)
        value = shader_input.Get() if shader_input else None
        if value is not None:
            bsdf[name] = float(check_finite(value, str(shader.GetPath()), f"inputs:{name}"))
    sigma = shader.GetInput("sigma_a")
    if sigma and sigma.Get() is not None:
        bsdf["sigma_a"] = _rgb(check_finite(sigma.Get(), str(shader.GetPath()), "inputs:sigma_a"))
        bsdf.pop("eumelanin", None)  # Mitsuba takes absorption or pigmentation, not both
        bsdf.pop("pheomelanin", None)
    roughness = float(bsdf.get("longitudinal_roughness", 0.3))
    return MaterialInfo(
        bsdf=bsdf, roughness=roughness, metallic=1.0, report={"material": path, "kind": "denoisebench hair"}
    )


def _from_materialx(translated, path: str, kind: str, surface: str, document: str) -> MaterialInfo:
    """A :class:`materialx.Translation` → MaterialInfo, with its manifest report."""
    report = {"material": path, "kind": kind, "surface": surface, "fallbacks": list(translated.fallbacks)}
    if document:
        report["document"] = document
    return MaterialInfo(
        bsdf=translated.bsdf,
        emission=translated.emission,
        roughness=translated.roughness,
        metallic=translated.metallic,
        opacity=translated.opacity,
        textured=bool(translated.texture_files),
        source=path,
        texture_files=list(translated.texture_files),
        uv_primvar=translated.uv_primvar,
        cutout=translated.cutout,
        report=report,
    )


def _use_texture(info: MaterialInfo, connection, want_color: bool, warnings: list[str], owner: str) -> dict | None:
    """Decode the texture of a ``(shader, output)`` connection; record it on ``info``. None: fallback."""
    shader, output = connection
    texture = read_texture(shader, output, want_color, warnings, owner)
    if texture is None:
        return None
    info.textured = True
    info.texture_files.append(texture.source)
    if texture.primvar:
        if info.uv_primvar and info.uv_primvar != texture.primvar:
            warnings.append(
                f"{owner}: textures read primvars '{info.uv_primvar}' and '{texture.primvar}'; "
                f"'{info.uv_primvar}' is used for all"
            )
        info.uv_primvar = info.uv_primvar or texture.primvar
    return texture.bitmap


def bound_material(prim, cache: dict, warnings: list[str]) -> MaterialInfo:
    """The material bound to ``prim`` (full-purpose binding), translated once per material path."""
    from pxr import UsdGeom, UsdShade

    material = UsdShade.MaterialBindingAPI(prim).ComputeBoundMaterial()[0]
    if not material:
        target = materialx.unresolved_binding(prim)
        found = materialx.mtlx_reference(prim.GetStage(), target) if target is not None else None
        if found is not None:
            key = f"{found[0]}:{found[1]}"
            if key not in cache:
                translated, category = materialx.translate_document_material(found[0], found[1], warnings)
                cache[key] = (
                    _from_materialx(translated, str(target), "MaterialX document", category, found[0])
                    if translated is not None
                    else default_material()
                )
            return cache[key]
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
