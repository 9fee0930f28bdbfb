"""Multi-layer OpenEXR files for frames and per-sample data (docs/architecture.md, "Buffers").

Channel names are ``layer.channel``: ``color.R/G/B``, ``diffuse.R/G/B``, ``specular.R/G/B``,
``albedo.R/G/B``, ``normal.X/Y/Z``, ``depth.Z``, ``position.X/Y/Z``, ``roughness.Y``,
``motion.X/Y``; a variance ``<name>_var`` has its base's channel names (``color_var.R``...). The
per-sample random parameters are ``pixel.X/Y``, ``lens.U/V``, ``time.T``, ``light.U/V`` and
``bounce.U/V``, the second-hit features ``position2.X/Y/Z`` and ``normal2.X/Y/Z``. A layer we do not know
gets ``C0, C1, ...`` (``Y`` when it has a single channel).

Storage type (the rule):

* **FLOAT** (float32, stored exactly) for everything by default: color, diffuse, specular, depth,
  position, motion, the random parameters and **every** variance. Radiance fireflies and
  variances overflow half (max 65504), and depth/position need more than half's 11 bits.
* **HALF** only for the bounded features ``albedo``, ``normal`` and ``roughness`` (:data:`HALF_LAYERS`;
  their documented range is [0, 1] or [−1, 1], where half's rounding error is at most 2⁻¹²
  absolute, 2⁻¹¹ relative) **and** only when every value of that layer converts to a finite half.
  A layer with a value out of half's range (a user material with a huge albedo, say) is stored
  FLOAT: nothing is ever clipped or turned into Inf. Reading returns float32 for every layer.

Determinism: the same arrays and header give the same bytes. Files are scanline images with ZIP
compression (deterministic, lossless) and increasing-Y line order; OpenEXR writes no time stamp,
and our only extra header attribute is ``denoisebench``: the canonical JSON (sorted keys) of
``header_extra``. Bytes do not depend on the number of threads.

Per-sample data goes to its own file, one part per sample index (``sample_0000``, ...), each part
with the same layers at H×W; reading stacks them back to S×H×W×C.

Writes are atomic (:mod:`.atomic`): the file is encoded in memory, written under a temporary name
in the same folder and renamed. Reading names the file in every error: missing, corrupt (not an
EXR, truncated), a channel set that does not form whole layers, or NaN/Inf in stored data
(:class:`~denoisebench.dataset.errors.DatasetError`). Writing refuses NaN/Inf (``ValueError``: a
renderer bug, not a file to keep).
"""

from __future__ import annotations

import hashlib
import io
import json
import os
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import OpenEXR

from denoisebench.dataset.atomic import atomic_write_bytes
from denoisebench.dataset.errors import DatasetError

#: Channel names of each known layer, in array order (variances use their base's names).
CHANNEL_NAMES: dict[str, tuple[str, ...]] = {
    "color": ("R", "G", "B"),
    "color_half": ("R", "G", "B"),  # a reference's half (generator.render.reference: half references)
    "diffuse": ("R", "G", "B"),
    "specular": ("R", "G", "B"),
    "albedo": ("R", "G", "B"),
    "normal": ("X", "Y", "Z"),
    "depth": ("Z",),
    "position": ("X", "Y", "Z"),
    "roughness": ("Y",),
    "motion": ("X", "Y"),
    # per-sample random parameters
    "pixel": ("X", "Y"),
    "lens": ("U", "V"),
    "time": ("T",),
    "medium": ("U",),  # the number that drew the first free flight in a medium (participating media)
    "light": ("U", "V"),
    "bounce": ("U", "V"),
    # per-sample second-hit features (where the first bounce lands)
    "position2": ("X", "Y", "Z"),
    "normal2": ("X", "Y", "Z"),
}

#: Layers stored as HALF when every value fits (never their variances).
HALF_LAYERS = frozenset({"albedo", "normal", "roughness"})

#: Header attribute holding ``header_extra`` as canonical JSON.
HEADER_KEY = "denoisebench"

COMPRESSION = OpenEXR.ZIP_COMPRESSION

#: Part name of sample ``i`` in a per-sample file.
SAMPLE_PART = "sample_{:04d}"


@dataclass(frozen=True)
class WrittenFile:
    path: Path
    sha256: str
    size: int


@dataclass(frozen=True)
class WrittenExr:
    """What :func:`write_exr` wrote: the frame file and, with per-sample data, the samples file."""

    main: WrittenFile
    samples: WrittenFile | None


