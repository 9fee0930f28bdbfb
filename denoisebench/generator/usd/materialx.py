"""MaterialX materials → Mitsuba ``principled`` (plain data), read with the MaterialX library.

Two ways a stage holds MaterialX, both translated by the same evaluator:

* **``.mtlx`` documents referenced from USD** (``references = @./Pawn_mat.mtlx@</MaterialX/Materials>``).
  PyPI's usd-core has no ``.mtlx`` file format, so the reference does not compose and the binding
  targets a prim that is not there. :func:`material_from_binding` finds, along the target path, the
  prim whose own specs reference a ``.mtlx`` file, reads the document with ``MaterialX`` (PyPI), and
  maps the target to a ``<surfacematerial>`` as usdMtlx lays a document out
  (``/MaterialX/Materials/<name>``).
* **MaterialX networks authored in USD** (a ``Material`` whose ``outputs:mtlx:surface`` is a
  ``Shader`` with ``info:id = "ND_standard_surface_surfaceshader"``, ``ND_image_color3``, ...):
  :func:`translate_usd_network`. ``NodeGraph`` connections are followed with
  ``UsdShade.Utils.GetValueProducingAttributes``.

Unauthored inputs take the node definition's default (MaterialX's own standard library).

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

Pattern nodes are evaluated here, on numpy: ``constant``, ``image``/``tiledimage`` (colour space
from the file input or document, sRGB decoded; ``float`` outputs take the first channel),
``normalmap``, and the common math nodes (add, subtract, multiply, divide, mix, clamp, invert, power,
min, max, absval, sqrt, remap, smoothstep, luminance, dotproduct, extract, convert, swizzle,
combine2/3/4, dot, separate3). A texture combined with a constant stays a texture (its pixels
computed); two textures combine pixel by pixel (the smaller resampled, nearest). Any other node:
one warning ``<node>: MaterialX node '<category>' is not translated; <input> uses <fallback>``.
Hair: a ``surface`` node over a ``chiang_hair_bsdf`` becomes Mitsuba's ``hair`` BSDF (:func:`_hair`),
with ``chiang_hair_roughness``, ``chiang_hair_absorption_from_color`` and
``deon_hair_absorption_from_melanin`` evaluated as MaterialX's own GLSL library does.
Each translated material records how (:attr:`MaterialInfo.report`): the document, the surface
shader, and the fallbacks taken; the manifest lists them.
"""

from __future__ import annotations

import functools
import os
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from denoisebench.generator.usd.textures import _read_rgba, _srgb_to_linear

# Lazy imports: pxr and MaterialX, inside the functions that use them.

SURFACES = ("standard_surface", "open_pbr_surface")
_SIZES = {"float": 1, "integer": 1, "boolean": 1, "vector2": 2, "color3": 3, "vector3": 3, "color4": 4, "vector4": 4}
_LUMA = np.array([0.2722287, 0.6740818, 0.0536895], dtype=np.float32)  # MaterialX's lin_rec709 luminance


@dataclass
class Val:
    """An evaluated MaterialX value: an array (C,) for a constant, or (H, W, C) pixels with ``meta``."""

    array: np.ndarray
    meta: dict | None = None  # textures: wrap_mode, primvar, files, normalmap

    @property
    def textured(self) -> bool:
        return self.array.ndim == 3


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
# The MaterialX library and documents


@functools.lru_cache(maxsize=1)
def standard_library():
    """MaterialX's standard data library (node definitions and their defaults)."""
    import MaterialX as mx

    library = mx.createDocument()
    mx.loadLibraries(mx.getDefaultDataLibraryFolders(), mx.getDefaultDataSearchPath(), library)
    return library


@functools.lru_cache(maxsize=32)
def _document(path: str, mtime: float):
    import MaterialX as mx

    document = mx.createDocument()
    mx.readFromXmlFile(document, path)
    document.importLibrary(standard_library())
    return document


def read_document(path: str | Path):
    """A ``.mtlx`` document with the standard library imported (cached by path and mtime)."""
    path = os.path.abspath(str(path))
    return _document(path, os.path.getmtime(path))


# --------------------------------------------------------------------------------------------------
# Node views: one interface over MaterialX documents and USD shaders


