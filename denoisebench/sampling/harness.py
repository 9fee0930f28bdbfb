"""Drive a sampler's rounds on a frame, enforce its budget, record every round: :func:`run_sampler`.

``run_sampler(sampler, frame, budget)`` hands the sampler a :class:`RoundHandle` over ``frame``
(anything with ``width``, ``height`` and ``render_round(counts) -> RoundBuffers``: the renderer's
``ProgressiveFrame`` or :class:`~denoisebench.sampling.synthetic.SyntheticProgressiveFrame`) and
returns a :class:`SamplerResult`: the final buffers, the spp map and the rounds.

Notes
-----
* **Budget.** An spp budget allows ``round(spp · W · H)`` samples in all; the handle never renders
  more. A request over what is left is cut to exactly what is left by
  :func:`~denoisebench.sampling.allocation.allocate` (proportional to the request, never above a
  pixel's request), :attr:`RoundHandle.cut` becomes True, and the next ``render`` raises
  :class:`~denoisebench.sampling.protocol.BudgetExhausted`. A seconds budget counts render seconds
  (each round's ``RoundBuffers.seconds``) plus decision seconds (all wall time outside
  ``render_round`` from the start of ``sample`` to its return); its rounds are cut to the samples
  that fit the time left at this frame's measured samples per render second, the first round to
  one sample per pixel.
* **Decision seconds** of round ``i`` are the wall time between the return of round ``i − 1`` (or the
  start of ``sample``) and the call of round ``i``'s ``render_round``; the time after the last round
  until ``sample`` returns is :attr:`SamplerResult.final_decision_seconds`. Both are the sampler's
  cost and go into its seconds.
* **What the sampler sees** are read-only views of the renderer's arrays; the result keeps the
  renderer's own, so writing into a view (it raises) cannot change the scored image.
* **Isolation.** ``run_sampler`` runs whatever sampler object it is given; a plugin loaded through
  :func:`denoisebench.sampling.isolation.load` is an :class:`~denoisebench.sampling.isolation.IsolatedSampler`
  whose ``sample`` serves a worker's round requests with this handle, so the budget is enforced
  here either way. A sampler that raises (or whose worker exits, crashes or runs over its limits)
  is recorded (``error``), with what it had rendered.
* A sampler that renders nothing leaves zero buffers and every pixel without a sample.
* **Placed rounds**. Where the frame can place samples (the renderer's
  ``ProgressiveFrame.render_placed``), :attr:`RoundHandle.dimensions` names what a sample position
  has beyond the film ``x, y`` (``"lens"``, ``"time"``; ``()`` for a pinhole without motion blur)
  and :meth:`RoundHandle.render_placed` renders one sample at each given position, returning the
  samples' values in request order (``RoundBuffers.placed``) with the pooled pixel buffers. Each
  position is one sample of its pixel's budget; a request over what is left keeps its first rows
  (a sampler lists its positions most wanted first) and sets :attr:`RoundHandle.cut`. Frames that
  cannot place (count-only synthetic frames) have ``dimensions`` None; count rounds are
  unchanged for every sampler.
* **Reconstruction.** A sampler with a ``reconstruct(rounds)`` method (a built-in: a plugin's proxy
  forwards none) may replace the scored ``color``, ``diffuse`` and ``specular`` with its own image
  of the samples it placed (``mdas`` integrates its k-d tree); ``run_sampler`` calls it once after
  ``sample``, counts its time as decision seconds, checks shapes and finiteness (a failure is the
  sampler's error), and keeps the renderer's pixel means in :attr:`SamplerResult.pixel_means`.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np

from denoisebench.errors import one_line
from denoisebench.generator.render.placed import check_positions
from denoisebench.plugins import PluginFailure
from denoisebench.plugins.proxy import log_failure
from denoisebench.sampling.allocation import allocate
from denoisebench.sampling.protocol import Budget, BudgetExhausted, SamplerRequestError, sampler_name

#: Rounds a sampler may ask for in one frame before the harness stops it.
DEFAULT_MAX_ROUNDS = 1000


@dataclass
class RoundRecord:
    """One rendered round: samples asked for and granted, the granted map, its seconds."""

    index: int
    requested: int
    granted: int
    cut: bool
    render_seconds: float
    decision_seconds: float
    counts: np.ndarray = field(repr=False)  # H×W int32: the samples this round added

    def summary(self) -> dict:
        return {
            "index": self.index,
            "requested": self.requested,
            "granted": self.granted,
            "cut": self.cut,
            "render_seconds": self.render_seconds,
            "decision_seconds": self.decision_seconds,
        }


@dataclass
class SamplerResult:
    """What :func:`run_sampler` returns. ``spp`` is the H×W int32 map of samples per pixel.

    ``stopped`` is ``"sampler"`` (it returned with budget left), ``"budget"`` (the budget was spent
    or it asked for more and was cut), ``"round_limit"`` or ``"error"`` (it raised: ``error`` says what).
    """

    sampler: str
    budget: Budget
    buffers: dict[str, np.ndarray]
    spp: np.ndarray
    rounds: list[RoundRecord]
    stopped: str
    error: str | None
    final_decision_seconds: float
    budget_samples: int | None
    pixel_means: dict[str, np.ndarray] | None = None  # the renderer's buffers where a reconstruction replaced them
    traceback: str | None = None  # where the sampler raised (``stopped == "error"``)

    @property
    def samples(self) -> int:
        return int(self.spp.sum(dtype=np.int64))

    @property
    def mean_spp(self) -> float:
        return self.samples / max(self.spp.size, 1)

    @property
    def render_seconds(self) -> float:
        return float(sum(r.render_seconds for r in self.rounds))

    @property
    def decision_seconds(self) -> float:
        return float(sum(r.decision_seconds for r in self.rounds)) + self.final_decision_seconds

    @property
    def seconds(self) -> float:
        """Render plus decision seconds: the sampler's time for the frame."""
        return self.render_seconds + self.decision_seconds

    @property
    def pixels_without_samples(self) -> int:
        """Pixels with fewer than 1 sample: their mean is 0, not an estimate (reports say so)."""
        return int((self.spp < 1).sum())

    @property
    def cut(self) -> bool:
        return any(r.cut for r in self.rounds)

    def summary(self) -> dict:
        """JSON-ready record of the run (no arrays)."""
        return {
            "sampler": self.sampler,
            "budget": self.budget.label(),
            "budget_samples": self.budget_samples,
            "samples": self.samples,
            "mean_spp": self.mean_spp,
            "max_spp": int(self.spp.max()) if self.spp.size else 0,
            "pixels_without_samples": self.pixels_without_samples,
            "render_seconds": self.render_seconds,
            "decision_seconds": self.decision_seconds,
            "seconds": self.seconds,
            "stopped": self.stopped,
            "cut": self.cut,
            "error": self.error,
            "rounds": [r.summary() for r in self.rounds],
        }