# --------------------------------------------------------------------------- naming


def channel_names(layer: str, channels: int) -> tuple[str, ...]:
    """Channel names of ``layer`` (``color_var`` → R, G, B); ValueError on a wrong channel count."""
    base = layer.removesuffix("_var")
    known = CHANNEL_NAMES.get(base)
    if known is not None:
        if len(known) != channels:
            raise ValueError(f"buffer {layer!r} has {channels} channels, expected {len(known)}")
        return known
    if channels == 1:
        return ("Y",)
    if not 1 <= channels <= 10:
        raise ValueError(f"buffer {layer!r} has {channels} channels (1 to 10 supported)")
    return tuple(f"C{i}" for i in range(channels))


def storage_type(layer: str, array: np.ndarray) -> str:
    """``"half"`` or ``"float"`` for this layer's values (see the module docstring's rule)."""
    if layer not in HALF_LAYERS:
        return "float"
    with np.errstate(over="ignore"):
        fits = bool(np.isfinite(array.astype(np.float16)).all())
    return "half" if fits else "float"


def sha256_bytes(data: bytes) -> str:
    return hashlib.sha256(data).hexdigest()


def sha256_file(path: str | os.PathLike) -> str:
    digest = hashlib.sha256()
    with open(path, "rb") as handle:
        for block in iter(lambda: handle.read(1 << 20), b""):
            digest.update(block)
    return digest.hexdigest()


def canonical_json(value) -> str:
    """Sorted keys, no spaces, no NaN: the same value always gives the same text."""
    return json.dumps(value, sort_keys=True, separators=(",", ":"), ensure_ascii=True, allow_nan=False)


# --------------------------------------------------------------------------- encoding


def _check_name(layer: str) -> None:
    if not isinstance(layer, str) or not layer or "." in layer or not layer.isprintable():
        raise ValueError(f"bad buffer name {layer!r}: non-empty, printable, without '.'")


def _as_float32(layer: str, array, ndim: int, what: str) -> np.ndarray:
    array = np.asarray(array)
    if array.ndim == ndim - 1:  # allow H×W for single-channel buffers
        array = array[..., None]
    if array.ndim != ndim:
        raise ValueError(f"{what} {layer!r} has shape {array.shape}, expected {ndim} dimensions")
    if not np.issubdtype(array.dtype, np.floating) and not np.issubdtype(array.dtype, np.integer):
        raise ValueError(f"{what} {layer!r} has dtype {array.dtype}, expected floats")
    array = array.astype(np.float32, copy=False)
    bad = int(array.size - np.count_nonzero(np.isfinite(array)))
    if bad:
        raise ValueError(f"{what} {layer!r} has {bad} NaN/Inf value(s); refusing to write it")
    return array


def _channels(layer: str, array: np.ndarray) -> dict[str, np.ndarray]:
    """``{"layer.C": H×W array}`` for one H×W×C float32 array, in the layer's storage type."""
    names = channel_names(layer, array.shape[-1])
    dtype = np.float16 if storage_type(layer, array) == "half" else np.float32
    return {f"{layer}.{c}": np.ascontiguousarray(array[..., i].astype(dtype)) for i, c in enumerate(names)}


def _header(extra: dict | None) -> dict:
    header = {"compression": COMPRESSION, "type": OpenEXR.scanlineimage}
    if extra:
        header[HEADER_KEY] = canonical_json(extra)
    return header


def _to_bytes(exr_file) -> bytes:
    stream = io.BytesIO()
    exr_file.write(stream)
    return stream.getvalue()


def _alike_arrays(buffers: Mapping[str, np.ndarray], ndim: int, what: str, label: str = ""):
    """Yield ``(layer, float32 array)`` in name order, each checked as it comes: a good name, ``ndim``
    dimensions of finite numbers, and the same non-empty leading ``ndim - 1`` dimensions as the first.

    Notes
    -----
    A generator, so that what the caller does with one layer (its channel names) is checked before
    the next layer is: the first fault in name order is the one reported. ``what`` names a buffer in
    the errors and ``label`` the leading dimensions (``"S×H×W = "``).
    """
    if not buffers:
        raise ValueError(f"no {what}s to write")
    lead = None
    for layer in sorted(buffers):
        _check_name(layer)
        array = _as_float32(layer, buffers[layer], ndim, what)
        if lead is None:
            lead = array.shape[: ndim - 1]
            if min(lead) < 1:
                raise ValueError(f"{what} {layer!r} is empty ({array.shape})")
        elif array.shape[: ndim - 1] != lead:
            raise ValueError(f"{what} {layer!r} is {label}{array.shape[: ndim - 1]}, others are {lead}")
        yield layer, array


