"""Opening a USD stage and mapping its space to Mitsuba's (Y-up, meters).

Transforms read from USD are row-vector ``Gf.Matrix4d`` (points multiply on the left); we store
column-vector numpy matrices (``M @ p``), so every matrix read goes through :func:`to_numpy`.
"""

from __future__ import annotations

import math
import re
from pathlib import Path

import numpy as np

from denoisebench.errors import UserInputError
from denoisebench.scenes.effects import METADATA_KEY

# Lazy imports: pxr, inside the functions that use it (generator/usd/__init__.py says why).


def open_stage(path: str | Path):
    """Open a stage read-only; a file that is missing or does not parse is a UserInputError."""
    from pxr import Tf, Usd

    path = Path(path)
    if not path.is_file():
        raise UserInputError(f"{path}: no such USD file")
    try:
        stage = Usd.Stage.Open(str(path), Usd.Stage.LoadAll)
    except Tf.ErrorException as error:
        # Tf errors read "Error in 'Function' at line N in file F : 'message'"; keep the first message.
        messages = re.findall(r" : '(.*?)'\s*(?:\n|$)", str(error), flags=re.S)
        detail = messages[0] if messages else "parse error"
        detail = detail.replace(str(path.resolve()) + ":", "line ")
        raise UserInputError(f"{path}: cannot open USD stage ({_one_line(detail)})") from None
    if stage is None:
        raise UserInputError(f"{path}: cannot open USD stage")
    return stage


def _one_line(text: str, limit: int = 200) -> str:
    text = " ".join(text.split())
    return text if len(text) <= limit else text[: limit - 1] + "…"


def to_numpy(gf_matrix) -> np.ndarray:
    """Gf.Matrix4d (row-vector convention) → 4×4 float64 column-vector matrix."""
    return np.array(gf_matrix, dtype=np.float64).reshape(4, 4).T


def stage_to_mitsuba_matrix(stage) -> np.ndarray:
    """The 4×4 map from stage space to Mitsuba world space: Z-up → Y-up, then units → meters."""
    from pxr import UsdGeom

    meters = float(UsdGeom.GetStageMetersPerUnit(stage))
    if not math.isfinite(meters) or meters <= 0:
        raise UserInputError(f"stage metersPerUnit is {meters}; it must be a positive number")
    up = UsdGeom.GetStageUpAxis(stage)
    matrix = np.diag([meters, meters, meters, 1.0])
    if up == UsdGeom.Tokens.z:
        # Rotate -90° about X: +Z (up) becomes +Y, +Y (forward) becomes -Z; right-handed both.
        rotate = np.array([[1, 0, 0, 0], [0, 0, 1, 0], [0, -1, 0, 0], [0, 0, 0, 1]], dtype=np.float64)
        matrix = matrix @ rotate
    return matrix


def stage_meters_per_unit(stage) -> float:
    from pxr import UsdGeom

    return float(UsdGeom.GetStageMetersPerUnit(stage))


#: Key under the root layer's ``customLayerData["denoisebench"]`` of the time codes to render, where
#: generate-dataset chose some of the stage's own (``--frames``, ``--time-range``).
FRAME_TIMES_KEY = "frameTimes"


def frame_range(stage) -> list[float]:
    """The frame times of the sequence: the time codes the dataset's copy lists (``frameTimes`` in
    its denoisebench metadata), else :func:`own_time_codes`."""
    chosen = (stage.GetRootLayer().customLayerData.get(METADATA_KEY, {}) or {}).get(FRAME_TIMES_KEY)
    if chosen is not None and len(chosen):
        times = [float(t) for t in chosen]
        if all(math.isfinite(t) for t in times) and times == sorted(set(times)):
            return times
        raise UserInputError(f"denoisebench {FRAME_TIMES_KEY} must be increasing finite time codes, got {chosen!r}")
    return own_time_codes(stage)


def own_time_codes(stage) -> list[float]:
    """The stage's own sequence: integer time codes from start to end (at least one)."""
    if stage.HasAuthoredTimeCodeRange():
        start, end = stage.GetStartTimeCode(), stage.GetEndTimeCode()
        if math.isfinite(start) and math.isfinite(end) and end >= start:
            return [float(t) for t in np.arange(math.ceil(start), math.floor(end) + 1)]
    return [0.0]


def check_finite(values, prim_path: str, attribute: str) -> np.ndarray:
    """Array of an attribute's values; NaN or Inf is a UserInputError naming prim and attribute."""
    array = np.asarray(values, dtype=np.float64)
    if array.size and not np.all(np.isfinite(array)):
        count = int(np.size(array) - np.count_nonzero(np.isfinite(array)))
        raise UserInputError(f"{prim_path}.{attribute} holds {count} NaN/Inf value(s)")
    return array