def _read_only(round_buffers):
    """A copy of the RoundBuffers record whose arrays are read-only views of the renderer's."""

    def view(array):
        out = np.asarray(array).view()
        out.flags.writeable = False
        return out

    samples = getattr(round_buffers, "samples", None)
    out = type(round_buffers)(
        buffers={name: view(array) for name, array in round_buffers.buffers.items()},
        counts=view(round_buffers.counts),
        seconds=float(round_buffers.seconds),
        samples=None if samples is None else {name: view(array) for name, array in samples.items()},
    )
    placed = getattr(round_buffers, "placed", None)
    if placed is not None:
        out.placed = {name: view(array) for name, array in placed.items()}
    return out


class RoundHandle:
    """What a sampler drives: ``render(counts)`` renders one round; see the module Notes.

    Attributes a sampler may read: ``width``, ``height``, ``budget``, ``counts`` (H×W int32 samples
    per pixel so far), ``latest`` (the last round's read-only RoundBuffers, None before the first),
    ``cut`` (the last round was cut to the budget), ``exhausted`` (nothing is left).
    """

    def __init__(self, frame, budget: Budget, *, max_rounds: int = DEFAULT_MAX_ROUNDS, clock=time.perf_counter):
        self._frame = frame
        self.width = int(frame.width)
        self.height = int(frame.height)
        self.budget = budget
        self.max_rounds = int(max_rounds)
        self.counts = np.zeros((self.height, self.width), dtype=np.int32)
        self.latest = None
        self.cut = False
        self.exhausted = False
        self.stop_reason: str | None = None
        self.records: list[RoundRecord] = []
        self.final = None  # the renderer's own RoundBuffers of the last round
        self._clock = clock
        self._mark = clock()
        self._render_seconds = 0.0
        self._decision_seconds = 0.0
        self._total = budget.total_samples(self.width * self.height)

    @property
    def pixels(self) -> int:
        return self.width * self.height

    @property
    def spent(self) -> int:
        return int(self.counts.sum(dtype=np.int64))

    def seconds_left(self) -> float | None:
        """Seconds left of a seconds budget (decision time so far included); None for an spp budget."""
        if self.budget.seconds is None:
            return None
        used = self._render_seconds + self._decision_seconds + (self._clock() - self._mark)
        return self.budget.seconds - used

    def remaining_samples(self) -> int:
        """Samples the next round may have: exact for spp budgets, an estimate for seconds budgets."""
        if self.exhausted:
            return 0
        if self._total is not None:
            return max(self._total - self.spent, 0)
        left = self.seconds_left()
        if not self.records:
            return self.pixels if left > 0 else 0  # the probe round: one sample per pixel
        rate = self.spent / max(self._render_seconds, 1e-9)
        return max(int(rate * max(left, 0.0)), 0)

    def _validate(self, counts) -> np.ndarray:
        array = np.asarray(counts)
        if array.shape != (self.height, self.width):
            raise SamplerRequestError(f"a round is an H×W = {self.height}×{self.width} map, got shape {array.shape}")
        if array.dtype.kind not in "iuf" or array.dtype == np.bool_:
            raise SamplerRequestError(f"a round's counts must be integers, got dtype {array.dtype}")
        if array.dtype.kind == "f":
            if not np.isfinite(array).all() or (array != np.round(array)).any():
                raise SamplerRequestError("a round's counts must be finite whole numbers")
        if (array < 0).any():
            raise SamplerRequestError("a round's counts must be non-negative")
        array = array.astype(np.int64)
        if array.sum() == 0:
            raise SamplerRequestError("a round with no samples (return from sample() to stop)")
        return array

    def render(self, counts):
        """Render ``counts`` more samples per pixel (cut to the budget); the accumulated RoundBuffers."""
        if self.exhausted:
            raise BudgetExhausted(f"the budget of {self.budget.label()} is spent ({self.spent} samples rendered)")
        if len(self.records) >= self.max_rounds:
            self.stop_reason = "round_limit"
            raise BudgetExhausted(f"the round limit ({self.max_rounds}) is reached")
        request = self._validate(counts)
        requested = int(request.sum())
        left = self.remaining_samples()
        if left <= 0:
            self.exhausted = True
            raise BudgetExhausted(f"the budget of {self.budget.label()} is spent ({self.spent} samples rendered)")
        granted = request if requested <= left else allocate(request, left)
        cut = requested > left
        granted32 = granted.astype(np.int32)
        before_render = self._clock()
        decision = before_render - self._mark
        round_buffers = self._frame.render_round(granted32)
        self._mark = self._clock()
        seconds = float(round_buffers.seconds)
        return self._record(requested, int(granted.sum()), cut, seconds, decision, granted32, round_buffers)

    @property
    def dimensions(self) -> tuple[str, ...] | None:
        """Placement dimensions beyond film x, y (``"lens"``, ``"time"``), or None where the frame cannot place."""
        if not callable(getattr(self._frame, "render_placed", None)):
            return None
        return tuple(getattr(self._frame, "placement_dimensions", ()))

    def render_placed(self, film, lens=None, time=None):
        """Render one sample at each position (module Notes, "Placed rounds"); the accumulated RoundBuffers.

        ``film`` N×2 film positions in pixels (``x`` in [0, W), ``y`` in [0, H)), ``lens`` N×2 and
        ``time`` N in [0, 1), each given exactly when it is one of :attr:`dimensions`. Cut to the
        budget by keeping the first rows.
        """
        if self.dimensions is None:
            raise SamplerRequestError("this frame cannot place samples (RoundHandle.dimensions is None)")
        if self.exhausted:
            raise BudgetExhausted(f"the budget of {self.budget.label()} is spent ({self.spent} samples rendered)")
        if len(self.records) >= self.max_rounds:
            self.stop_reason = "round_limit"
            raise BudgetExhausted(f"the round limit ({self.max_rounds}) is reached")
        try:
            film, lens, time = check_positions(
                film, lens, time, width=self.width, height=self.height, dimensions=self.dimensions
            )
        except ValueError as error:
            raise SamplerRequestError(str(error)) from None
        requested = film.shape[0]
        left = self.remaining_samples()
        if left <= 0:
            self.exhausted = True
            raise BudgetExhausted(f"the budget of {self.budget.label()} is spent ({self.spent} samples rendered)")
        cut = requested > left
        if cut:
            film = film[:left]
            lens = None if lens is None else lens[:left]
            time = None if time is None else time[:left]
        pixel = np.floor(film[:, 1]).astype(np.int64) * self.width + np.floor(film[:, 0]).astype(np.int64)
        granted32 = np.bincount(pixel, minlength=self.pixels).reshape(self.height, self.width).astype(np.int32)
        before_render = self._clock()
        decision = before_render - self._mark
        round_buffers = self._frame.render_placed(film, lens, time)
        self._mark = self._clock()
        seconds = float(round_buffers.seconds)
        return self._record(requested, int(film.shape[0]), cut, seconds, decision, granted32, round_buffers)

    def _record(
        self, requested, granted_total: int, cut: bool, seconds: float, decision: float, granted32, round_buffers
    ):
        """Book one rendered round (count or placed): clocks, counts, its record, the budget; the read-only buffers."""
        self._render_seconds += seconds
        self._decision_seconds += decision
        self.counts = self.counts + granted32
        self.records.append(RoundRecord(len(self.records), requested, granted_total, cut, seconds, decision, granted32))
        self.final = round_buffers
        self.cut = cut
        if self._total is not None:
            self.exhausted = self.spent >= self._total
        elif cut and len(self.records) > 1:
            self.exhausted = True
        self.latest = _read_only(round_buffers)
        return self.latest

    def finish(self) -> float:
        """Stop the clock: the decision seconds since the last round."""
        return self._clock() - self._mark


