"""The records of a benchmark run: what the runner measures and writes, and the rows the store reads back.

Written (made by :mod:`denoisebench.benchmark.measure` for the runner, the live sampler pairs and
the Ray executor; kept by :class:`~.store.ResultsStore` in one transaction per unit):

* :class:`FrameRecord`: one frame of a unit, its timings and metric values.
* :class:`UnitRecord`: one denoiser (or sampler × denoiser pair) on one scene's sequence at one spp.

Read (what :class:`~.store.ResultsStore` returns, one class per table):

* :class:`RunRow`, :class:`EntryRow` (a run's labels: the noisy input, its denoisers, its sampler
  pairs), :class:`UnitRow`, :class:`FrameRow`, :class:`SequenceRow`, :class:`NotApplicableRow`,
  :class:`StripRow`, and :class:`NotApplicableCount` (a metric's not-applicable rows counted);
  :class:`RunRows`: every row of one run the analyses read, loaded at once.

Notes
-----
* **Read by attribute.** A row is a frozen dataclass (``row.status``), with no key access;
  :meth:`Row.as_dict` gives the plain dict results.json writes (its keys and their order are the
  table's reading order; the sampler dimension of :class:`EntryRow` is left out, so reports made
  before it existed keep their bytes).
* **The sampler dimension.** A label of a run is the noisy input (``sampler`` and
  ``denoiser_label`` None), a denoiser on the dataset's stored inputs (``sampler`` None), a sampler's
  live image alone (``denoiser_label`` None) or a sampler × denoiser pair (both set).
"""

from __future__ import annotations

from dataclasses import dataclass, field, fields
from typing import ClassVar

import numpy as np

# --------------------------------------------------------------------------------------------------
# written


@dataclass(kw_only=True)
class FrameRecord:
    """One frame of a unit: what the runner measured."""

    frame: int
    status: str
    error: str | None
    render_seconds: float | None
    denoise_seconds: float | None
    total_seconds: float | None
    sanitized: int = 0
    metrics: dict[str, float] = field(default_factory=dict)
    floors: dict[str, float] = field(default_factory=dict)  # reference-noise floor per MSE-family metric
    ref_se: dict[str, float] = field(default_factory=dict)  # the score's standard error from the reference's noise
    not_applicable: dict[str, str] = field(default_factory=dict)  # metric → why it does not apply to this frame


@dataclass(kw_only=True)
class UnitRecord:
    """One denoiser on one scene's sequence at one spp, ready to be written in one transaction."""

    denoiser: str
    scene: str
    spp: int
    status: str
    error: str | None
    frames: list[FrameRecord]
    sequence_metrics: dict[str, float] = field(default_factory=dict)
    sequence_floors: dict[str, float] = field(default_factory=dict)
    sequence_ref_se: dict[str, float] = field(default_factory=dict)
    sequence_not_applicable: dict[str, str] = field(default_factory=dict)  # temporal metric → reason
    #: frame index → H×W×3 float32 denoised frame kept for reports: the last frame and the frame each
    #: deciding score is worst on (:data:`~denoisebench.results.names.DECIDING_SCORES`)
    images: dict[int, np.ndarray] = field(default_factory=dict)
    strip_first: int | None = None  # first frame of the strip
    strip_window: tuple[int, int, int] | None = None  # (top, left, side) of its crop
    strip: np.ndarray | None = None  # F×side×side×3 float32 crops of consecutive outputs
    sampler_frames: list = field(default_factory=list)  # live sampler units: sampler_maps.SamplerFrame per frame

    @property
    def denoise_seconds(self) -> float | None:
        values = [f.denoise_seconds for f in self.frames if f.denoise_seconds is not None]
        return float(sum(values)) if values else None

    @property
    def render_seconds(self) -> float | None:
        values = [f.render_seconds for f in self.frames if f.render_seconds is not None]
        return float(sum(values)) if values else None


