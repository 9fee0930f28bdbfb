"""MaterialX materials → Mitsuba ``principled`` (plain data), read with the MaterialX library.

Two ways a stage holds MaterialX, both translated by the same evaluator:

* **``.mtlx`` documents referenced from USD** (``references = @./Pawn_mat.mtlx@</MaterialX/Materials>``).
  PyPI's usd-core has no ``.mtlx`` file format, so the reference does not compose and the binding
  targets a prim that is not there. :func:`mtlx_reference` finds, along the binding target's path, the
  prim whose own specs reference a ``.mtlx`` file, reads the document with ``MaterialX`` (PyPI), and
  maps the target to a ``<surfacematerial>`` as usdMtlx lays a document out
  (``/MaterialX/Materials/<name>``).
* **MaterialX networks authored in USD** (a ``Material`` whose ``outputs:mtlx:surface`` is a
  ``Shader`` with ``info:id = "ND_standard_surface_surfaceshader"``, ``ND_image_color3``, ...):
  :func:`translate_usd_network`. ``NodeGraph`` connections are followed with
  ``UsdShade.Utils.GetValueProducingAttributes``.

Surface shaders (``standard_surface`` / ``open_pbr_surface`` input → principled parameter):

=======================================================  =========================================
base × base_color / base_weight × base_color             base_color
metalness / base_metalness                               metallic
specular_roughness                                       roughness (both square it into α)
specular_IOR / specular_ior, specular / specular_weight  eta (weight 1), else specular = w·F0(ior)/0.08
specular_anisotropy / specular_roughness_anisotropy      anisotropic
transmission(_weight), transmission_color                spec_trans; principled tints transmission by
                                                         √base_color, so base_color → mix(base,
                                                         transmission_color², transmission)
coat(_weight), coat_roughness                            clearcoat, clearcoat_gloss = 1 − roughness
sheen / fuzz_weight                                      sheen
emission × emission_color / emission_luminance × color   an ``area`` emitter (constant radiance)
opacity / geometry_opacity (< 1)                         a ``mask`` around the BSDF (cut-out)
normal / geometry_normal ← ``normalmap``                 a ``normalmap`` around the BSDF
=======================================================  =========================================

Not translated, each with one warning naming the input and what was used: specular/coat/sheen
colours other than white, subsurface, thin-walled, diffuse roughness, textured emission.
Opaque materials are wrapped in ``twosided`` as in :mod:`~denoisebench.generator.usd.materials`.

Pattern nodes (images, normal maps, the common math nodes, the hair absorption nodes) are evaluated
on numpy by :mod:`~denoisebench.generator.usd.materialx_graph`, which names each node it cannot
evaluate in one warning. Hair: a ``surface`` node over a ``chiang_hair_bsdf`` becomes Mitsuba's
``hair`` BSDF (:func:`_hair`).
Each translated material records how (:attr:`MaterialInfo.report`): the document, the surface
shader, and the fallbacks taken; the manifest lists them.
"""

from __future__ import annotations

import os
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from denoisebench.generator.usd.materialx_graph import (
    Evaluator,
    MxNode,
    UsdNode,
    Val,
    combine,
    read_document,
    to_channels,
)

# Lazy imports: pxr and MaterialX, inside the functions that use them.

SURFACES = ("standard_surface", "open_pbr_surface")


@dataclass
class Translation:
    """What :func:`_principled` produces before it becomes a MaterialInfo."""

    bsdf: dict
    emission: tuple[float, float, float] | None
    roughness: float
    metallic: float
    opacity: float
    cutout: bool
    texture_files: list[str] = field(default_factory=list)
    uv_primvar: str | None = None
    fallbacks: list[str] = field(default_factory=list)


# --------------------------------------------------------------------------------------------------
# Surface shader → principled


