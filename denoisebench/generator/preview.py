"""A quick look at a stage: one frame's reference color from the feature renderer, tone-mapped to a PNG.

The stage is a USD file (translated by ``translate_usd``) or a Mitsuba 3 XML scene (``.xml``,
loaded by :func:`~denoisebench.generator.mitsuba_xml.load_mitsuba_xml`, as ``generate-dataset
--mitsuba`` loads it).

The preview renders with the same renderer, camera model and render plan as the dataset (camera
motion blur and thin-lens depth of field included, which Mitsuba's own sensors would not show for
an animated camera), at the spp asked for, so it shows what the dataset will contain.
Tone map: exposure set so the 99th-percentile luminance maps to 1, then x/(1+x) and the sRGB
curve (a preview is for eyes, not for metrics).
"""

from __future__ import annotations

import os
import tempfile
from pathlib import Path

import numpy as np

from denoisebench.errors import UserInputError
from denoisebench.generator.contract.render_plan import RenderOptions, make_render_plan
from denoisebench.generator.mitsuba_xml import load_mitsuba_xml
from denoisebench.generator.render.scene import build_mitsuba_scene
from denoisebench.generator.usd.translate import translate_usd

# Lazy imports: render_frame is looked up when a preview renders (tests replace it on its
# module), and PIL only where a PNG is written.


def tone_map_preview(image: np.ndarray) -> np.ndarray:
    """Linear HDR → 8-bit sRGB with auto exposure (finite input assumed; NaN/Inf become 0)."""
    image = np.nan_to_num(np.asarray(image, dtype=np.float64), nan=0.0, posinf=0.0, neginf=0.0).clip(0, None)
    luminance = image @ np.array([0.2126, 0.7152, 0.0722])
    white = np.percentile(luminance, 99) if luminance.size else 0.0
    scaled = image / white if white > 0 else image
    mapped = scaled / (1.0 + scaled) * 1.6  # brightens mid-tones; 1.0 input ≈ 0.8 after the curve
    mapped = np.clip(mapped, 0, 1)
    srgb = np.where(mapped <= 0.0031308, 12.92 * mapped, 1.055 * np.power(mapped, 1 / 2.4) - 0.055)
    return (np.clip(srgb, 0, 1) * 255 + 0.5).astype(np.uint8)


def render_preview(
    usd_path: str | Path,
    frame: int = 0,
    width: int = 256,
    height: int = 256,
    spp: int = 64,
    seed: int = 0,
    max_depth: int | None = None,
    translate_options: dict | None = None,
    before_render=None,
) -> tuple[np.ndarray, object]:
    """(linear HDR image H×W×3, translated scene) of ``usd_path`` (USD, or Mitsuba ``.xml``) at ``frame``.

    ``max_depth``: the user's transport restriction (None: the stage's own, else full transport).
    ``translate_options``: keywords of :func:`translate_usd` (camera, auto camera, default light),
    or for a ``.xml`` file those of ``load_mitsuba_xml`` (frames, auto camera).
    ``before_render(translated)`` is called before rendering starts (the CLI prints the warnings
    there, so that they are seen even when rendering fails)."""
    try:
        options = RenderOptions(max_depth=max_depth)
    except ValueError as error:
        raise UserInputError(f"--max-depth: {error}") from None
    if Path(usd_path).suffix.lower() == ".xml":
        translated, loaded = load_mitsuba_xml(usd_path, **(translate_options or {}))
    else:
        translated, loaded = translate_usd(usd_path, **(translate_options or {})), None
    if not 0 <= frame < translated.camera.frames:
        raise UserInputError(f"--frame {frame} is out of range: the stage has {translated.camera.frames} frame(s)")
    from denoisebench.generator.render.frame import render_frame

    plan = make_render_plan(translated.effects, options, stage_max_depth=translated.max_depth)
    try:
        # may add warnings (prims Mitsuba refuses); an XML scene is Mitsuba's already
        scene = loaded if loaded is not None else build_mitsuba_scene(translated, frame=frame)
    finally:
        if before_render is not None:
            before_render(translated)
    rendered = render_frame(
        scene, translated.camera, frame, plan, width=width, height=height, spp=spp, seed=seed, reference=True
    )
    return rendered.buffers["color"], translated


def write_png(image_8bit: np.ndarray, out: str | Path) -> Path:
    """Write atomically (temporary name in the same folder, then rename)."""
    from PIL import Image

    out = Path(out)
    out.parent.mkdir(parents=True, exist_ok=True)
    handle, temporary = tempfile.mkstemp(prefix=".", suffix=".png", dir=out.parent)
    os.close(handle)
    try:
        Image.fromarray(image_8bit).save(temporary, format="PNG")
        os.replace(temporary, out)
    finally:
        if os.path.exists(temporary):
            os.unlink(temporary)
    return out
