"""The report's sampler part: each live sampler's spp map beside its image, and where it left pixels unsampled.

:func:`sampler_section` reads what the run kept (:mod:`denoisebench.results.sampler_maps`) into a
:class:`~.model.SamplerSection` for the renderers and results.json.

Notes
-----
* **Whose map.** A sampler's pairs (``SAMPLER+DENOISER``) share its live render, so the maps and
  counts shown are those of the sampler alone (the labels in the run's ``samplers`` config).
* **Scale.** The maps of one scene at one spp share one linear scale, from 0 spp to the largest
  count any of its samplers gave a pixel, so that they compare at a glance (:func:`~.images.spp_map_png`;
  viridis, pixels with fewer than one sample in red).
* **Unsampled pixels.** A pixel with fewer than one sample has the value 0, not an estimate, and
  its error counts against the sampler; the report lists every (sampler, scene, spp) where that
  happened, with the frames and pixels concerned.
"""

from __future__ import annotations

from denoisebench.reports import images
from denoisebench.reports.model import SamplerFrameCount, SamplerSection, SppMap, Undersampled
from denoisebench.results import sampler_maps
from denoisebench.results.records import RunRow


def sampler_section(store, run: RunRow) -> SamplerSection | None:
    """The run's live samplers (:class:`~.model.SamplerSection`), or None without samplers.

    ``frames``: one row per sampler, scene, spp and frame (samples, mean and max spp, pixels without a
    sample); ``maps``: {(sampler, scene, spp): (frame, H×W int32)}; ``scale``: {(scene, spp): top spp};
    ``undersampled``: one row per (sampler, scene, spp) that left pixels with fewer than one sample.
    """
    samplers = list((run.config or {}).get("samplers") or [])
    if not samplers:
        return None
    rows = [r for r in sampler_maps.read(store, run.run_id) if r.denoiser in samplers]
    frames, maps, scale = [], {}, {}
    for r in rows:
        frames.append(
            SamplerFrameCount(
                sampler=r.denoiser,
                scene=r.scene,
                spp=r.spp,
                frame=r.frame,
                samples=r.samples,
                mean_spp=r.mean_spp,
                max_spp=r.max_spp,
                pixels_without_samples=r.pixels_without_samples,
            )
        )
        if r.spp_map is not None:
            maps[(r.denoiser, r.scene, r.spp)] = (r.frame, r.spp_map)
            top = int(r.spp_map.max()) if r.spp_map.size else 1
            scale[(r.scene, r.spp)] = max(scale.get((r.scene, r.spp), 1), top)
    undersampled = []
    for (sampler, scene, spp), group in frame_groups(frames).items():
        hit = [f for f in group if f.pixels_without_samples > 0]
        if hit:
            undersampled.append(
                Undersampled(
                    sampler=sampler,
                    scene=scene,
                    spp=spp,
                    frames=len(group),
                    frames_affected=len(hit),
                    pixels_max=max(f.pixels_without_samples for f in hit),
                    pixels_total=sum(f.pixels_without_samples for f in hit),
                )
            )
    return SamplerSection(samplers=samplers, frames=frames, maps=maps, scale=scale, undersampled=undersampled)


def frame_groups(frames: list[SamplerFrameCount]) -> dict[tuple[str, str, int], list[SamplerFrameCount]]:
    """``frames`` by (sampler, scene, spp), in their order."""
    groups: dict[tuple[str, str, int], list[SamplerFrameCount]] = {}
    for f in frames:
        groups.setdefault((f.sampler, f.scene, f.spp), []).append(f)
    return groups


def undersampled_lines(section: SamplerSection | None) -> list[str]:
    """One sentence per (sampler, scene, spp) that left pixels with fewer than one sample."""
    if not section:
        return []
    return [
        f"sampler {u.sampler} left pixels with fewer than 1 sample in {u.scene} at {u.spp} spp: "
        f"{u.frames_affected} of {u.frames} frame(s), up to {u.pixels_max} pixel(s) per frame "
        f"({u.pixels_total} in all); their value is 0, not an estimate, and their error counts against it"
        for u in section.undersampled
    ]


def map_entry(
    section: SamplerSection | None, label: str, scene: str, spp: int, frame: int, scale: int
) -> SppMap | None:
    """The spp map of ``label`` at ``frame`` as a comparison entry's ``spp_map`` (PNG data URI and its
    numbers), or None when ``label`` is no sampler of the run or kept no map of that frame."""
    if not section or (label, scene, spp) not in section.maps:
        return None
    kept, counts = section.maps[(label, scene, spp)]
    if kept != frame:
        return None
    top = section.scale[(scene, spp)]
    png = images.spp_map_png(counts, top, scale)
    return SppMap(
        image=images.data_uri(png),
        png=png,
        top=top,
        mean=float(counts.mean()) if counts.size else 0.0,
        max=int(counts.max()) if counts.size else 0,
        min=int(counts.min()) if counts.size else 0,
        pixels_without_samples=int((counts < 1).sum()),
    )


def as_json(section: SamplerSection | None) -> dict | None:
    """results.json's ``samplers``: the samplers, their per-frame counts and the unsampled-pixel rows (no maps)."""
    if not section:
        return None
    return {
        "samplers": section.samplers,
        "frames": section.frames,
        "map_scale": [{"scene": scene, "spp": spp, "top": top} for (scene, spp), top in section.scale.items()],
        "undersampled": section.undersampled,
    }
