"""UsdUVTexture → Mitsuba ``bitmap`` (plain data), read through USD's asset resolver.

What a texture node means here (UsdPreviewSurface's spec):

* ``inputs:file`` is resolved by USD (Ar), so a path inside a ``.usdz`` package
  (``pkg.usdz[textures/a.png]``) is read through ``ArResolver.OpenAsset``: its bytes go to a
  temporary file that Mitsuba's ``Bitmap`` decodes, and the decoded pixels travel as an array
  (``data``): nothing of the package is left for Mitsuba to find on disk.
* Which **output** feeds the material input: ``outputs:rgb`` (3 channels), or ``outputs:r/g/b/a``
  (one channel). A float input fed by ``outputs:rgb`` takes the red channel (the spec's rule).
  An image without alpha has a = 1; a grey image has r = g = b.
* ``sourceColorSpace``: ``sRGB`` decodes the sRGB curve (on colour channels only; alpha is always
  linear), ``raw`` does not, ``auto`` follows the input (colours sRGB, numbers raw) unless the file
  says otherwise. ``scale`` and ``bias`` (per channel, applied after decoding) are honoured.
* The ``st`` coordinates come from a ``UsdPrimvarReader_float2`` whose ``varname`` names the
  primvar (``st``, ``st0``, ``uv``, ...); the geometry reader is told which one. A
  ``UsdTransform2d`` between reader and texture (st' = R(s·st) + t, rotation in degrees) becomes
  the bitmap's ``to_uv`` matrix, conjugated by the v flip (USD's v points up the image, Mitsuba's
  down; see :func:`usd_to_mitsuba_uv_matrix`).

Pitfall: an unreadable texture (missing, corrupt, CMYK JPEG, unknown format) must never crash a
render: :func:`read_texture` returns ``None`` with one warning and the material falls back to its
input's own value. Decoding happens at translation time for that reason (Mitsuba would only fail
later, inside ``load_dict``, with a traceback).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from denoisebench.generator.image_codec import decode_image

# Lazy imports: pxr, inside the functions that use it (generator/usd/__init__.py says why).

CHANNELS = {"r": 0, "g": 1, "b": 2, "a": 3}


@dataclass
class TextureRead:
    """A decoded texture ready for Mitsuba: the bitmap dict, the primvar it reads, a label for warnings."""

    bitmap: dict
    primvar: str | None
    source: str


def _srgb_to_linear(values: np.ndarray) -> np.ndarray:
    return np.where(values <= 0.04045, values / 12.92, np.power((values + 0.055) / 1.055, 2.4))


def _input_value(shader, name, default=None):
    shader_input = shader.GetInput(name)
    if not shader_input:
        return default
    value = shader_input.Get()
    return default if value is None else value


def connected_shader(shader_input):
    """(shader, output name) feeding this input, or (None, None)."""
    from pxr import UsdShade

    if not shader_input.HasConnectedSource():
        return None, None
    sources = shader_input.GetConnectedSources()[0]
    if not sources:
        return None, None
    info = sources[0]
    return UsdShade.Shader(info.source.GetPrim()), str(info.sourceName)


def _upstream(shader, name):
    """The shader connected to ``inputs:name`` of ``shader`` (or None)."""
    shader_input = shader.GetInput(name)
    return connected_shader(shader_input)[0] if shader_input else None


def shader_id(shader) -> str:
    return str(shader.GetIdAttr().Get() or "") if shader else ""


def usd_to_mitsuba_uv_matrix(scale, rotation_deg: float, translation) -> np.ndarray:
    """3×3 map of Mitsuba uv → transformed Mitsuba uv for a UsdTransform2d (st' = R(s·st) + t).

    Mitsuba's (u, v) is USD's (s, 1 − t): with F that flip (its own inverse), the matrix is F·A·F.
    """
    angle = math.radians(float(rotation_deg))
    cos, sin = math.cos(angle), math.sin(angle)
    affine = np.array(
        [
            [cos * scale[0], -sin * scale[1], translation[0]],
            [sin * scale[0], cos * scale[1], translation[1]],
            [0.0, 0.0, 1.0],
        ]
    )
    flip = np.array([[1.0, 0.0, 0.0], [0.0, -1.0, 1.0], [0.0, 0.0, 1.0]])
    return flip @ affine @ flip


def _coordinates(texture_shader, warnings: list[str], owner: str):
    """(primvar name or None, to_uv 3×3 or None) of the ``st`` input's upstream chain."""
    node = _upstream(texture_shader, "st")
    matrix = None
    if node is not None and shader_id(node) == "UsdTransform2d":
        scale = tuple(_input_value(node, "scale", (1.0, 1.0)))
        rotation = float(_input_value(node, "rotation", 0.0))
        translation = tuple(_input_value(node, "translation", (0.0, 0.0)))
        matrix = usd_to_mitsuba_uv_matrix(scale, rotation, translation)
        node = _upstream(node, "in")
    if node is None:
        return None, matrix
    if not shader_id(node).startswith("UsdPrimvarReader"):
        warnings.append(
            f"{texture_shader.GetPath()}: st driven by '{shader_id(node)}'; the mesh's st is used on {owner}"
        )
        return None, matrix
    name = _input_value(node, "varname")
    return (str(name) if name else None), matrix


def _asset_bytes(resolved: str) -> bytes:
    """The bytes of a resolved asset, through ArResolver (works inside .usdz packages)."""
    from pxr import Ar

    handle = Ar.GetResolver().OpenAsset(Ar.ResolvedPath(resolved))
    if handle is None:
        raise OSError("the asset resolver cannot open it")
    return bytes(handle.GetBuffer())


def _read_rgba(resolved: str, fallback_suffix: str = "") -> tuple[np.ndarray, str]:
    """(RGBA pixels, file suffix) of a resolved image asset; raises whatever reading or decoding raises."""
    suffix = Path(resolved.rstrip("]").split("[")[-1]).suffix or fallback_suffix
    return _expand(decode_image(_asset_bytes(resolved), suffix)), suffix


def _expand(array: np.ndarray) -> np.ndarray:
    """Any channel count → RGBA (grey → r = g = b; no alpha → a = 1)."""
    channels = array.shape[-1]
    if channels == 1:
        rgb = np.repeat(array, 3, axis=-1)
        alpha = np.ones_like(array)
    elif channels == 2:  # grey + alpha
        rgb = np.repeat(array[..., :1], 3, axis=-1)
        alpha = array[..., 1:2]
    else:
        rgb = array[..., :3]
        alpha = array[..., 3:4] if channels >= 4 else np.ones_like(array[..., :1])
    return np.concatenate([rgb, alpha], axis=-1)


def read_texture(texture_shader, output: str, want_color: bool, warnings: list[str], owner: str) -> TextureRead | None:
    """Decode a UsdUVTexture for one material input, or None (one warning) when it cannot be used.

    Args:
        output: the texture output the input is connected to (``rgb``, ``r``, ``g``, ``b``, ``a``).
        want_color: the input is a colour (3 channels, ``auto`` colour space = sRGB); else one channel.
    """
    path = str(texture_shader.GetPath())
    file_input = texture_shader.GetInput("file")
    asset = file_input.Get() if file_input else None
    if asset is None or not asset.path:
        warnings.append(f"{path}: UsdUVTexture without inputs:file; fallback value used on {owner}")
        return None
    resolved = str(asset.resolvedPath or "")
    if not resolved:
        warnings.append(f"{path}: texture file '{asset.path}' not found; fallback value used on {owner}")
        return None
    try:
        pixels, _ = _read_rgba(resolved, Path(asset.path).suffix)
    except Exception as error:  # any decoder failure: corrupt, unknown format, CMYK, truncated
        detail = " ".join(str(error).split())[:120]
        warnings.append(f"{path}: texture '{asset.path}' cannot be read ({detail}); fallback value used on {owner}")
        return None
    space = str(_input_value(texture_shader, "sourceColorSpace", "auto"))
    channel = output if output in CHANNELS or output == "rgb" else "rgb"
    if channel != output:
        warnings.append(f"{path}: output '{output}' is not a UsdUVTexture output; rgb used on {owner}")
    decode_srgb = space == "sRGB" or (space == "auto" and want_color)
    if decode_srgb:
        pixels[..., :3] = _srgb_to_linear(pixels[..., :3])
    scale = np.asarray(_input_value(texture_shader, "scale", (1, 1, 1, 1)), dtype=np.float32)
    bias = np.asarray(_input_value(texture_shader, "bias", (0, 0, 0, 0)), dtype=np.float32)
    pixels = pixels * scale + bias
    if want_color:
        data = (
            pixels[..., :3]
            if channel == "rgb"
            else np.repeat(pixels[..., CHANNELS[channel] : CHANNELS[channel] + 1], 3, -1)
        )
    else:
        index = 0 if channel == "rgb" else CHANNELS[channel]
        data = pixels[..., index : index + 1]
    primvar, matrix = _coordinates(texture_shader, warnings, owner)
    wrap = str(_input_value(texture_shader, "wrapS", "repeat"))
    wrap_mode = {"repeat": "repeat", "mirror": "mirror", "clamp": "clamp", "black": "clamp"}.get(wrap, "repeat")
    bitmap = {
        "type": "bitmap",
        "data": np.ascontiguousarray(data, dtype=np.float32),
        "raw": True,
        "wrap_mode": wrap_mode,
        "filter_type": "bilinear",
    }
    if matrix is not None:
        bitmap["to_uv"] = matrix.tolist()
    return TextureRead(bitmap=bitmap, primvar=primvar, source=asset.path)


def read_environment(light_prim, asset, warnings: list[str]) -> np.ndarray | None:
    """A DomeLight's lat-long texture as linear float32 RGB (H×W×3), or None with one warning.

    8-bit images are sRGB-decoded, float images (EXR, HDR) taken as they are."""
    path = str(light_prim.GetPath())
    resolved = str(getattr(asset, "resolvedPath", "") or "")
    name = getattr(asset, "path", asset)
    if not resolved:
        warnings.append(f"{path}: DomeLight texture '{name}' not found; constant radiance used")
        return None
    try:
        pixels, suffix = _read_rgba(resolved)
        pixels = pixels[..., :3]
    except Exception as error:
        detail = " ".join(str(error).split())[:120]
        warnings.append(f"{path}: DomeLight texture '{name}' cannot be read ({detail}); constant radiance used")
        return None
    if suffix.lower() not in (".exr", ".hdr", ".pfm"):
        pixels = _srgb_to_linear(pixels)
    return np.ascontiguousarray(pixels, dtype=np.float32)