# --------------------------------------------------------------------------------------------------
# read


class Row:
    """Base of the rows read back: :meth:`as_dict`, the row as results.json writes it (module Notes).

    ``_attributes_only``: fields left out of :meth:`as_dict`."""

    __slots__ = ()
    _attributes_only: ClassVar[tuple[str, ...]] = ()

    def as_dict(self) -> dict:
        """The row as a plain dict (shallow: a frame's ``metrics`` dict is the row's own)."""
        return {f.name: getattr(self, f.name) for f in fields(self) if f.name not in self._attributes_only}


@dataclass(frozen=True, slots=True, kw_only=True)
class RunRow(Row):
    """One benchmark run: its identity, what it measured (``config``) and with which software."""

    run_id: str
    dataset_hash: str
    dataset_path: str
    config: dict
    versions: dict
    created_at: str
    finished_at: str | None


@dataclass(frozen=True, slots=True, kw_only=True)
class EntryRow(Row):
    """One label of a run (a row of ``run_denoisers``): the noisy input, a denoiser or a sampler pair.

    ``sampler``: the live sampler whose image the label scores (None: the dataset's stored input);
    ``denoiser_label``: the label of the denoiser run on that image (None: none, the image as it is).
    """

    _attributes_only: ClassVar[tuple[str, ...]] = ("sampler", "denoiser_label")

    label: str
    spec: str
    kind: str
    needs: list[str]
    temporal: bool
    load_error: str | None
    trained_on: list[str]
    sampler: str | None = None
    denoiser_label: str | None = None


@dataclass(frozen=True, slots=True, kw_only=True)
class UnitRow(Row):
    """One unit: a label on one scene's sequence at one spp (seconds summed over its frames)."""

    denoiser: str
    scene: str
    spp: int
    status: str
    error: str | None
    frames: int
    frames_ok: int
    denoise_seconds: float | None
    render_seconds: float | None


@dataclass(frozen=True, slots=True, kw_only=True)
class FrameRow(Row):
    """One frame of a unit with its metric values, and the floors/ref_se of the metrics that have them."""

    denoiser: str
    scene: str
    spp: int
    frame: int
    status: str
    error: str | None
    render_seconds: float | None
    denoise_seconds: float | None
    total_seconds: float | None
    sanitized: int
    metrics: dict[str, float | None]
    floors: dict[str, float]
    ref_se: dict[str, float]


@dataclass(frozen=True, slots=True, kw_only=True)
class SequenceRow(Row):
    """One temporal metric of one unit (``floor``/``ref_se`` None without)."""

    denoiser: str
    scene: str
    spp: int
    metric: str
    value: float | None
    floor: float | None
    ref_se: float | None


@dataclass(frozen=True, slots=True, kw_only=True)
class NotApplicableRow(Row):
    """A metric that did not apply to a frame (``frame`` ≥ 0) or to a unit's sequence (``frame`` = -1)."""

    denoiser: str
    scene: str
    spp: int
    frame: int
    metric: str
    reason: str


@dataclass(frozen=True, slots=True, kw_only=True)
class StripRow(Row):
    """A unit's strip: the crop window and its F×side×side×3 float32 crops of consecutive frames."""

    first_frame: int
    top: int
    left: int
    side: int
    crops: np.ndarray


@dataclass(frozen=True, slots=True, kw_only=True)
class NotApplicableCount(Row):
    """One metric's not-applicable rows of a run: how many frames or sequences (``count``), and one reason."""

    count: int
    reason: str


@dataclass(frozen=True, kw_only=True)
class RunRows:
    """Every row of one run the analyses read (:meth:`~.store.ResultsStore.run_rows`): the run, its
    labels in the order they were added, its units, frames and temporal metric rows. The analyses
    take this and never open the store themselves."""

    run: RunRow
    entries: list[EntryRow]
    units: list[UnitRow]
    frames: list[FrameRow]
    sequences: list[SequenceRow]