def _param(val: Val, name: str, evaluator: Evaluator, translation: Translation) -> object:
    """A Val → principled parameter: a float, an ``rgb`` dict, or a ``bitmap`` dict."""
    if not val.textured:
        values = [round(float(v), 6) for v in val.array]  # float32 inputs: 0.8f → 0.8
        return values[0] if len(values) == 1 else {"type": "rgb", "value": values}
    meta = val.meta or {}
    translation.texture_files.extend(f for f in meta.get("files", []) if f not in translation.texture_files)
    primvar = meta.get("primvar")
    if primvar:
        if translation.uv_primvar and translation.uv_primvar != primvar:
            evaluator.warnings.append(f"{name}: textures read primvars '{translation.uv_primvar}' and '{primvar}'")
        translation.uv_primvar = translation.uv_primvar or primvar
    bitmap = {
        "type": "bitmap",
        "data": np.ascontiguousarray(val.array, dtype=np.float32),
        "raw": True,
        "wrap_mode": meta.get("wrap_mode", "repeat"),
        "filter_type": "bilinear",
    }
    if "to_uv" in meta:
        bitmap["to_uv"] = meta["to_uv"]
    return bitmap


def _clipped(val: Val) -> Val:
    """``val`` clamped to [0, 1]; an image already inside stays the same array (no copy of large textures)."""
    if float(val.array.min()) >= 0.0 and float(val.array.max()) <= 1.0:
        return val
    return combine(lambda a: np.clip(a, 0.0, 1.0), val)


def _mean(val: Val | None, default: float) -> float:
    return default if val is None else float(np.mean(val.array))


_NAMES = {
    "standard_surface": {
        "base": "base",
        "base_color": "base_color",
        "metallic": "metalness",
        "specular": "specular",
        "specular_color": "specular_color",
        "roughness": "specular_roughness",
        "ior": "specular_IOR",
        "anisotropic": "specular_anisotropy",
        "transmission": "transmission",
        "transmission_color": "transmission_color",
        "coat": "coat",
        "coat_color": "coat_color",
        "coat_roughness": "coat_roughness",
        "sheen": "sheen",
        "sheen_color": "sheen_color",
        "emission": "emission",
        "emission_color": "emission_color",
        "opacity": "opacity",
        "normal": "normal",
        "subsurface": "subsurface",
        "thin_walled": "thin_walled",
        "diffuse_roughness": "diffuse_roughness",
    },
    "open_pbr_surface": {
        "base": "base_weight",
        "base_color": "base_color",
        "metallic": "base_metalness",
        "specular": "specular_weight",
        "specular_color": "specular_color",
        "roughness": "specular_roughness",
        "ior": "specular_ior",
        "anisotropic": "specular_roughness_anisotropy",
        "transmission": "transmission_weight",
        "transmission_color": "transmission_color",
        "coat": "coat_weight",
        "coat_color": "coat_color",
        "coat_roughness": "coat_roughness",
        "sheen": "fuzz_weight",
        "sheen_color": "fuzz_color",
        "emission": "emission_luminance",
        "emission_color": "emission_color",
        "opacity": "geometry_opacity",
        "normal": "geometry_normal",
        "subsurface": "subsurface_weight",
        "thin_walled": "geometry_thin_walled",
        "diffuse_roughness": "base_diffuse_roughness",
    },
}