def folder_file(node, folder: str) -> str:
    """The ``.mtlx`` file a node came from (its document's source URI), else its folder."""
    uri = node.getDocument().getSourceUri()
    return uri or folder


class _MxNode:
    """A node of a MaterialX document."""

    def __init__(self, node, folder: str):
        self.node = node
        self.folder = folder
        self.category = node.getCategory()
        self.type = node.getType()
        self.label = f"{os.path.basename(folder_file(node, folder))}#{node.getNamePath()}"
        self._definition = node.getNodeDef()

    def _input(self, name):
        element = self.node.getInput(name)
        # An input bound to its nodegraph's interface takes the interface input's value/connection.
        while element is not None and element.getInterfaceName():
            element = element.getInterfaceInput()
        return element

    def connection(self, name):
        element = self._input(name)
        if element is None:
            return None
        upstream = element.getConnectedNode()
        if upstream is None:
            return None
        output = element.getConnectedOutput()
        return _MxNode(upstream, self.folder), (output.getName() if output is not None else "out")

    def value(self, name):
        element = self._input(name)
        if element is not None and element.getValueString():
            return element.getValue()
        if self._definition is not None:
            default = self._definition.getActiveInput(name)
            if default is not None and default.getValueString():
                return default.getValue()
        return None

    def filename(self, name) -> tuple[str | None, str]:
        element = self._input(name)
        if element is None or not element.getValueString():
            return None, ""
        text = element.getResolvedValueString()
        if not text:
            return None, ""
        resolved = text if os.path.isabs(text) else os.path.join(self.folder, text)
        return resolved, element.getActiveColorSpace()


class _UsdNode:
    """A MaterialX node authored in USD (a ``UsdShade.Shader`` whose ``info:id`` names a nodedef)."""

    def __init__(self, shader):
        self.shader = shader
        self.label = str(shader.GetPath())
        node_id = str(shader.GetIdAttr().Get() or "")
        self._definition = standard_library().getNodeDef(node_id) if node_id else None
        self.category = self._definition.getNodeString() if self._definition is not None else node_id
        self.type = self._definition.getType() if self._definition is not None else ""

    def _producer(self, name):
        from pxr import UsdShade

        shader_input = self.shader.GetInput(name)
        if not shader_input:
            return None
        attributes = UsdShade.Utils.GetValueProducingAttributes(shader_input)
        return attributes[0] if attributes else None

    def connection(self, name):
        from pxr import UsdShade

        attribute = self._producer(name)
        if attribute is None or not UsdShade.Output.IsOutput(attribute):
            return None
        prim = attribute.GetPrim()
        if not prim.IsA(UsdShade.Shader):
            return None
        output = UsdShade.Output(attribute).GetBaseName()
        return _UsdNode(UsdShade.Shader(prim)), output

    def value(self, name):
        from pxr import UsdShade

        attribute = self._producer(name)
        if attribute is not None and not UsdShade.Output.IsOutput(attribute):
            got = attribute.Get()
            if got is not None:
                return got
        if self._definition is not None:
            default = self._definition.getActiveInput(name)
            if default is not None and default.getValueString():
                return default.getValue()
        return None

    def filename(self, name) -> tuple[str | None, str]:
        attribute = self._producer(name)
        got = attribute.Get() if attribute is not None else None
        if got is None or not getattr(got, "path", ""):
            return None, ""
        resolved = str(got.resolvedPath or "")
        space = attribute.GetColorSpace() if attribute.HasColorSpace() else ""
        return (resolved or None), str(space or "")


# --------------------------------------------------------------------------------------------------
# Pattern evaluation


def _as_array(value) -> np.ndarray | None:
    if value is None or isinstance(value, str):
        return None
    if isinstance(value, bool):
        return np.array([float(value)], dtype=np.float32)
    try:
        array = np.asarray(list(value) if not np.isscalar(value) else [value], dtype=np.float32).reshape(-1)
    except (TypeError, ValueError):
        return None
    return array if np.all(np.isfinite(array)) else None


