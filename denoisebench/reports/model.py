"""The report model: everything a run's report shows, as one typed record handed to the renderers.

:func:`~.report.build_report` makes a :class:`ReportModel`; :mod:`.report_markdown`,
:mod:`.report_html` and :func:`~.report.results_json` read its attributes.

Notes
-----
* **Read by key too.** ``model["summary"]`` and ``model.get("samplers")`` answer like the plain dict
  the model replaced, so callers written against that dict (:mod:`.formatting`, tests) keep working;
  an unknown key raises ``KeyError``.
* Images are PNG bytes or base64 data URIs; figures are (PNG bytes, SVG text) pairs.
"""

from __future__ import annotations

from dataclasses import dataclass, field, fields
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:  # annotations only: report.py imports these modules where it builds the model
    from denoisebench.analysis.equal_tables import Tables
    from denoisebench.analysis.summary import AccuracyTime, Indistinguishable, SummaryRow
    from denoisebench.analysis.time_model import TimeModel


@dataclass
class ReportModel:
    """A run's report, ready to render (module docstring)."""

    run: Any
    """The run's record from the store: run_id, dataset hash and path, config, versions, start and finish times."""
    denoisers: list
    """The run's labels as the store lists them: label, spec, kind, needs, temporal, load error, trained_on."""
    scenes: list[str]
    """The scenes scored, in the run's order."""
    spp: list[int]
    """The input spp measured, ascending."""
    scene_effects: dict[str, list[str]]
    """Per scene: the effects it declares or had inferred, sorted."""
    reference: dict
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
    effects: dict
    """Per-effect breakdown: the metric used, the effects, and each label's share of the noisy input's error."""
    flicker: dict
    """Per-frame flicker: ``spp``, ``metrics`` and ``series`` {metric: {spp: {label: [per-frame means]}}}."""
    temporal_metrics: list[str]
    """The flicker table's columns, scale-free metrics first (:func:`~.report.temporal_metric_order`)."""
    indistinguishable: list[Indistinguishable]
    """Pairs of labels whose scores the reference's noise cannot separate."""
    strips: list[dict]
    """Per scene: a crop of consecutive frames per label and the reference (PNG strip and APNG data URIs)."""
    failures: list[dict]
    """Units that did not finish: denoiser, scene, spp, error."""
    unresolved_references: dict
    """Scenes whose reference cannot resolve the headline scores (``scenes``) and whether they were ``included``."""
    not_applicable: dict[str, dict]
    """Per metric that did not apply somewhere: how many frames or sequences, and one reason."""
    comparisons: list[dict]
    """Per scene: the compared frame's images, worst-region crops and, for live samplers, their spp maps."""
    samplers: dict | None
    """Live samplers (:func:`~.report_samplers.sampler_section`): per-frame spp counts, maps, unsampled pixels; None without."""
    cvvdp_viewing: dict | None
    """cvvdp's display, pixels per degree and each scene's exposure and field of view; None when cvvdp was not measured."""
    not_applicable_detail: list[dict]
    """Per metric that did not apply: the scenes, frames and sequences concerned, and the reasons."""
    stability: dict | None
    """Hard-case stability per denoiser instance ({label: [{case, status, detail}]}); None without the suite."""
    figures: dict[str, tuple[bytes, str]]
    """Figure name → (PNG bytes, SVG text)."""
    palette: dict[str, str]
    """Label → colour, shared by every figure."""
    frames: list
    """Every frame row of the run with its metrics, floors and seconds (results.csv, results.json)."""
    sequences: list
    """Every temporal metric row of the run (results.json's ``sequence_metrics``)."""
    deciding_frames: list = field(default_factory=list)
    """Frames a plain mean would be decided by (over 10× their scene's median of the lead score):
    label, spp, scene, frame, value, median; the trimmed scene value leaves them out."""

    def __getitem__(self, key: str):
        if key not in self._names():
            raise KeyError(key)
        return getattr(self, key)

    def __contains__(self, key: str) -> bool:
        return key in self._names()

    def get(self, key: str, default=None):
        return getattr(self, key) if key in self._names() else default

    @classmethod
    def _names(cls) -> frozenset[str]:
        return frozenset(f.name for f in fields(cls))