def _principled(surface, warnings: list[str]) -> Translation:
    """A standard_surface / open_pbr_surface node view → the principled BSDF of the module docstring."""
    names = _NAMES[surface.category]
    translation = Translation(bsdf={}, emission=None, roughness=0.5, metallic=0.0, opacity=1.0, cutout=False)
    evaluator = Evaluator(warnings, translation.fallbacks)
    label = surface.label

    def get(key: str, size: int) -> Val | None:
        return evaluator.input(surface, names[key], size)

    def note(line: str) -> None:
        warnings.append(f"{label}: {line}")
        translation.fallbacks.append(line)

    def constant(key: str, size: int, default: float) -> float:
        got = get(key, size)
        if got is not None and got.textured:
            note(f"textured {names[key]} is not supported; its mean {_mean(got, default):g} used")
        return round(_mean(got, default), 6)

    principled: dict = {"type": "principled"}
    base = get("base", 1)
    colour = get("base_color", 3) or Val(np.full(3, 0.8, dtype=np.float32))
    if base is not None:
        colour = combine(np.multiply, colour, to_channels(base, 3))
    transmission = constant("transmission", 1, 0.0)
    transmission = float(np.clip(transmission, 0.0, 1.0))
    if transmission > 0:
        tint = get("transmission_color", 3) or Val(np.ones(3, dtype=np.float32))
        colour = combine(
            lambda c, t: c * (1.0 - transmission) + np.square(t) * transmission, colour, to_channels(tint, 3)
        )
        principled["spec_trans"] = transmission
    colour = _clipped(colour)
    principled["base_color"] = _param(colour, label, evaluator, translation)

    for key, target, default in (("roughness", "roughness", 0.2), ("metallic", "metallic", 0.0)):
        got = get(key, 1)
        got = Val(np.array([default], dtype=np.float32)) if got is None else got
        got = _clipped(got)
        principled[target] = _param(got, label, evaluator, translation)
        setattr(translation, key, _mean(got, default))
    anisotropic = float(np.clip(constant("anisotropic", 1, 0.0), 0.0, 1.0))
    if anisotropic > 0:
        principled["anisotropic"] = anisotropic

    ior = constant("ior", 1, 1.5)
    weight = float(np.clip(constant("specular", 1, 1.0), 0.0, 1.0))
    if ior <= 1.0 + 1e-4 or weight <= 0.0:
        principled["specular"] = 0.0
        if transmission > 0:
            principled.pop("specular")
            principled["eta"] = max(ior, 1.0 + 1e-3)
    elif abs(weight - 1.0) > 1e-6 and transmission == 0:
        principled["specular"] = round(float(weight * ((ior - 1.0) / (ior + 1.0)) ** 2 / 0.08), 6)
    else:
        principled["eta"] = round(float(ior), 6)
    for key in ("specular_color", "coat_color", "sheen_color"):
        got = get(key, 3)
        if got is not None and (got.textured or np.any(np.abs(got.array - 1.0) > 1e-4)):
            note(f"{names[key]} other than white is not supported; white used")

    coat = float(np.clip(constant("coat", 1, 0.0), 0.0, 1.0))
    if coat > 0:
        principled["clearcoat"] = coat
        gloss = 1.0 - constant("coat_roughness", 1, 0.1)
        principled["clearcoat_gloss"] = round(float(np.clip(gloss, 0.0, 1.0)), 6)
    sheen = float(np.clip(constant("sheen", 1, 0.0), 0.0, 1.0))
    if sheen > 0:
        principled["sheen"] = sheen

    emission = get("emission", 1)
    emission_colour = get("emission_color", 3)
    if emission is not None and (emission.textured or float(emission.array[0]) > 0):
        radiance = combine(np.multiply, to_channels(emission, 3), emission_colour or Val(np.ones(3, np.float32)))
        if radiance.textured:
            note("textured emission is not supported; its mean used")
        value = tuple(max(0.0, float(v)) for v in radiance.array.reshape(-1, 3).mean(0))
        if max(value) > 0:
            translation.emission = value

    for key, instead in (("subsurface", "a diffuse base used"), ("diffuse_roughness", "Lambertian diffuse used")):
        got = get(key, 1)
        if got is not None and (got.textured or float(got.array[0]) > 0.0):
            note(f"{names[key]} is not supported; {instead}")
    thin = get("thin_walled", 1)
    if thin is not None and float(thin.array[0]) > 0.5:
        note(f"{names['thin_walled']} is not supported; a solid surface used")

    bsdf: dict = principled
    normal = get("normal", 3)
    if normal is not None and normal.textured and (normal.meta or {}).get("normalmap"):
        bsdf = {"type": "normalmap", "normalmap": _param(normal, label, evaluator, translation), "bsdf": bsdf}
    elif normal is not None and normal.textured:
        note("a normal input not fed by a normalmap node is not supported; the geometric normal used")
    if transmission == 0:
        bsdf = {"type": "twosided", "bsdf": bsdf}
    translation.opacity = 1.0 - transmission

    opacity = get("opacity", 1)
    if opacity is not None and (opacity.textured or float(opacity.array[0]) < 1.0):
        opacity = combine(lambda a: np.clip(a, 0.0, 1.0), opacity)
        bsdf = {"type": "mask", "opacity": _param(opacity, label, evaluator, translation), "bsdf": bsdf}
        translation.cutout = True
    translation.bsdf = bsdf
    return translation


