"""The report model: everything a run's report shows, as one typed record handed to the renderers.

:func:`~.build.build_report` makes a :class:`ReportModel`; :mod:`.markdown`, :mod:`.html` and
:func:`~.build.results_json` read its attributes. Its parts are small frozen dataclasses, defined
here (the report's own) or where they are computed (the store's rows in :mod:`denoisebench.results.records`,
the analyses' results in :mod:`denoisebench.analysis`).

Notes
-----
* **Read by attribute only.** No part answers ``part["key"]``; results.json is written from the
  attributes (:func:`~.build.results_json`: a part becomes a JSON object with its fields as keys, in
  their order, or with the keys of its own ``as_dict``), so the field order of a part that
  results.json holds is part of the file's format.
* Images are PNG bytes or base64 data URIs; figures are (PNG bytes, SVG text) pairs.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import TYPE_CHECKING

if TYPE_CHECKING:  # annotations only: build.py imports these modules where it builds the model
    import numpy as np

    from denoisebench.analysis.accuracy import AccuracyTime
    from denoisebench.analysis.aggregate import Unresolved
    from denoisebench.analysis.equal_tables import Tables
    from denoisebench.analysis.summary import EffectBreakdown, Indistinguishable, SummaryRow
    from denoisebench.analysis.time_model import TimeModel
    from denoisebench.reports.identical import IdenticalGroup
    from denoisebench.reports.summary_screen import FirstScreen
    from denoisebench.results.records import EntryRow, FrameRow, NotApplicableCount, RunRow, SequenceRow


# --------------------------------------------------------------------------------------------------
# parts results.json holds (field order = key order in the file)


@dataclass(frozen=True, kw_only=True)
class ReferenceInfo:
    """The run's references: mean render seconds and spp, light transport, adaptive spp used and worst floor."""

    seconds: float | None
    spp: int | None
    transport: str
    """One line: ``full transport``, or the restricted scenes and who restricted them."""
    restricted: dict[str, str]
    """Scene → its restricted transport in words."""
    description: str
    """One line for the report's header: spp (adaptive range and floor) and transport."""
    spp_used: list[int] | None
    """[lowest, highest] spp the adaptive references used; None: no adaptive reference."""
    floor_max: float | None


@dataclass(frozen=True, kw_only=True)
class FlickerSection:
    """Per-frame flicker: the spp, the metrics with a series, and the series themselves."""

    spp: list[int]
    metrics: list[str]
    series: dict[str, dict[int, dict[str, list[float | None]]]]
    """{metric: {spp: {label: [mean flicker of frame 1, 2, ...] over scenes]}}}."""


@dataclass(frozen=True, kw_only=True)
class Failure:
    """A unit that did not finish."""

    denoiser: str
    scene: str
    spp: int
    error: str | None


@dataclass(frozen=True, kw_only=True)
class UnresolvedReferences:
    """Scenes whose reference cannot resolve the headline scores, and whether they were ``included``."""

    included: bool
    scenes: list[Unresolved]


@dataclass(frozen=True, kw_only=True)
class SamplerFrameCount:
    """One live-rendered frame of a sampler: its samples, mean and largest spp, pixels without a sample."""

    sampler: str
    scene: str
    spp: int
    frame: int
    samples: int
    mean_spp: float
    max_spp: int
    pixels_without_samples: int


@dataclass(frozen=True, kw_only=True)
class Undersampled:
    """A (sampler, scene, spp) that left pixels with fewer than one sample: frames and pixels concerned."""

    sampler: str
    scene: str
    spp: int
    frames: int
    frames_affected: int
    pixels_max: int
    pixels_total: int


@dataclass(frozen=True, kw_only=True)
class SamplerSection:
    """The run's live samplers (:func:`~.samplers.sampler_section`); results.json holds it without
    the maps (:func:`~.samplers.as_json`)."""

    samplers: list[str]
    frames: list[SamplerFrameCount]
    maps: dict[tuple[str, str, int], tuple[int, np.ndarray]]
    """(sampler, scene, spp) → (frame, H×W int32 spp map) of the frame the unit kept."""
    scale: dict[tuple[str, int], int]
    """(scene, spp) → the top of the maps' shared scale (largest count of any sampler there)."""
    undersampled: list[Undersampled]


