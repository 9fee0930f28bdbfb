"""MaterialX node graphs evaluated on numpy: node views, pattern nodes, MaterialX's standard library.

One interface over the two places a node comes from: a node of a ``.mtlx`` document (:class:`MxNode`)
and a MaterialX node authored in USD, a ``UsdShade.Shader`` whose ``info:id`` names a nodedef
(:class:`UsdNode`; ``NodeGraph`` connections followed with ``UsdShade.Utils.GetValueProducingAttributes``).
Both give ``category``, ``type``, ``label``, ``connection(input)``, ``value(input)`` and
``filename(input)``; unauthored inputs take the node definition's default (MaterialX's own standard
library, :func:`standard_library`).

:class:`Evaluator` evaluates pattern nodes to a :class:`Val` (a constant or pixels): ``constant``,
``image``/``tiledimage`` (colour space from the file input or document, sRGB decoded; ``float`` outputs
take the first channel), ``normalmap``, the common math nodes (add, subtract, multiply, divide, mix,
clamp, invert, power, min, max, absval, sqrt, remap, smoothstep, luminance, dotproduct, extract,
convert, swizzle, combine2/3/4, dot, separate3), and ``chiang_hair_absorption_from_color`` and
``deon_hair_absorption_from_melanin`` as MaterialX's own GLSL library computes them. A texture combined
with a constant stays a texture (its pixels computed); two textures combine pixel by pixel (the smaller
resampled, nearest). Any other node: one warning ``<node>: MaterialX node '<category>' is not
translated; <input> uses <fallback>``, also kept in the evaluator's ``fallbacks`` for the manifest.
What surfaces become is :mod:`~denoisebench.generator.usd.materialx`'s concern.
"""

from __future__ import annotations

import functools
import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from denoisebench.generator.usd.textures import _read_rgba, _srgb_to_linear

# Lazy imports: pxr and MaterialX, inside the functions that use them.

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


class MxNode:
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
        return MxNode(upstream, self.folder), (output.getName() if output is not None else "out")

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


class UsdNode:
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
        return UsdNode(UsdShade.Shader(prim)), output

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


def to_channels(val: Val, count: int) -> Val:
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


def combine(function, *vals: Val) -> Val:
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
                return to_channels(got, size)
        array = _as_array(node.value(name))
        return None if array is None else to_channels(Val(array), size)

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
            return combine(binary[category], arg("in1"), arg("in2"))
        if category == "mix":
            mix = self.input(node, "mix", 1)
            if mix is None:
                raise _Untranslated(node, "has no value for 'mix'")
            return combine(lambda fg, bg, m: bg * (1.0 - m) + fg * m, arg("fg"), arg("bg"), to_channels(mix, size))
        if category == "clamp":
            return combine(np.clip, arg("in"), arg("low"), arg("high"))
        if category == "invert":
            return combine(np.subtract, arg("amount"), arg("in"))
        if category == "absval":
            return combine(np.abs, arg("in"))
        if category == "sqrt":
            return combine(lambda a: np.sqrt(np.maximum(a, 0.0)), arg("in"))
        if category in ("dot", "convert"):
            got = self.input(node, "in", _SIZES.get(_input_type(node, "in"), size))
            if got is None:
                raise _Untranslated(node, "has no input")
            return to_channels(got, size)
        if category == "remap":
            return combine(
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

            return combine(smooth, arg("in"), arg("low"), arg("high"))
        if category == "luminance":
            colour = arg("in", 3)
            return to_channels(combine(lambda c: (c * _LUMA).sum(-1, keepdims=True), colour), size)
        if category == "dotproduct":
            width = _SIZES.get(_input_type(node, "in1"), 3)
            return combine(lambda a, b: (a * b).sum(-1, keepdims=True), arg("in1", width), arg("in2", width))
        if category == "extract":
            width = _SIZES.get(_input_type(node, "in"), 3)
            source = arg("in", width)
            index = int(_as_array(node.value("index"))[0]) if _as_array(node.value("index")) is not None else 0
            return combine(lambda a: a[..., min(index, width - 1) : min(index, width - 1) + 1], source)
        if category == "separate3":
            source = arg("in", 3)
            index = {"outr": 0, "outx": 0, "outg": 1, "outy": 1, "outb": 2, "outz": 2}.get(output, 0)
            return combine(lambda a: a[..., index : index + 1], source)
        if category == "chiang_hair_absorption_from_color":  # MaterialX's genglsl formula (Chiang et al. 2016)
            colour, beta = arg("color", 3), arg("azimuthal_roughness", 1)

            def from_colour(c, b):
                factor = 5.969 - 0.215 * b + 2.532 * b**2 - 10.73 * b**3 + 5.574 * b**4 + 0.245 * b**5
                return np.square(np.log(np.clip(c, 0.001, 1.0)) / factor)

            return combine(from_colour, colour, to_channels(beta, 3))
        if category == "deon_hair_absorption_from_melanin":  # MaterialX's genglsl formula (d'Eon et al. 2011)
            concentration, redness = arg("melanin_concentration", 1), arg("melanin_redness", 1)
            eumelanin, pheomelanin = arg("eumelanin_color", 3), arg("pheomelanin_color", 3)

            def from_melanin(m, r, eu, pheo):
                melanin = -np.log(np.maximum(1.0 - m, 1e-4))
                eu_log, pheo_log = -np.log(np.maximum(eu, 1e-6)), -np.log(np.maximum(pheo, 1e-6))
                return np.maximum(melanin * (1.0 - r) * eu_log + melanin * r * pheo_log, 0.0)

            return combine(from_melanin, to_channels(concentration, 3), to_channels(redness, 3), eumelanin, pheomelanin)
        if category in ("combine2", "combine3", "combine4"):
            count = int(category[-1])
            parts = [arg(f"in{i + 1}", 1) for i in range(count)]
            return combine(lambda *a: np.concatenate(a, axis=-1), *parts)
        if category == "swizzle":
            width = _SIZES.get(_input_type(node, "in"), 3)
            source = arg("in", width)
            pattern = str(node.value("channels") or "")
            lookup = {"r": 0, "x": 0, "g": 1, "y": 1, "b": 2, "z": 2, "a": 3, "w": 3}
            indices = [min(lookup.get(c, 0), width - 1) for c in pattern] or [0]
            return to_channels(combine(lambda a: a[..., indices], source), size)
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