def _hair(surface, warnings: list[str]) -> Translation | None:
    """A ``surface`` node whose ``bsdf`` is a ``chiang_hair_bsdf`` → Mitsuba's ``hair`` (the same model).

    ``roughness_R`` from a ``chiang_hair_roughness`` node gives Mitsuba's longitudinal and azimuthal
    roughness directly; a raw ``roughness_R`` (MaterialX's variance and logistic scale) is inverted
    through that node's mapping. ``cuticle_angle`` (0..1, 0.5 = none) → ``scale_tilt`` in degrees;
    ``absorption_coefficient`` → ``sigma_a``. Tints other than white and TT/TRT scales other than
    MaterialX's defaults (Mitsuba fixes 0.5 and 2) warn."""
    upstream = surface.connection("bsdf")
    if upstream is None or upstream[0].category != "chiang_hair_bsdf":
        return None
    hair = upstream[0]
    translation = Translation(bsdf={}, emission=None, roughness=0.3, metallic=1.0, opacity=1.0, cutout=False)
    evaluator = Evaluator(warnings, translation.fallbacks)

    def note(line: str) -> None:
        warnings.append(f"{hair.label}: {line}")
        translation.fallbacks.append(line)

    def number(node, name: str, size: int, default) -> np.ndarray:
        got = evaluator.input(node, name, size)
        if got is None:
            return np.asarray(default, dtype=np.float64)
        if got.textured:
            note(f"textured {name} is not supported; its mean used")
        return got.array.reshape(-1, size).mean(0).astype(np.float64)

    bsdf: dict = {"type": "hair", "eta": round(float(number(hair, "ior", 1, [1.55])[0]), 6)}
    source = hair.connection("roughness_R")
    if source is not None and source[0].category == "chiang_hair_roughness":
        longitudinal = float(number(source[0], "longitudinal", 1, [0.1])[0])
        azimuthal = float(number(source[0], "azimuthal", 1, [0.2])[0])
        scales = number(source[0], "scale_TT", 1, [0.5])[0], number(source[0], "scale_TRT", 1, [2.0])[0]
        if abs(scales[0] - 0.5) > 1e-6 or abs(scales[1] - 2.0) > 1e-6:
            note("scale_TT/scale_TRT other than 0.5/2 are not supported; Mitsuba's 0.5/2 used")
    else:
        variance, logistic = number(hair, "roughness_R", 2, [0.1, 0.1])
        beta = np.linspace(0.001, 1.0, 2000)
        v = np.square(0.726 * beta + 0.812 * beta**2 + 3.7 * beta**20)
        s = 0.265 * beta + 1.194 * beta**2 + 5.372 * beta**22
        longitudinal = float(np.interp(variance, v, beta))
        azimuthal = float(np.interp(logistic, s, beta))
    bsdf["longitudinal_roughness"] = round(float(np.clip(longitudinal, 0.001, 1.0)), 6)
    bsdf["azimuthal_roughness"] = round(float(np.clip(azimuthal, 0.001, 1.0)), 6)
    bsdf["scale_tilt"] = round(float(number(hair, "cuticle_angle", 1, [0.5])[0]) * 180.0 - 90.0, 6)
    for name in ("tint_R", "tint_TT", "tint_TRT"):
        if np.any(np.abs(number(hair, name, 3, [1.0, 1.0, 1.0]) - 1.0) > 1e-4):
            note(f"{name} other than white is not supported; white used")
    absorption = np.maximum(number(hair, "absorption_coefficient", 3, [0.0, 0.0, 0.0]), 0.0)
    bsdf["sigma_a"] = {"type": "rgb", "value": [round(float(v), 6) for v in absorption]}
    translation.bsdf = bsdf
    translation.roughness = bsdf["longitudinal_roughness"]
    return translation


# --------------------------------------------------------------------------------------------------
# Entry points (USD side)