@dataclass(frozen=True, kw_only=True)
class ViewingDisplay:
    """cvvdp's display (:func:`denoisebench.metrics.field.colorvideovdp.viewing_conditions`, no reference)."""

    display: str
    description: str
    resolution: list[int]
    ppd: float
    peak_cd_m2: float
    black_cd_m2: float
    ambient_lux: float
    fps: float
    target_key_cd_m2: float
    text: str


@dataclass(frozen=True, kw_only=True)
class SceneViewing:
    """cvvdp's view of one scene: frame size, its visual angle, the exposure set from its reference."""

    frame_px: list[int]
    field_deg: list[float]
    exposure: float
    key: float | None
    lit_fraction: float
    clipped_fraction: float
    text: str


@dataclass(frozen=True, kw_only=True)
class CvvdpViewing:
    """cvvdp's display once, and per scene its viewing (the one every denoiser of that scene got)."""

    display: ViewingDisplay
    scenes: dict[str, SceneViewing]


@dataclass(frozen=True, kw_only=True)
class StabilityCase:
    """One hard case of one denoiser instance (:func:`denoisebench.benchmark.stability.stability_table`)."""

    case: str
    status: str
    detail: str
    seconds: float | None = None
    """None: the suite itself failed for this denoiser (no case was timed)."""

    def as_dict(self) -> dict[str, str | float]:
        """As results.json writes it: the suite's own failure has no ``seconds``."""
        out: dict[str, str | float] = {"case": self.case, "status": self.status, "detail": self.detail}
        if self.seconds is not None:
            out["seconds"] = self.seconds
        return out


@dataclass(frozen=True, kw_only=True)
class DecidingFrame:
    """A frame over 10× its scene's median of the lead score: a plain mean would be decided by it."""

    label: str
    spp: int
    scene: str
    frame: int
    metric: str
    value: float
    median: float


# --------------------------------------------------------------------------------------------------
# parts only the renderers read


@dataclass(frozen=True, kw_only=True)
class StripEntry:
    """One row of a scene's frame strip: a label's (or the reference's) crops as a strip and an animation."""

    label: str
    kind: str
    """``input``, ``denoiser`` or ``reference``."""
    strip: str
    """PNG data URI: the crops left to right."""
    animation: str
    """APNG data URI: the crops looping in place."""


@dataclass(frozen=True, kw_only=True)
class StripWindow:
    top: int
    left: int
    side: int


@dataclass(frozen=True, kw_only=True)
class SceneStrip:
    """One scene's frame strips: the same crop of consecutive frames for every label and the reference."""

    scene: str
    spp: int
    first_frame: int
    frames: int
    window: StripWindow
    entries: list[StripEntry]
    visible: bool = True
    """False: the stored window shows almost nothing of the reference (under half its pixels visible
    after the tone map: cut by an older rule); the report says so."""


@dataclass(frozen=True, kw_only=True)
class SppMap:
    """A live sampler's spp map at the compared frame, and its numbers (:func:`~.samplers.map_entry`)."""

    image: str
    """PNG data URI."""
    png: bytes
    top: int
    """The top of the scale the map is drawn on (shared by the scene's samplers at that spp)."""
    mean: float
    max: int
    min: int
    pixels_without_samples: int


@dataclass(frozen=True, kw_only=True)
class ComparisonEntry:
    """One image of a scene's comparison: the noisy input, a denoiser or the reference."""

    label: str
    kind: str
    """``input``, ``denoiser`` or ``reference``."""
    relmse: float | None
    """The frame's relMSE against the reference (None for the reference)."""
    image: str
    """PNG data URI of the whole frame."""
    crops: list[str]
    """PNG data URIs of the worst-region crops, in the comparison's window order."""
    spp_map: SppMap | None = None
    """A live sampler's spp map of this frame; None for anything else."""


@dataclass(frozen=True, kw_only=True)
class CropWindow:
    top: int
    left: int
    size: int


@dataclass(frozen=True, kw_only=True)
class Comparison:
    """One scene's compared frame at one spp: every label's image and the reference, with worst-region crops."""

    scene: str
    spp: int
    frame: int
    why: str | None
    """Why this frame is shown beside the last one: it would decide its scene's mean (None: the last frame)."""
    width: int
    height: int
    windows: list[CropWindow]
    entries: list[ComparisonEntry]
    """The labels' entries, then the reference's (last)."""


@dataclass(frozen=True, kw_only=True)
class NotApplicableDetail:
    """A metric that did not apply somewhere: the scenes, how many frames and sequences, and why."""

    metric: str
    scenes: list[str]
    frames: int
    sequences: int
    reasons: list[str]


