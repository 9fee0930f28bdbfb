"""Times that hold where users render: fixed and per-pixel cost of rendering and of each denoiser.

One unit: the render lines, the denoiser costs and who pays which line are read together from one run's timing
records into one :class:`TimeModel`; every time figure of a report reads that model.

A benchmark's frames are small (the demo's are 64×64 = 4096 pixels); at that size most of a
frame's seconds grow with neither pixels nor samples (kernel launches, a network's set-up, Python
calls). Scaling such a time by the pixel ratio to 1920×1080 charges that overhead 506 times. This
module separates the costs from measurements and projects them to the resolution a report states
(``run-benchmark --time-at WxH``, default 1920×1080):

* **Denoisers**: ``seconds(P, s₀) = fixed + (t₀(s₀) − fixed) · P / P₀`` at the lowest spp ``s₀``; ``t₀(s)``
  is the median measured seconds per frame at the dataset's ``P₀`` pixels and input spp ``s`` (the run's own
  calls); ``fixed`` (per call) comes from a line through that time and one more call, after the run, on a
  synthetic frame of ``--time-size`` pixels (default 1024×1024, 1 MP): the frame's buffers (and per-sample
  data) tiled up to that size (:func:`upscaled_frame`) at the lowest spp. At another spp that line is scaled
  whole by ``t₀(s) / t₀(s₀)`` (a change seen only at ``P₀`` cannot be split; capping ``fixed`` at ``t₀(s)``
  instead let load noise drop the per-pixel part: kpcn's 1080p frame at 2 spp charged its 43 ms 64×64 time).
  Where ``t₀`` at the highest spp differs from the lowest by more than the spread, the denoiser is timed at
  the larger size there too (:class:`HighestSppTiming`) and ``seconds(P, s)`` lies between the two measured
  lines, at the place ``t₀(s)`` takes between ``t₀`` at the two ends. Pitfall: a small frame's seconds mix
  fixed and per-pixel work, so a change with spp measured only at ``P₀`` cannot be split; read through one
  line it made cross_bilateral's 1080p time at 2–16 spp its 3 ms fixed cost (0.8 s measured: its 1-spp
  frames estimate their own variance per pixel, 6 ms at 64×64 against 2.5 ms).
* **Rendering**: ``seconds(P, s) = a(P) + b(P) · s``, one line per **buffer set** a render makes
  (:class:`RenderCost`): rendering more samples without a denoiser makes colour only (with its
  diffuse/specular split, :data:`~denoisebench.results.timings.COLOUR_ONLY`), a denoiser's input makes
  the buffers it reads (``benchmark.timing.render_buffers``). Each line comes from **timed renders of
  the dataset's own stage** (its first scene, frame 0, spp 1 and 16) made with that set, at the
  dataset's size and at the timing size (``benchmark.timing.probe_render``): ``b`` (per sample) and the
  offset ``a`` are each split into fixed and per-pixel parts through the two sizes. The noisy input's
  "render more" curve, and every budget of the equal-time and equal-quality tables, is the colour-only
  line; a denoiser's point is its own set's line plus its denoise seconds (:meth:`TimeModel.render_line`).
  Each pays its own set's line (:func:`_charge`), whose every measured point is the least over that set's
  renders and those of every larger set (a render of more buffers makes them too: :func:`_least_of_supersets`).
  Without those renders (``--no-render-probe``, ``--time-size none``, or the probe failed) there is one
  line, through the stored render seconds of the ladder's rungs (with nested rungs, the progressive time
  to reach each) at ``P₀``: what the dataset rendered, every buffer it holds, charged to rendering alone
  and to every denoiser alike; its per-sample cost is scaled with pixels (each sample is one camera path
  through one pixel) and its offset held fixed, which the report says.

Notes
-----
* **Which figures are projected.** Every time at a resolution other than the dataset's own is a
  projection and is marked so; within ``P₀ … P₁`` (the two measured sizes) it is interpolated,
  beyond ``P₁`` extrapolated along the measured line. Without a second size (``--time-size none``)
  nothing is projected: the report's time axis stays at the dataset's resolution and says why.
* **What cancels, and what does not.** Where both are charged the same line, rendering's offset is
  paid by "render s spp" and "render s′ spp, then denoise" alike, and comparisons of the two depend on
  ``b`` and the denoiser's time, not on how the offset is split. With a line per buffer set they differ
  by what the denoiser's buffers add: charged to the denoiser, never to rendering alone (measured on the
  renderer at 1 MP and 1 spp: features and variances cost about 3× a colour-only render, docs/time.md).
  Pitfall: a line fitted through the dataset's frames charges rendering alone for buffers it never
  needs, which pulls every time ratio toward 1.
* **Time budget.** A denoiser whose proportional estimate at the timing size exceeds
  ``budget`` seconds is timed at the largest size that fits (at least 4 × ``P₀``), or not at all;
  the record says which size was used. The timing call is made after ``reset()`` and followed by
  one, so that a temporal denoiser neither sees a frame of another size as its history nor keeps
  it.
* **Times on a busy machine.** Other processes only ever add time, so every cost is the
  **minimum** of repeated measurements: the render probe renders the stage at the dataset's size
  and at ``--time-size`` in turn (:data:`PROBE_REPEATS` rounds, interleaved, so that both sizes see
  the same load and the fixed/per-pixel split does not mix an idle size with a loaded one); each
  denoiser's timing call is repeated (:data:`TIMING_REPEATS`); the run's own per-frame seconds are
  taken by their median. The **spread** of each cost is its median over its minimum (at least
  :data:`MIN_SPREAD`): the time could plausibly be that much larger. Every ratio of a denoiser's
  time to rendering's carries it (:meth:`TimeModel.ratio_bounds`: the render and the denoise parts
  each between their minimum and minimum × spread, the render part of both sides moving together at
  each probe spp, each spp's render on its own: the lines tilt, most where they are extrapolated)
  and a time verdict is written only when it holds at both ends (``analysis.equal_tables``,
  ``analysis.accuracy.readings``). Measured on the README tour's dataset: the probe's fixed
  1080p cost was 2.4 s idle and 11 s beside other jobs with one render per point (docs/time.md).
* **Where it comes from.** :mod:`denoisebench.benchmark.timing` measures; the store keeps the
  records (:mod:`denoisebench.results.timings`, table ``run_timings``); this module only reads them.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from denoisebench.errors import UserInputError
from denoisebench.results.finite import is_finite
from denoisebench.results.names import NOISY
from denoisebench.results.timings import COLOUR_ONLY, MIN_SPREAD, PROBE_REPEATS, TIMING_REPEATS, machine

#: The resolution a report's time axis is for unless ``--time-at`` says otherwise.
DEFAULT_TIME_AT = (1920, 1080)


def parse_size(text: str | None, option: str) -> tuple[int, int] | None:
    """``"1920x1080"`` → (1920, 1080); ``"none"``/``"0"``/``""`` → None; anything else is bad input."""
    if text is None or text.strip().lower() in ("", "none", "0", "off"):
        return None
    parts = text.lower().replace("×", "x").split("x")
    try:
        width, height = (int(p) for p in parts)
    except ValueError:
        raise UserInputError(f"{option} wants WIDTHxHEIGHT such as 1920x1080, got {text!r}") from None
    if width < 1 or height < 1 or width * height > 64_000_000:
        raise UserInputError(f"{option} wants a size between 1x1 and 64 megapixels, got {text!r}")
    return width, height


def size_text(size) -> str:
    return f"{size[0]}×{size[1]}"


def line_through(points) -> tuple[float, float] | None:
    """(offset, slope) of a least-squares line through (x, y) points, offset ≥ 0 and slope ≥ 0.

    A negative offset (noise on a time that is all per-unit) refits through the origin; a negative
    slope (noise on a time that is all offset) gives slope 0 and the mean as offset. One distinct x:
    through the origin. None without a point."""
    pairs = [(float(x), float(y)) for x, y in points if is_finite(y) and x > 0]
    if not pairs:
        return None
    x = np.array([p[0] for p in pairs])
    y = np.array([p[1] for p in pairs])
    if np.ptp(x) > 0:
        slope, offset = np.polyfit(x, y, 1)
        if abs(offset) <= 1e-9 * float(np.max(np.abs(y))):  # rounding of a line through the origin
            offset = 0.0
        if slope >= 0 and offset >= 0:
            return float(offset), float(slope)
        if slope < 0:
            return float(max(np.mean(y), 0.0)), 0.0
    return 0.0, float(max(np.sum(x * y) / np.sum(x * x), 0.0))


@dataclass(kw_only=True)
class DenoiserCost:
    """One denoiser's time per frame: ``fixed`` per call plus a per-pixel part measured at ``pixels0``;
    with ``highest`` (a second timing at the ladder's highest spp), one such line at each end of the ladder."""

    label: str
    pixels0: int
    small: dict[int, float]  # spp → median measured seconds per frame at pixels0
    fixed: float | None = None  # None: no second size measured
    large_pixels: int | None = None
    large_seconds: float | None = None
    note: str = ""
    spread: float = MIN_SPREAD  # median / minimum of its timing calls (≥ MIN_SPREAD)
    highest: HighestSppTiming | None = None

    @property
    def per_megapixel(self) -> float | None:
        """Seconds per megapixel of the per-pixel part at the lowest spp (None without a second size)."""
        if self.fixed is None or not self.small:
            return None
        base = self.small[min(self.small)]
        return (base - self.fixed) / self.pixels0 * 1e6

    def small_at(self, spp: float) -> float | None:
        """Seconds per frame at ``pixels0``, linear in spp between measured spp (held beyond them)."""
        if not self.small:
            return None
        keys = sorted(self.small)
        return float(np.interp(spp, keys, [self.small[k] for k in keys]))

    def seconds(self, pixels: int, spp: float) -> float | None:
        base = self.small_at(spp)
        if base is None:
            return None
        if pixels == self.pixels0:
            return base
        if self.fixed is None:
            return None  # never scale a small frame's time by the pixel ratio alone
        high = self.highest
        low_spp = min(self.small)
        at_low = self.small[low_spp]
        low_line = self.fixed + (at_low - self.fixed) * pixels / self.pixels0
        if high is None or high.spp not in self.small:
            return low_line * base / at_low if at_low > 0 else low_line
        at_high = self.small[high.spp]
        high_line = high.fixed + (at_high - high.fixed) * pixels / self.pixels0
        weight = float(np.clip((base - at_low) / (at_high - at_low), 0.0, 1.0)) if at_high != at_low else 1.0
        return low_line + weight * (high_line - low_line)


@dataclass(frozen=True, kw_only=True)
class HighestSppTiming:
    """A denoiser's second timing, at the ladder's highest spp: the line ``fixed + per-pixel · P`` there."""

    spp: int
    pixels: int
    seconds: float
    fixed: float


@dataclass(kw_only=True)
class RenderCost:
    """Render seconds per frame ``a(P) + b(P) · spp`` of one buffer set, from renders at ``pixels0`` (the
    probe's at the dataset's size, or the ladder's own) and at the probe's larger size.

    ``buffers``: the buffer set the line renders (empty: the dataset's own renders, whatever they held)."""

    pixels0: int
    offset0: float
    per_spp0: float
    measured_spp: list[int]
    probe: dict | None = None  # {"pixels", "offset", "per_spp", "scene"}: the timed larger render
    note: str = ""
    spread: float = MIN_SPREAD  # median / minimum of the probe's renders (≥ MIN_SPREAD)
    buffers: tuple[str, ...] = ()
    borrowed: int = 0  # measured points taken from a cheaper render of more buffers

    def _linear(self, pixels: int, at0: float, at1: float | None) -> float:
        """A cost measured at pixels0 (``at0``) and at the probe's size (``at1``), as fixed + per-pixel."""
        if at1 is None or self.probe is None or self.probe["pixels"] == self.pixels0:
            return at0
        slope = max((at1 - at0) / (self.probe["pixels"] - self.pixels0), 0.0)
        fixed = max(at0 - slope * self.pixels0, 0.0)
        return fixed + slope * pixels

    def offset(self, pixels: int) -> float:
        """Per-frame seconds that do not grow with spp; held fixed without a probe."""
        return self._linear(pixels, self.offset0, None if self.probe is None else self.probe["offset"])

    def per_spp(self, pixels: int) -> float:
        """Seconds per spp: per pixel-sample, so proportional to pixels without a probe."""
        if self.probe is None:
            return self.per_spp0 * pixels / self.pixels0
        return self._linear(pixels, self.per_spp0, self.probe["per_spp"])

    def seconds(self, pixels: int, spp: float) -> float:
        return self.offset(pixels) + self.per_spp(pixels) * spp

    def scaled_seconds(self, pixels: int, spp: float, *, low: float, high: float) -> float:
        """:meth:`seconds` on the line through the probe's two renders with the one at its lower spp ``low`` times
        and the one at its higher spp ``high`` times as long (each spp is a render of its own, so each may be
        slower on its own); without probe spp the whole line ``low`` times. Never below the cheaper probe point."""
        points = (self.probe or {}).get("spp") or []
        if len(points) < 2:
            return low * self.seconds(pixels, spp)
        a, b = min(points), max(points)
        at_a, at_b = self.seconds(pixels, a), self.seconds(pixels, b)
        weight = (b - spp) / (b - a)
        return max(weight * low * at_a + (1 - weight) * high * at_b, min(at_a, at_b))

    @property
    def per_megapixel_per_spp(self) -> float:
        """Seconds per spp of a 1-megapixel frame (its fixed part included)."""
        return self.per_spp(1_000_000)

    @property
    def fixed(self) -> float:
        """Seconds per frame that grow with neither pixels nor spp (the offset's fixed part)."""
        return self.offset(0)

    @property
    def offset_per_megapixel(self) -> float:
        """Seconds per megapixel of the offset (per frame, not per spp); 0 without a probe (held fixed)."""
        return self.offset(1_000_000) - self.offset(0)

    def as_dict(self, pixels: int) -> dict:
        """The line as results.json lists it; ``pixels``: the time axis' resolution."""
        return {
            "buffers": list(self.buffers),
            "fixed_s": self.fixed,
            "seconds_per_megapixel": self.offset_per_megapixel,
            "seconds_per_megapixel_per_spp": self.per_megapixel_per_spp,
            "offset_s": self.offset(pixels),
            "seconds_per_spp": self.per_spp(pixels),
            "offset_s_at_dataset_size": self.offset0,
            "seconds_per_spp_at_dataset_size": self.per_spp0,
            "measured_spp": self.measured_spp,
            "probe": self.probe,
            "note": self.note,
            "spread": self.spread,
        }


@dataclass(kw_only=True)
class TimeModel:
    """What a report's time axis rests on: the resolution, the machine and every cost.

    ``render`` is the line rendering alone pays (the colour-only one when it was timed); ``lines`` holds every render
    line by its buffer set (``render`` among them) and ``charged`` each denoiser's set: its points are charged
    that line (:meth:`render_line`). ``timed_size``: the second size things were timed at (None: none)."""

    time_at: tuple[int, int]
    pixels0: int
    dataset_size: tuple[int, int]
    render: RenderCost | None
    denoisers: dict[str, DenoiserCost] = field(default_factory=dict)
    machine: dict = field(default_factory=dict)
    projected: bool = False  # times are at another resolution than the dataset's
    notes: list[str] = field(default_factory=list)
    lines: dict[tuple[str, ...], RenderCost] = field(default_factory=dict)
    charged: dict[str, tuple[str, ...]] = field(default_factory=dict)
    timed_size: tuple[int, int] | None = None

    @property
    def pixels(self) -> int:
        return self.time_at[0] * self.time_at[1]

    def render_line(self, label: str = NOISY) -> RenderCost | None:
        """The render line ``label``'s points are charged: rendering alone's for the noisy input (and for a
        denoiser without a line of its own), else the line of the buffers it reads."""
        if label == NOISY or label not in self.charged:
            return self.render
        return self.lines.get(self.charged[label], self.render)

    def render_seconds(self, spp: float, label: str = NOISY) -> float | None:
        """Seconds per frame of rendering ``spp`` samples with the buffers ``label`` reads (default: rendering
        alone, colour only) at the time axis' resolution."""
        line = self.render_line(label)
        return None if line is None else line.seconds(self.pixels, spp)

    def denoise_seconds(self, label: str, spp: float) -> float | None:
        """Seconds per frame of ``label`` at the time axis' resolution (0 for the noisy input)."""
        if label == NOISY:
            return 0.0
        cost = self.denoisers.get(label)
        return None if cost is None else cost.seconds(self.pixels, spp)

    def total_seconds(self, label: str, spp: float) -> float | None:
        """Render (``label``'s buffer set) + denoise seconds per frame at ``spp``."""
        render, denoise = self.render_seconds(spp, label), self.denoise_seconds(label, spp)
        return None if render is None or denoise is None else render + denoise

    def ratio_bounds(self, label: str, spp: float, render_spp: float) -> tuple[float, float] | None:
        """(least, largest) plausible ratio of ``label``'s time at ``spp`` (render + denoise) to rendering
        ``render_spp`` alone, across the measured spreads (module Notes).

        The render part of both sides moves together (one renderer, one machine; its lines timed in the same
        interleaved rounds) with the larger of the two lines' spreads, but the probe's render at each spp is a
        render of its own: each may be up to that spread slower independently, which tilts both lines
        (:meth:`RenderCost.scaled_seconds`). The bounds are the least and largest ratio over those tilts and the
        denoiser at its fastest or slowest. Pitfall: one common factor for the whole line kept its offset/per-spp
        split as measured, and a loaded run's split (the difference of two renders) flipped verdicts."""
        denoise = self.denoise_seconds(label, spp)
        mine_line, alone_line = self.render_line(label), self.render
        if denoise is None or mine_line is None or alone_line is None or not self.render_seconds(render_spp):
            return None
        render_spread = max(mine_line.spread, alone_line.spread)
        cost = self.denoisers.get(label)
        denoise_spread = cost.spread if cost is not None else 1.0
        ratios = []
        for low, high in ((1.0, 1.0), (1.0, render_spread), (render_spread, 1.0), (render_spread, render_spread)):
            mine = mine_line.scaled_seconds(self.pixels, spp, low=low, high=high)
            alone = alone_line.scaled_seconds(self.pixels, render_spp, low=low, high=high)
            ratios += [(mine + d) / alone for d in (denoise, denoise_spread * denoise) if alone > 0]
        return (min(ratios), max(ratios)) if ratios else None

    def payers(self) -> dict[tuple[str, ...], list[str]]:
        """{buffer set: the labels charged its line}, rendering alone (the noisy input) first on its line."""
        out: dict[tuple[str, ...], list[str]] = {key: [] for key in self.lines}
        if self.render is not None:
            out.setdefault(self.render.buffers, []).append(NOISY)
        for label in self.denoisers:
            line = self.render_line(label)
            if line is not None:
                out.setdefault(line.buffers, []).append(label)
        return out

    def measurement_text(self) -> str:
        """How the times were measured and how noisy they were, in one sentence for a report."""
        parts = []
        if self.render is not None:
            spreads = [line.spread for line in self.lines.values()] or [self.render.spread]
            how = (
                f"rendering: least of {self.render.probe.get('repeats', PROBE_REPEATS)} interleaved renders per point"
                f" for each of {len(self.lines)} buffer set(s)"
                if self.render.probe
                else "rendering: the dataset's own render seconds"
            )
            parts.append(f"{how}, spread ×{min(spreads):.2f}–×{max(spreads):.2f}")
        if self.denoisers:
            spreads = [c.spread for c in self.denoisers.values()]
            parts.append(
                f"denoisers: median of the run's calls and least of {TIMING_REPEATS} timing calls at the second size, "
                f"spread ×{min(spreads):.2f}–×{max(spreads):.2f}"
            )
        return (
            "Times were measured as "
            + "; ".join(parts)
            + " (spread: median over least of the repeats, at least "
            + f"×{MIN_SPREAD:g}). A time verdict is given only where it holds across these spreads."
        )

    def extrapolated_pixels(self) -> bool:
        """True when the time axis lies beyond the largest size anything was timed at."""
        sizes = [c.large_pixels for c in self.denoisers.values() if c.large_pixels]
        if self.render is not None and self.render.probe:
            sizes.append(self.render.probe["pixels"])
        return self.projected and (not sizes or self.pixels > max(sizes))

    def as_dict(self) -> dict:
        payers = self.payers()
        return {
            "time_at": list(self.time_at),
            "dataset_size": list(self.dataset_size),
            "timed_size": None if self.timed_size is None else list(self.timed_size),
            "projected": self.projected,
            "beyond_timed_sizes": self.extrapolated_pixels(),
            "machine": self.machine,
            "notes": self.notes,
            "measurement": self.measurement_text(),
            "render": None if self.render is None else self.render.as_dict(self.pixels),
            "render_lines": [
                {**line.as_dict(self.pixels), "paid_by": payers.get(key, [])} for key, line in self.lines.items()
            ],
            "denoisers": {
                label: {
                    "fixed_s_per_call": c.fixed,
                    "seconds_per_megapixel": c.per_megapixel,
                    "measured_at_dataset_size": c.small,
                    "timed_pixels": c.large_pixels,
                    "timed_seconds": c.large_seconds,
                    "timed_at_highest_spp": None
                    if c.highest is None
                    else {"spp": c.highest.spp, "pixels": c.highest.pixels, "seconds": c.highest.seconds},
                    "seconds_at_time_at": {str(s): c.seconds(self.pixels, s) for s in sorted(c.small)},
                    "render_buffers": None
                    if self.render_line(label) is None
                    else list(self.render_line(label).buffers),
                    "note": c.note,
                    "spread": c.spread,
                }
                for label, c in self.denoisers.items()
            },
        }


def _probe_line(line: dict, probe: dict, *, pixels0: int, rungs: list[int]) -> RenderCost | None:
    """One buffer set's :class:`RenderCost` from its probe record (both sizes), or None without its points."""
    large, small = line_through(line.get("points") or []), line_through(line.get("small_points") or [])
    if large is None or small is None or int(probe.get("small_pixels", 0)) != pixels0:
        return None
    width, height = int(probe["width"]), int(probe["height"])
    spp = ", ".join(str(int(p[0])) for p in line["points"])
    return RenderCost(
        pixels0=pixels0,
        offset0=small[0],
        per_spp0=small[1],
        measured_spp=rungs,
        probe={
            "pixels": width * height,
            "width": width,
            "height": height,
            "scene": probe.get("scene"),
            "offset": large[0],
            "per_spp": large[1],
            "repeats": int(probe.get("repeats", 1)),
            "spp": sorted({int(p[0]) for p in line["points"]}),
        },
        note=f"renders of {probe.get('scene')} at the dataset's size and at {width}×{height} (spp {spp})",
        spread=max(float(line.get("spread", MIN_SPREAD)), MIN_SPREAD),
        buffers=tuple(line["buffers"]),
        borrowed=int(line.get("borrowed", 0)),
    )


def _least_of_supersets(records: list[dict]) -> list[dict]:
    """The probe's line records with each measured point (size, spp) the least over the renders of that set and
    of every larger set that makes its buffers too (a render of more buffers makes them; other processes only
    add time); ``borrowed`` counts the points a larger set gave.

    Pitfall: choosing one whole line per alternative by comparing lines at one spp switched, with load, which
    line (and so which offset/per-sample shape) rendering alone paid, and verdicts flipped between an idle and
    a loaded run; a point-wise least moves continuously with every measurement and never switches shapes."""
    out = []
    for line in records:
        mine = set(line.get("buffers") or ())
        larger = [r for r in records if r is not line and mine <= set(r.get("buffers") or ())]
        new, borrowed = dict(line), 0
        for field_name in ("points", "small_points"):
            best = {int(at): float(v) for at, v in line.get(field_name) or [] if is_finite(v)}
            for other in larger:
                for at, v in other.get(field_name) or []:
                    if int(at) in best and is_finite(v) and float(v) < best[int(at)]:
                        best[int(at)], borrowed = float(v), borrowed + 1
            new[field_name] = [[at, best.get(int(at), v)] for at, v in line.get(field_name) or []]
        new["borrowed"] = borrowed
        out.append(new)
    return out


def _render_lines(data, timings: dict[str, dict], pixels0: int) -> tuple[RenderCost | None, dict, list[str]]:
    """(rendering alone's line, {buffer set: line}, notes) from the probe's lines, or from the dataset's own
    render seconds where the probe made none (one line for everything; older probes: that line's offset split)."""
    render_points = [(f.spp, f.render_seconds) for f in data.frames_of(NOISY)]
    rungs = sorted({int(s) for s, _ in render_points})
    probe = timings.get("render_probe") or {}
    lines = {}
    for line in _least_of_supersets(probe.get("lines") or []):
        cost = _probe_line(line, probe, pixels0=pixels0, rungs=rungs)
        if cost is not None:
            lines[cost.buffers] = cost
    if COLOUR_ONLY in lines:
        return lines[COLOUR_ONLY], lines, []
    fitted = line_through(render_points)
    if fitted is None:
        return None, {}, []
    dataset = tuple((timings.get("timing") or {}).get("dataset_buffers") or ())
    render = RenderCost(pixels0=pixels0, offset0=fitted[0], per_spp0=fitted[1], measured_spp=rungs, buffers=dataset)
    if probe.get("points"):  # a probe made before render lines: the dataset's buffers, one set
        legacy = _probe_line({**probe, "buffers": dataset}, probe, pixels0=pixels0, rungs=rungs)
        if legacy is not None:
            render = legacy
    if render.probe is None:
        reason = probe.get("error") or "no timed larger render"
        render.note = (
            f"per-sample cost scaled with pixels; the per-frame offset ({fitted[0]:.3g} s) held fixed ({reason})"
        )
    notes = [
        "No colour-only render was timed: rendering alone and every denoiser are charged the dataset's own "
        "renders (every buffer it holds), which overstates what rendering more samples without a denoiser costs."
    ]
    return render, {render.buffers: render}, notes


def _denoiser_costs(data, timings: dict[str, dict], pixels0: int) -> dict[str, DenoiserCost]:
    """Each denoiser's :class:`DenoiserCost` from the run's frames and its timing record."""
    costs = {}
    for label in data.labels:
        if label == NOISY:
            continue
        small = {}
        for spp in data.spp:
            values = [f.denoise_seconds for f in data.ok_frames(label, spp) if f.denoise_seconds is not None]
            if values:
                small[int(spp)] = float(np.median(values))  # a loaded moment adds to a few calls, not to all
        if not small:
            continue
        cost = DenoiserCost(label=label, pixels0=pixels0, small=small)
        record = timings.get(f"denoiser:{label}") or {}
        if record.get("seconds") is not None:
            pixels = int(record["width"]) * int(record["height"])
            line = line_through([(pixels0, small[min(small)]), (pixels, record["seconds"])])
            if line is not None and pixels > pixels0:
                cost.fixed = min(line[0], small[min(small)])
                cost.large_pixels, cost.large_seconds = pixels, float(record["seconds"])
            high = record.get("highest") or {}
            at_high = small.get(int(high.get("spp", -1)))
            if cost.fixed is not None and at_high is not None and high.get("seconds") is not None:
                pixels = int(high["width"]) * int(high["height"])
                line = line_through([(pixels0, at_high), (pixels, high["seconds"])])
                if line is not None and pixels > pixels0:
                    cost.highest = HighestSppTiming(
                        spp=int(high["spp"]), pixels=pixels, seconds=float(high["seconds"]), fixed=min(line[0], at_high)
                    )
        cost.note = record.get("note", "")
        cost.spread = max(float(record.get("spread") or MIN_SPREAD), MIN_SPREAD)
        if cost.highest is not None:  # its times between the two lines carry the larger of the two spreads
            cost.spread = max(cost.spread, float(high.get("spread") or MIN_SPREAD))
        costs[label] = cost
    return costs


def _timed_size(timings: dict[str, dict]) -> tuple[int, int] | None:
    """The second size the run was timed at: its ``timing`` record's, else (older runs) the probe's or the
    largest denoiser timing's; None when nothing was timed at a second size."""
    record = timings.get("timing") or {}
    if record.get("width"):
        return int(record["width"]), int(record["height"])
    sizes = [timings.get("render_probe") or {}] + [v for k, v in timings.items() if k.startswith("denoiser:")]
    sizes = [(int(r["width"]), int(r["height"])) for r in sizes if r.get("width") and r.get("height")]
    return max(sizes, key=lambda wh: wh[0] * wh[1]) if sizes else None


def _cheapest(lines: dict, wanted, *, pixels: int, spp: float) -> tuple[str, ...] | None:
    """The buffer set of the cheapest line (at ``pixels`` and ``spp``) whose render makes every buffer of ``wanted``."""
    fits = [key for key in lines if set(wanted) <= set(key)]
    return min(fits, key=lambda key: lines[key].seconds(pixels, spp)) if fits else None


def _charge(model: TimeModel, timings: dict[str, dict]) -> None:
    """Set ``model.render`` and ``model.charged``: rendering alone pays the colour-only line, each denoiser its own
    buffer set's line (each point already the least over its set and every larger one, :func:`_least_of_supersets`).

    A set no line was measured for pays the cheapest line that makes its buffers (at the time axis' resolution and
    the ladder's top rung); a denoiser whose record names no set, or a set no line makes, pays the dearest line
    (noted). With one line (no probe) everything pays it."""
    lines = model.lines
    if not lines:
        return
    keys = list(lines)
    top = max(model.render.measured_spp or [1]) if model.render is not None else 1
    cost = lambda key: lines[key].seconds(model.pixels, top)  # noqa: E731
    if len(keys) == 1:
        model.render, model.charged = lines[keys[0]], dict.fromkeys(model.denoisers, keys[0])
        return
    alone = COLOUR_ONLY if COLOUR_ONLY in lines else _cheapest(lines, COLOUR_ONLY, pixels=model.pixels, spp=top)
    if alone is not None:
        model.render = lines[alone]
    dearest = max(keys, key=cost)
    unlined = []
    for label in model.denoisers:
        wanted = tuple((timings.get(f"denoiser:{label}") or {}).get("buffers") or ())
        key = wanted if wanted in lines else None
        if key is None and wanted:
            key = _cheapest(lines, wanted, pixels=model.pixels, spp=top)
        if key is None:
            key = dearest
            unlined.append(label)
        model.charged[label] = key
    if unlined:
        model.notes.append(
            f"no render line makes the buffers of {', '.join(sorted(unlined))}: charged the dearest line"
        )
    borrowed = [key for key in keys if lines[key].borrowed]
    if borrowed:
        model.notes.append(
            f"{len(borrowed)} render line(s) take some points from a render of more buffers that was measured "
            "cheaper (it makes theirs too)"
        )


def build_time_model(data, timings: dict[str, dict], time_at: tuple[int, int] | None, dataset_size) -> TimeModel:
    """The run's :class:`TimeModel` from its frames (``analysis.RunData``) and stored timings.

    ``time_at`` None: :data:`DEFAULT_TIME_AT`. Without any second-size timing the model stays at the
    dataset's resolution (``projected`` False) and says so in ``notes``. Who pays which render line:
    :func:`_charge`."""
    width0, height0 = dataset_size
    pixels0 = int(width0 * height0)
    requested = tuple(time_at or DEFAULT_TIME_AT)
    render, lines, notes = _render_lines(data, timings, pixels0)
    costs = _denoiser_costs(data, timings, pixels0)
    timed_size = _timed_size(timings)
    timed = [c for c in costs.values() if c.fixed is not None]
    model = TimeModel(
        time_at=requested,
        pixels0=pixels0,
        dataset_size=(width0, height0),
        render=render,
        denoisers=costs,
        machine=timings.get("machine") or machine(),
        notes=notes,
        lines=lines,
        timed_size=timed_size,
    )
    if requested != (width0, height0):
        if costs and len(timed) < len(costs):
            missing = sorted(c.label for c in costs.values() if c.fixed is None)
            model.notes.append(
                f"not timed at a second size: {', '.join(missing)}; times stay at the dataset's "
                f"{width0}×{height0} (a small frame's time is never scaled by pixel count alone)"
            )
            model.time_at = (width0, height0)
        else:
            model.projected = True
    _charge(model, timings)
    return model