def translate_usd_network(shader, warnings: list[str]) -> Translation | None:
    """A MaterialX surface shader authored in USD → Translation (None: not a supported surface)."""
    node = UsdNode(shader)
    if node.category == "surface":
        return _hair(node, warnings)
    if node.category not in SURFACES:
        return None
    return _principled(node, warnings)


def translate_document_material(path: str, name: str, warnings: list[str]) -> tuple[Translation | None, str]:
    """The ``<surfacematerial name=...>`` of a ``.mtlx`` file → (Translation or None, surface category)."""
    import MaterialX as mx

    document = read_document(path)
    material = document.getNode(name)
    if material is None or material.getType() != "material":
        warnings.append(f"{path}: no material '{name}' in the MaterialX document; grey diffuse used")
        return None, ""
    shaders = mx.getShaderNodes(material)
    if not shaders:
        warnings.append(f"{path}: material '{name}' has no surface shader; grey diffuse used")
        return None, ""
    shader = shaders[0]
    category = shader.getCategory()
    if category == "surface":
        hair = _hair(MxNode(shader, str(Path(path).parent)), warnings)
        if hair is not None:
            return hair, "chiang_hair_bsdf"
    if category not in SURFACES:
        warnings.append(f"{path}: material '{name}': surface '{category}' is not translated; grey diffuse used")
        return None, category
    return _principled(MxNode(shader, str(Path(path).parent)), warnings), category


def document_files(path: str | Path) -> list[str]:
    """Absolute paths of the existing files a ``.mtlx`` document's ``filename`` inputs name (its textures),
    for copying a stage with its dependencies; an unreadable document names none."""
    try:
        document = read_document(path)
    except Exception:
        return []
    folder = os.path.dirname(os.path.abspath(str(path)))
    out = set()
    for element in document.traverseTree():
        if element.getCategory() == "input" and element.getType() == "filename":
            if element.getDocument() != document or not element.getValueString():
                continue
            text = element.getResolvedValueString()
            resolved = text if os.path.isabs(text) else os.path.join(folder, text)
            if os.path.isfile(resolved):
                out.add(os.path.normpath(resolved))
    return sorted(out)


def mtlx_reference(stage, target_path) -> tuple[str, str] | None:
    """The ``.mtlx`` document and material name a binding target means, or None.

    Walks up ``target_path`` to a prim whose specs reference a ``.mtlx`` layer; the rest of the path,
    appended to the reference's prim path (``/MaterialX/Materials`` by convention), names the material."""
    from pxr import Sdf

    path = Sdf.Path(str(target_path))
    tail: list[str] = []
    while path != Sdf.Path.absoluteRootPath and not path.isEmpty:
        prim = stage.GetPrimAtPath(path)
        if prim:
            for spec in prim.GetPrimStack():
                references = spec.referenceList
                items = list(references.prependedItems) + list(references.appendedItems)
                items += list(references.explicitItems) + list(references.addedItems)
                for reference in items:
                    asset = str(reference.assetPath)
                    if not asset.lower().endswith(".mtlx"):
                        continue
                    resolved = spec.layer.ComputeAbsolutePath(asset)
                    if not os.path.isfile(resolved):
                        continue
                    inner = str(reference.primPath) if not reference.primPath.isEmpty else "/MaterialX"
                    full = "/".join([inner.rstrip("/")] + list(reversed(tail)))
                    parts = [p for p in full.split("/") if p]
                    # usdMtlx: /MaterialX/Materials/<name>
                    if len(parts) >= 3 and parts[1] == "Materials":
                        return resolved, parts[2]
                    if parts:
                        return resolved, parts[-1]
            return None
        tail.append(path.name)
        path = path.GetParentPath()
    return None


def unresolved_binding(prim):
    """The target of the nearest ``material:binding`` on ``prim`` or an ancestor when it is not a Material."""
    from pxr import UsdShade

    current = prim
    while current and not current.IsPseudoRoot():
        relationship = current.GetRelationship("material:binding")
        if relationship:
            targets = relationship.GetForwardedTargets()
            if targets:
                target = current.GetStage().GetPrimAtPath(targets[0])
                if target and target.IsA(UsdShade.Material):
                    return None
                return targets[0]
        current = current.GetParent()
    return None