def encode_exr(buffers: Mapping[str, np.ndarray], header_extra: dict | None = None) -> bytes:
    """The bytes of one single-part multi-layer EXR holding ``buffers`` (H×W×C each)."""
    channels: dict[str, np.ndarray] = {}
    for layer, array in _alike_arrays(buffers, 3, "buffer"):
        channels.update(_channels(layer, array))
    return _to_bytes(OpenEXR.File(_header(header_extra), channels))


def encode_samples_exr(samples: Mapping[str, np.ndarray], header_extra: dict | None = None) -> bytes:
    """The bytes of a multi-part EXR: part ``i`` holds sample ``i`` of every S×H×W×C array."""
    arrays = dict(_alike_arrays(samples, 4, "per-sample buffer", "S×H×W = "))
    count = next(iter(arrays.values())).shape[0]
    # One storage type per layer for all parts, decided over all samples (parts stay alike).
    dtypes = {layer: np.float16 if storage_type(layer, a) == "half" else np.float32 for layer, a in arrays.items()}
    parts = []
    for s in range(count):
        channels = {}
        for layer, array in arrays.items():
            names = channel_names(layer, array.shape[-1])
            for i, c in enumerate(names):
                channels[f"{layer}.{c}"] = np.ascontiguousarray(array[s, :, :, i].astype(dtypes[layer]))
        header = _header(header_extra if s == 0 else None)
        parts.append(OpenEXR.Part(header, channels, SAMPLE_PART.format(s)))
    return _to_bytes(OpenEXR.File(parts))


def samples_file_for(path: str | os.PathLike) -> Path:
    """Where the per-sample file of frame file ``path`` goes: ``<folder>/samples/<name>``."""
    path = Path(path)
    return path.parent / "samples" / path.name


def write_exr(
    path: str | os.PathLike,
    buffers: Mapping[str, np.ndarray],
    per_sample: Mapping[str, np.ndarray] | None = None,
    header_extra: dict | None = None,
) -> WrittenExr:
    """Write ``buffers`` to ``path`` (and ``per_sample`` to ``samples/<name>`` beside it), atomically.

    Both files are encoded before either is written, so bad input leaves the disk untouched. The
    samples file is written first; the frame counts as done only once the caller records it.
    """
    path = Path(path)
    main_bytes = encode_exr(buffers, header_extra)
    samples_written = None
    if per_sample is not None:
        sample_bytes = encode_samples_exr(per_sample, header_extra)
        samples_target = samples_file_for(path)
        atomic_write_bytes(samples_target, sample_bytes)
        samples_written = WrittenFile(samples_target, sha256_bytes(sample_bytes), len(sample_bytes))
    atomic_write_bytes(path, main_bytes)
    return WrittenExr(WrittenFile(path, sha256_bytes(main_bytes), len(main_bytes)), samples_written)


# --------------------------------------------------------------------------- decoding


@dataclass
class ExrContents:
    """A decoded frame file: layers H×W×C float32, the ``header_extra`` dict and the file's sha256."""

    buffers: dict[str, np.ndarray]
    extra: dict
    sha256: str


@dataclass
class SamplesContents:
    """A decoded per-sample file: layers S×H×W×C float32, ``header_extra`` and sha256."""

    samples: dict[str, np.ndarray]
    extra: dict
    sha256: str


def _read_bytes(path: Path, what: str) -> bytes:
    try:
        return path.read_bytes()
    except FileNotFoundError:
        raise DatasetError(f"{what} {path} is missing") from None
    except IsADirectoryError:
        raise DatasetError(f"{what} {path} is a folder, not an EXR file") from None
    except OSError as exc:
        raise DatasetError(f"cannot read {what} {path}: {exc.strerror or exc}") from None


def _open(path: Path, data: bytes, what: str):
    if not data:
        raise DatasetError(f"{what} {path} is empty (corrupt or not an EXR file)")
    try:
        return OpenEXR.File(io.BytesIO(data), True)
    except Exception as exc:  # OpenEXR raises RuntimeError for anything unreadable
        reason = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
        raise DatasetError(f"{what} {path} is corrupt or not an EXR file ({reason})") from None


