"""The report's images: side-by-side comparisons and temporal strips, read from the results store.

Notes
-----
* **Which frames.** Every scene at every input spp gets a comparison at its last frame (every unit
  keeps it); then each frame that would decide a scene's mean of a lead score gets one of its own, at
  most :data:`MAX_DECIDING_COMPARISONS`, with every label whose unit kept that frame (each unit keeps
  the frame each deciding score is worst on: ``results.names.DECIDING_SCORES``) and the noisy input
  read from the dataset where its unit did not keep it.
* **Where to look.** Crops are the two non-overlapping windows where the shown denoisers' mean relMSE
  is worst among those that show the reference (:func:`.crop_choice.crop_windows`: at least half of
  a window's pixels visible after the tone map, where any window is), so every tile shows the same
  place and none is a black patch of sky.
* A stored strip whose window shows almost nothing of the reference (cut by an older rule) is
  marked (``SceneStrip.visible``) and the report says so.
"""

from __future__ import annotations

import numpy as np

from denoisebench.analysis.summary import RunData
from denoisebench.dataset import Dataset
from denoisebench.metrics import relmse_map
from denoisebench.reports import crop_choice, images, strips
from denoisebench.reports import samplers as report_samplers
from denoisebench.reports.model import (
    Comparison,
    ComparisonEntry,
    CropWindow,
    DecidingFrame,
    SamplerSection,
    SceneStrip,
    StripEntry,
    StripWindow,
)
from denoisebench.results.crops import window_size
from denoisebench.results.names import NOISY
from denoisebench.results.store import ResultsStore


def _kind(label: str) -> str:
    """``input`` (the noisy input), ``reference`` or ``denoiser``: how an image's tile is styled."""
    return "input" if label == NOISY else ("reference" if label == "reference" else "denoiser")


#: At most this many comparisons of frames that decide a scene's mean (beyond one per scene and spp).
MAX_DECIDING_COMPARISONS = 12


def comparisons(
    store: ResultsStore,
    data: RunData,
    dataset: Dataset,
    deciding: list[DecidingFrame],
    samplers: SamplerSection | None = None,
) -> list[Comparison]:
    """Per scene and input spp: the noisy input, each denoiser and the reference at the last frame; then,
    for each frame that would decide its scene's mean of the lead score (``deciding``, at any spp; at most
    :data:`MAX_DECIDING_COMPARISONS`), the same at that frame, with every label whose unit kept it."""
    out = []
    for scene in data.scenes:
        for spp in data.spp:
            found = comparison(store, data, dataset, scene=scene, spp=spp, frame_index=None, samplers=samplers)
            if found is not None:
                out.append(found)
    seen: set[tuple[str, int, int]] = set()
    for item in deciding:
        key = (item.scene, item.spp, item.frame)
        if key in seen or len(seen) >= MAX_DECIDING_COMPARISONS:
            continue
        seen.add(key)
        why = f"{item.label}'s {item.metric} is {item.value:.3g} on this frame, against its scene median of {item.median:.3g}"
        scene, spp, frame = key
        found = comparison(store, data, dataset, scene=scene, spp=spp, frame_index=frame, samplers=samplers, why=why)
        if found is not None:
            out.append(found)
    return out


def comparison(
    store: ResultsStore,
    data: RunData,
    dataset: Dataset,
    scene: str,
    spp: int,
    frame_index: int | None,
    samplers: SamplerSection | None,
    why: str | None = None,
) -> Comparison | None:
    """One comparison at ``frame_index`` (None: the last frame, which every unit keeps), with worst-region
    crops; a live sampler's entry has its ``spp_map`` of that frame (:mod:`.samplers`). The noisy input
    comes from the dataset where its unit did not keep that frame."""
    shown: list[tuple[str, np.ndarray]] = []
    for label in data.labels:
        stored = store.image(data.run_id, label, spp=spp, scene=scene, frame=frame_index)
        if stored is None:
            continue
        frame_index = stored[0] if frame_index is None else frame_index
        if stored[0] == frame_index:
            shown.append((label, stored[1]))
    if frame_index is None or not any(label != NOISY for label, _ in shown):
        return None
    frame = dataset.frame(scene, spp, frame_index, samples=False, buffers=["color"])
    reference = frame.reference
    if NOISY in data.labels and all(label != NOISY for label, _ in shown):
        shown.insert(0, (NOISY, np.nan_to_num(np.asarray(frame.color, np.float32), nan=0.0, posinf=0.0, neginf=0.0)))
    denoised = [img for label, img in shown if label != NOISY]
    height, width = reference.shape[:2]
    size = window_size(width=width, height=height)
    windows = crop_choice.crop_windows(denoised, reference, size, count=2)
    scale = images.crop_scale(size)
    full_scale = max(1, 256 // max(reference.shape[:2]))
    entries = [
        ComparisonEntry(
            label=label,
            kind=_kind(label),
            relmse=None if label == "reference" else float(np.mean(relmse_map(img, reference))),
            image=images.data_uri(images.to_png(img, full_scale)),
            crops=[images.data_uri(images.to_png(images.crop(img, t, l, size=size), scale)) for t, l in windows],
            spp_map=report_samplers.map_entry(
                samplers, label, scene, spp=spp, frame=int(frame_index), scale=full_scale
            ),
        )
        for label, img in shown + [("reference", reference)]
    ]
    return Comparison(
        scene=scene,
        spp=spp,
        frame=int(frame_index),
        why=why,
        width=int(reference.shape[1] * full_scale),
        height=int(reference.shape[0] * full_scale),
        windows=[CropWindow(top=t, left=l, size=size) for t, l in windows],
        entries=entries,
    )


def scene_strips(store: ResultsStore, data: RunData, dataset: Dataset, spp: int) -> list[SceneStrip]:
    """Per scene: the noisy input's, each denoiser's and the reference's strip of one crop at ``spp``."""
    out = []
    for scene in data.scenes:
        found = [(label, store.strip(data.run_id, label, spp=spp, scene=scene)) for label in data.labels]
        found = [(label, strip) for label, strip in found if strip is not None]
        if not found:
            continue
        first = found[0][1]
        top, left, side, count = first.top, first.left, first.side, len(first.crops)
        same = [
            (label, st)
            for label, st in found
            if (st.top, st.left, st.side, st.first_frame) == (top, left, side, first.first_frame)
        ]
        refs = np.stack(
            [
                dataset.frame(scene, spp, first.first_frame + i, samples=False, buffers=["color"]).reference[
                    top : top + side, left : left + side
                ]
                for i in range(count)
            ]
        )
        scale = max(1, 96 // side)
        entries = [
            StripEntry(
                label=label,
                kind=_kind(label),
                strip=images.data_uri(strips.strip_png(crops, scale)),
                animation=images.data_uri(strips.strip_apng(crops, scale)),
            )
            for label, crops in [(label, st.crops) for label, st in same] + [("reference", refs)]
        ]
        out.append(
            SceneStrip(
                scene=scene,
                spp=spp,
                first_frame=first.first_frame,
                frames=count,
                window=StripWindow(top=top, left=left, side=side),
                entries=entries,
                visible=crop_choice.shows_something(refs),
            )
        )
    return out