def _channels(val: Val, count: int) -> Val:
    """Convert to ``count`` channels (MaterialX's convert rules: float broadcasts, extra channels dropped)."""
    have = val.array.shape[-1]
    if have == count:
        return val
    if have == 1:
        array = np.repeat(val.array, count, axis=-1)
    elif have > count:
        array = val.array[..., :count]
    else:
        pad = np.ones(val.array.shape[:-1] + (count - have,), dtype=np.float32)
        array = np.concatenate([val.array, pad], axis=-1)
    return Val(array, val.meta)


def _resample(array: np.ndarray, shape) -> np.ndarray:
    rows = (np.arange(shape[0]) * array.shape[0] // shape[0]).astype(np.int64)
    cols = (np.arange(shape[1]) * array.shape[1] // shape[1]).astype(np.int64)
    return array[rows][:, cols]


def _combine(function, *vals: Val) -> Val:
    """Apply ``function`` to arrays of equal channel count; textures keep their pixels (larger grid wins)."""
    textures = [v for v in vals if v.textured]
    if not textures:
        return Val(np.asarray(function(*[v.array for v in vals]), dtype=np.float32))
    grid = max((v.array.shape[:2] for v in textures), key=lambda s: s[0] * s[1])
    arrays = [
        (_resample(v.array, grid) if v.array.shape[:2] != tuple(grid) else v.array) if v.textured else v.array
        for v in vals
    ]
    meta = dict(textures[0].meta or {})
    meta["files"] = sorted({f for v in textures for f in (v.meta or {}).get("files", [])})
    meta.pop("normalmap", None)
    return Val(np.asarray(function(*arrays), dtype=np.float32), meta)


class Evaluator:
    """Evaluates pattern nodes to constants or pixels; collects warnings and texture files."""

    def __init__(self, warnings: list[str], fallbacks: list[str]):
        self.warnings = warnings
        self.fallbacks = fallbacks

    def input(self, node, name: str, size: int) -> Val | None:
        """The value of ``node``'s input ``name`` as ``size`` channels (None: no value at all)."""
        upstream = node.connection(name)
        if upstream is not None:
            got = self.output(upstream[0], upstream[1], node, name)
            if got is not None:
                return _channels(got, size)
        array = _as_array(node.value(name))
        return None if array is None else _channels(Val(array), size)

    def _fallback(self, node, name, upstream, why: str) -> None:
        own = _as_array(node.value(name))
        used = "its default" if own is None else "value " + ", ".join(f"{v:g}" for v in own)
        line = f"{upstream.label}: MaterialX node '{upstream.category}' {why}; {node.label}.{name} uses {used}"
        self.warnings.append(line)
        self.fallbacks.append(line)

    def output(self, upstream, output: str, consumer, name: str) -> Val | None:
        size = _SIZES.get(upstream.type, 3)
        category = upstream.category
        try:
            got = self._evaluate(upstream, output, size)
        except _Untranslated as error:
            self._fallback(consumer, name, error.node, error.why)
            return None
        if got is None and category != "normalmap":
            self._fallback(consumer, name, upstream, "is not translated")
        return got

    def _evaluate(self, node, output: str, size: int) -> Val | None:
        category = node.category

        def arg(name, channels=size):
            got = self.input(node, name, channels)
            if got is None:
                raise _Untranslated(node, f"has no value for '{name}'")
            return got

        if category == "constant":
            return arg("value")
        if category in ("image", "tiledimage"):
            return self._image(node, size)
        if category == "normalmap":
            encoded = arg("in", 3)
            if not encoded.textured:
                return None  # a constant normal: nothing to perturb
            scale = self.input(node, "scale", 1)
            array = encoded.array
            if scale is not None and not scale.textured and abs(float(scale.array[0]) - 1.0) > 1e-6:
                vector = array * 2.0 - 1.0
                vector[..., :2] *= float(scale.array[0])
                array = vector * 0.5 + 0.5
            return Val(np.ascontiguousarray(array, dtype=np.float32), dict(encoded.meta or {}, normalmap=True))
        binary = {
            "add": np.add,
            "subtract": np.subtract,
            "multiply": np.multiply,
            "divide": lambda a, b: a / np.where(np.abs(b) < 1e-12, 1e-12, b),
            "power": lambda a, b: np.power(np.maximum(a, 0.0), b),
            "max": np.maximum,
            "min": np.minimum,
        }
        if category in binary:
            return _combine(binary[category], arg("in1"), arg("in2"))
        if category == "mix":
            mix = self.input(node, "mix", 1)
            if mix is None:
                raise _Untranslated(node, "has no value for 'mix'")
            return _combine(lambda fg, bg, m: bg * (1.0 - m) + fg * m, arg("fg"), arg("bg"), _channels(mix, size))
        if category == "clamp":
            return _combine(np.clip, arg("in"), arg("low"), arg("high"))
        if category == "invert":
            return _combine(np.subtract, arg("amount"), arg("in"))
        if category == "absval":
            return _combine(np.abs, arg("in"))
        if category == "sqrt":
            return _combine(lambda a: np.sqrt(np.maximum(a, 0.0)), arg("in"))
        if category in ("dot", "convert"):
            got = self.input(node, "in", _SIZES.get(_input_type(node, "in"), size))
            if got is None:
                raise _Untranslated(node, "has no input")
            return _channels(got, size)
        if category == "remap":
            return _combine(
                lambda x, il, ih, ol, oh: ol + (x - il) * (oh - ol) / np.where(np.abs(ih - il) < 1e-12, 1e-12, ih - il),
                arg("in"),
                arg("inlow"),
                arg("inhigh"),
                arg("outlow"),
                arg("outhigh"),
            )
        if category == "smoothstep":

            def smooth(x, low, high):
                t = np.clip((x - low) / np.where(np.abs(high - low) < 1e-12, 1e-12, high - low), 0.0, 1.0)
                return t * t * (3.0 - 2.0 * t)

            return _combine(smooth, arg("in"), arg("low"), arg("high"))
        if category == "luminance":
            colour = arg("in", 3)
            return _channels(_combine(lambda c: (c * _LUMA).sum(-1, keepdims=True), colour), size)
        if category == "dotproduct":
            width = _SIZES.get(_input_type(node, "in1"), 3)
            return _combine(lambda a, b: (a * b).sum(-1, keepdims=True), arg("in1", width), arg("in2", width))
        if category == "extract":
            width = _SIZES.get(_input_type(node, "in"), 3)
            source = arg("in", width)
            index = int(_as_array(node.value("index"))[0]) if _as_array(node.value("index")) is not None else 0
            return _combine(lambda a: a[..., min(index, width - 1) : min(index, width - 1) + 1], source)
        if category == "separate3":
            source = arg("in", 3)
            index = {"outr": 0, "outx": 0, "outg": 1, "outy": 1, "outb": 2, "outz": 2}.get(output, 0)
            return _combine(lambda a: a[..., index : index + 1], source)
        if category == "chiang_hair_absorption_from_color":  # MaterialX's genglsl formula (Chiang et al. 2016)
            colour, beta = arg("color", 3), arg("azimuthal_roughness", 1)

            def from_colour(c, b):
                factor = 5.969 - 0.215 * b + 2.532 * b**2 - 10.73 * b**3 + 5.574 * b**4 + 0.245 * b**5
                return np.square(np.log(np.clip(c, 0.001, 1.0)) / factor)

            return _combine(from_colour, colour, _channels(beta, 3))
        if category == "deon_hair_absorption_from_melanin":  # MaterialX's genglsl formula (d'Eon et al. 2011)
            concentration, redness = arg("melanin_concentration", 1), arg("melanin_redness", 1)
            eumelanin, pheomelanin = arg("eumelanin_color", 3), arg("pheomelanin_color", 3)

            def from_melanin(m, r, eu, pheo):
                melanin = -np.log(np.maximum(1.0 - m, 1e-4))
                eu_log, pheo_log = -np.log(np.maximum(eu, 1e-6)), -np.log(np.maximum(pheo, 1e-6))
                return np.maximum(melanin * (1.0 - r) * eu_log + melanin * r * pheo_log, 0.0)

            return _combine(from_melanin, _channels(concentration, 3), _channels(redness, 3), eumelanin, pheomelanin)
        if category in ("combine2", "combine3", "combine4"):
            count = int(category[-1])
            parts = [arg(f"in{i + 1}", 1) for i in range(count)]
            return _combine(lambda *a: np.concatenate(a, axis=-1), *parts)
        if category == "swizzle":
            width = _SIZES.get(_input_type(node, "in"), 3)
            source = arg("in", width)
            pattern = str(node.value("channels") or "")
            lookup = {"r": 0, "x": 0, "g": 1, "y": 1, "b": 2, "z": 2, "a": 3, "w": 3}
            indices = [min(lookup.get(c, 0), width - 1) for c in pattern] or [0]
            return _channels(_combine(lambda a: a[..., indices], source), size)
        return None

    def _image(self, node, size: int) -> Val | None:
        path, space = node.filename("file")
        if not path:
            raise _Untranslated(node, "has no file")
        try:
            mtime = os.path.getmtime(path) if os.path.isfile(path) else 0.0
            pixels = _decoded(path, mtime, "srgb" in space.lower(), size)
        except Exception as error:
            detail = " ".join(str(error).split())[:120]
            raise _Untranslated(node, f"cannot read '{path}' ({detail})") from None
        data = pixels
        mode = str(node.value("uaddressmode") or "periodic")
        wrap = {"periodic": "repeat", "mirror": "mirror", "clamp": "clamp", "constant": "clamp"}.get(mode, "repeat")
        meta = {"wrap_mode": wrap, "files": [path], "primvar": self._primvar(node)}
        if node.category == "tiledimage":
            tiling = _as_array(node.value("uvtiling"))
            if tiling is not None and np.any(np.abs(tiling - 1.0) > 1e-6):
                meta["to_uv"] = [[float(tiling[0]), 0.0, 0.0], [0.0, float(tiling[1]), 0.0], [0.0, 0.0, 1.0]]
        return Val(data, meta)

    def _primvar(self, image) -> str | None:
        upstream = image.connection("texcoord")
        if upstream is None:
            return None
        reader = upstream[0]
        if reader.category == "geompropvalue":
            name = reader.value("geomprop")
            return str(name) if name else None
        if reader.category != "texcoord":
            line = f"{image.label}: texcoord from MaterialX node '{reader.category}' is not translated; st used"
            self.warnings.append(line)
            self.fallbacks.append(line)
        return None


@functools.lru_cache(maxsize=16)
def _decoded(path: str, mtime: float, srgb: bool, size: int) -> np.ndarray:
    """An image's first ``size`` channels as float32 (sRGB decoded when asked); shared, read-only."""
    pixels, _ = _read_rgba(path, Path(path).suffix)
    if srgb:
        pixels[..., :3] = _srgb_to_linear(pixels[..., :3])
    data = np.ascontiguousarray(pixels[..., :size], dtype=np.float32)
    data.setflags(write=False)
    return data


class _Untranslated(Exception):
    def __init__(self, node, why: str):
        super().__init__(why)
        self.node = node
        self.why = why


def _input_type(node, name: str) -> str:
    definition = getattr(node, "_definition", None)
    if definition is not None:
        element = definition.getActiveInput(name)
        if element is not None:
            return element.getType()
    return "color3"


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
    return _combine(lambda a: np.clip(a, 0.0, 1.0), val)


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
        colour = _combine(np.multiply, colour, _channels(base, 3))
    transmission = constant("transmission", 1, 0.0)
    transmission = float(np.clip(transmission, 0.0, 1.0))
    if transmission > 0:
        tint = get("transmission_color", 3) or Val(np.ones(3, dtype=np.float32))
        colour = _combine(
            lambda c, t: c * (1.0 - transmission) + np.square(t) * transmission, colour, _channels(tint, 3)
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
        radiance = _combine(np.multiply, _channels(emission, 3), emission_colour or Val(np.ones(3, np.float32)))
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
        opacity = _combine(lambda a: np.clip(a, 0.0, 1.0), opacity)
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
    node = _UsdNode(shader)
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
        hair = _hair(_MxNode(shader, str(Path(path).parent)), warnings)
        if hair is not None:
            return hair, "chiang_hair_bsdf"
    if category not in SURFACES:
        warnings.append(f"{path}: material '{name}': surface '{category}' is not translated; grey diffuse used")
        return None, category
    return _principled(_MxNode(shader, str(Path(path).parent)), warnings), category


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