# --------------------------------------------------------------------------------------------------
# the model


@dataclass(kw_only=True)
class ReportModel:
    """A run's report, ready to render (module docstring)."""

    run: RunRow
    """The run's record from the store: run_id, dataset hash and path, config, versions, start and finish times."""
    denoisers: list[EntryRow]
    """The run's labels as the store lists them: label, spec, kind, needs, temporal, load error, trained_on."""
    scenes: list[str]
    """The scenes scored, in the run's order."""
    spp: list[int]
    """The input spp measured, ascending."""
    scene_effects: dict[str, list[str]]
    """Per scene: the effects it declares or had inferred, sorted."""
    reference: ReferenceInfo
    """The references: mean seconds, spp, adaptive spp used and worst floor, light transport, one-line description."""
    frame_metrics: list[str]
    """Per-frame metric names the run measured."""
    sequence_metrics: list[str]
    """Temporal (per-sequence) metric names the run measured."""
    summary: list[SummaryRow]
    """One row per label and spp: each metric combined over scenes with its interval, floor and seconds."""
    accuracy: list[AccuracyTime]
    """Accuracy-against-time panels, one per error metric shown (robust relMSE first)."""
    readings: dict[str, list[str]]
    """Per panel metric: the sentences reading it (equivalent spp, time ratios), measured rungs only."""
    time_model: TimeModel
    """Seconds at the stated resolution: fixed and per-pixel costs, machine, notes."""
    equal_tables: list[Tables]
    """Equal-time and equal-quality tables, one per lead metric."""
    verdicts: list[str]
    """Verdict sentences from the equal tables (measured rungs only)."""
    effects: EffectBreakdown
    """Per-effect breakdown: the metric used, the effects, and each label's share of the noisy input's error."""
    flicker: FlickerSection
    """Per-frame flicker: ``spp``, ``metrics`` and ``series`` {metric: {spp: {label: [per-frame means]}}}."""
    temporal_metrics: list[str]
    """The flicker table's columns, scale-free metrics first (:func:`~.build.temporal_metric_order`)."""
    indistinguishable: list[Indistinguishable]
    """Pairs of labels whose scores the reference's noise cannot separate."""
    strips: list[SceneStrip]
    """Per scene: a crop of consecutive frames per label and the reference (PNG strip and APNG data URIs)."""
    failures: list[Failure]
    """Units that did not finish: denoiser, scene, spp, error."""
    unresolved_references: UnresolvedReferences
    """Scenes whose reference cannot resolve the headline scores (``scenes``) and whether they were ``included``."""
    not_applicable: dict[str, NotApplicableCount]
    """Per metric that did not apply somewhere: how many frames or sequences, and one reason."""
    comparisons: list[Comparison]
    """Per scene and spp the last frame, then the frames that would decide a mean: images, worst-region crops
    and, for live samplers, their spp maps."""
    samplers: SamplerSection | None
    """Live samplers (:func:`~.samplers.sampler_section`): per-frame spp counts, maps, unsampled pixels; None without."""
    cvvdp_viewing: CvvdpViewing | None
    """cvvdp's display, pixels per degree and each scene's exposure and field of view; None when cvvdp was not measured."""
    not_applicable_detail: list[NotApplicableDetail]
    """Per metric that did not apply: the scenes, frames and sequences concerned, and the reasons."""
    stability: dict[str, list[StabilityCase]] | None
    """Hard-case stability per denoiser instance (label → its cases); None without the suite."""
    figures: dict[str, tuple[bytes, str]]
    """Figure name → (PNG bytes, SVG text)."""
    palette: dict[str, str]
    """Label → colour, shared by every figure."""
    frames: list[FrameRow]
    """Every frame row of the run with its metrics, floors and seconds (results.csv, results.json)."""
    sequences: list[SequenceRow]
    """Every temporal metric row of the run (results.json's ``sequence_metrics``)."""
    deciding_frames: list[DecidingFrame] = field(default_factory=list)
    """Frames a plain mean would be decided by (over 10× their scene's median of the lead score):
    label, spp, scene, frame, value, median; the trimmed scene value leaves them out."""
    first_screen: FirstScreen | None = None
    """The report's first screen (:mod:`.summary_screen`): per denoiser its best spp, equal-time error,
    equal-quality time and deciding scenes; None without an accuracy panel of the lead metric."""
    identical: list[IdenticalGroup] = field(default_factory=list)
    """Groups of denoisers whose every score and kept image agree (:mod:`.identical`)."""