def _order(layer: str, names: list[str]) -> list[str]:
    known = CHANNEL_NAMES.get(layer.removesuffix("_var"))
    if known is not None and sorted(known) == sorted(names):
        return list(known)
    return sorted(names)


def _layers(path: Path, channels: dict, what: str) -> dict[str, np.ndarray]:
    """Group ``layer.C`` channels of one part into H×W×C float32 arrays; check them."""
    groups: dict[str, dict[str, np.ndarray]] = {}
    for full_name, channel in channels.items():
        layer, dot, chan = full_name.rpartition(".")
        if not dot:
            layer, chan = full_name, ""
        groups.setdefault(layer, {})[chan] = channel.pixels
    out = {}
    for layer in sorted(groups):
        parts = groups[layer]
        base = CHANNEL_NAMES.get(layer.removesuffix("_var"))
        if base is not None and sorted(base) != sorted(parts):
            raise DatasetError(f"{what} {path}: layer {layer!r} has channels {sorted(parts)}, expected {list(base)}")
        array = np.stack([np.asarray(parts[c], dtype=np.float32) for c in _order(layer, list(parts))], axis=-1)
        bad = int(array.size - np.count_nonzero(np.isfinite(array)))
        if bad:
            raise DatasetError(f"{what} {path}: layer {layer!r} holds {bad} NaN/Inf value(s)")
        out[layer] = array
    return out


def _extra(path: Path, header: dict, what: str) -> dict:
    text = header.get(HEADER_KEY)
    if text is None:
        return {}
    try:
        value = json.loads(text)
    except (TypeError, ValueError):
        raise DatasetError(f"{what} {path}: header attribute {HEADER_KEY!r} is not JSON") from None
    return value if isinstance(value, dict) else {}


def _check_sha(path: Path, data: bytes, expect: str | None, what: str) -> str:
    digest = sha256_bytes(data)
    if expect is not None and digest != expect:
        raise DatasetError(
            f"{what} {path} has sha256 {digest[:12]}…, the manifest says {expect[:12]}… (changed or corrupt)"
        )
    return digest


def load_exr(path: str | os.PathLike, expect_sha256: str | None = None, what: str = "EXR file") -> ExrContents:
    """Read a frame file: layers, header extra, sha256 (checked against ``expect_sha256`` if given)."""
    path = Path(path)
    data = _read_bytes(path, what)
    digest = _check_sha(path, data, expect_sha256, what)
    exr = _open(path, data, what)
    if len(exr.parts) != 1:
        raise DatasetError(f"{what} {path} has {len(exr.parts)} parts, expected 1 (a frame file)")
    part = exr.parts[0]
    return ExrContents(_layers(path, part.channels, what), _extra(path, part.header, what), digest)


def load_samples_exr(
    path: str | os.PathLike, expect_sha256: str | None = None, what: str = "samples file"
) -> SamplesContents:
    """Read a per-sample file (one part per sample) back to S×H×W×C arrays."""
    path = Path(path)
    data = _read_bytes(path, what)
    digest = _check_sha(path, data, expect_sha256, what)
    exr = _open(path, data, what)
    per_part = [_layers(path, part.channels, what) for part in exr.parts]
    names = sorted(per_part[0])
    for index, layers in enumerate(per_part):
        if sorted(layers) != names:
            raise DatasetError(f"{what} {path}: part {index} has layers {sorted(layers)}, part 0 has {names}")
    samples = {name: np.stack([layers[name] for layers in per_part], axis=0) for name in names}
    return SamplesContents(samples, _extra(path, exr.parts[0].header, what), digest)


def read_exr(path: str | os.PathLike) -> dict[str, np.ndarray]:
    """The layers of a frame file as H×W×C float32 arrays (DatasetError naming the file on trouble)."""
    return load_exr(path).buffers


def read_samples_exr(path: str | os.PathLike) -> dict[str, np.ndarray]:
    """The layers of a per-sample file as S×H×W×C float32 arrays."""
    return load_samples_exr(path).samples


def read_exr_extra(path: str | os.PathLike) -> dict:
    """The ``header_extra`` dict a frame or samples file was written with (``{}`` if none)."""
    path = Path(path)
    exr = _open(path, _read_bytes(path, "EXR file"), "EXR file")
    return _extra(path, exr.parts[0].header, "EXR file")