def run_sampler(
    sampler, frame, budget: Budget, *, max_rounds: int = DEFAULT_MAX_ROUNDS, clock=time.perf_counter
) -> SamplerResult:
    """Let ``sampler`` spend ``budget`` on ``frame``; its buffers, spp map and rounds (module docstring).

    ``clock`` (seconds, monotonic) times the decisions; tests pass a fake one.
    """
    name = sampler_name(sampler)
    handle = RoundHandle(frame, budget, max_rounds=max_rounds, clock=clock)
    error = trace = None
    stopped = "sampler"
    try:
        sampler.sample(budget, handle)
    except BudgetExhausted:
        stopped = handle.stop_reason or "budget"
    except Exception as failure:  # noqa: BLE001 - a failing sampler is recorded, its rounds kept
        error = str(failure) if isinstance(failure, PluginFailure) else one_line(failure)  # a worker's: one line
        stopped = "error"
        trace = log_failure("sampler", name, f"a {handle.width}x{handle.height} frame", error, failure)
    if stopped == "sampler" and handle.exhausted:
        stopped = "budget"
    if handle.final is not None:
        buffers = dict(handle.final.buffers)
    else:
        zeros = np.zeros((handle.height, handle.width, 3), dtype=np.float32)
        buffers = {"color": zeros, "color_var": zeros.copy()}
    pixel_means = None
    reconstruct = getattr(sampler, "reconstruct", None)
    if error is None and handle.final is not None and callable(reconstruct):
        try:
            image = _checked_reconstruction(reconstruct(handle), buffers)
        except Exception as failure:  # noqa: BLE001 - a failing reconstruction is the sampler's error
            error, stopped = one_line(failure), "error"
        else:
            if image:
                pixel_means, buffers = buffers, {**buffers, **image}
    final_decision = handle.finish()
    return SamplerResult(
        sampler=name,
        budget=budget,
        buffers=buffers,
        spp=handle.counts.copy(),
        rounds=handle.records,
        stopped=stopped,
        error=error,
        final_decision_seconds=final_decision,
        budget_samples=handle._total,
        pixel_means=pixel_means,
        traceback=trace,
    )


#: Buffers a sampler's reconstruction may replace.
RECONSTRUCTED = ("color", "diffuse", "specular")


def _checked_reconstruction(image, buffers: dict) -> dict:
    """``reconstruct``'s result (None, or name → H×W×3 for :data:`RECONSTRUCTED`) as float32; ValueError if malformed."""
    if image is None:
        return {}
    if not isinstance(image, dict) or not image or not set(image) <= set(RECONSTRUCTED):
        raise ValueError(f"a reconstruction is a dict of some of {', '.join(RECONSTRUCTED)}")
    out = {}
    for name, array in image.items():
        array = np.asarray(array, dtype=np.float32)
        if array.shape != buffers["color"].shape or not np.isfinite(array).all():
            raise ValueError(f"reconstructed {name} must be finite and shaped {buffers['color'].shape}")
        out[name] = array
    return out
