"""The hard-case suite: inputs that break careless denoisers, and what passing means.

Every case is a short sequence of synthetic frames (:mod:`.synthetic`) with per-sample data, so a
denoiser that needs ``samples`` (RPF) runs on it as well as one that reads buffers. Cases:

==================  =================================================================================
fireflies           isolated samples of 1e5–1e6 in an ordinary frame (means recomputed from samples)
black_frame         every buffer and sample zero
zero_albedo         albedo zero everywhere (a demodulating denoiser must not divide by it)
dynamic_range       colour scaled by a horizontal ramp from 1e-6 to 1e6
nan_inf             NaN and ±Inf injected into color, albedo, normal and depth (means and samples);
                    the runner sanitises and counts them, and the case also requires the count
constant_features   every feature constant over the frame (a guide that carries no information)
one_spp             one sample per pixel (all variances zero)
odd_size            67×45 pixels
tiny                3×3 pixels
one_frame_sequence  a sequence of one frame (temporal denoisers: reset, then a single frame)
==================  =================================================================================

A case **passes** when every frame's output is (checked by the runner) a finite H×W×3 float32
array, is non-negative, and has a robust mean within a factor :data:`ENERGY_FACTOR` of the
input's robust mean. The robust mean is the mean after clipping each array at its own
:data:`ROBUST_PERCENTILE`-th percentile (a winsorised mean), so that isolated fireflies do not
decide the scale of either side: identity passes, a filter that spreads a firefly over its
neighbourhood or darkens the frame fails. When the input's robust mean is 0 (the black frame)
the output's must be at most :data:`ABSOLUTE_TOLERANCE`.

A failing case says in one line what it tests and what usually fixes it (:attr:`CaseResult.hint`:
the case's own :attr:`HardCase.hint`, or the fix for the kind of failure where that is the clearer
one: a wrong shape or dtype, a negative output, an exception), and keeps the denoiser's traceback
where it raised (:attr:`CaseResult.traceback`).

Notes:
    * The suite's frames are made once per call of :func:`hard_cases` with fixed seeds:
      results are reproducible.
    * Per-sample data is modified together with the means (means and variances are recomputed
      from the samples), so a sample-based and a pixel-based denoiser see the same input.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable
from dataclasses import dataclass, field

import numpy as np

from denoisebench.dataset.frame import Frame, Sequence
from denoisebench.denoisers.runner import DenoiseResult, run_sequence
from denoisebench.denoisers.synthetic import make_scene, render

ENERGY_FACTOR = 4.0
ROBUST_PERCENTILE = 99.0
ABSOLUTE_TOLERANCE = 1e-6
BASE_SIZE = 32
BASE_SPP = 4


@dataclass(frozen=True)
class HardCase:
    """One named case: ``make()`` builds its frames (one sequence)."""

    name: str
    description: str
    make: Callable[[], Sequence]
    expect_sanitized: bool = False  # the input holds NaN/Inf: the runner must have counted some
    hint: str = ""  # what usually fixes a denoiser that fails this case (one line)


@dataclass
class CaseResult:
    """How one denoiser did on one case."""

    case: str
    passed: bool
    reason: str = ""
    seconds: float = 0.0  # total time inside denoise() over the case's frames
    sanitized: int = 0  # NaN/Inf values the runner replaced in the inputs
    results: list[DenoiseResult] = field(default_factory=list)
    hint: str = ""  # failed: what the case tests and what usually fixes it (one line)
    traceback: str | None = None  # failed by raising: the denoiser's traceback


def robust_mean(array: np.ndarray) -> float:
    """Mean of ``array`` after clipping at its :data:`ROBUST_PERCENTILE`-th percentile (float64)."""
    values = np.asarray(array, dtype=np.float64).ravel()
    if values.size == 0:
        return 0.0
    ceiling = np.percentile(values, ROBUST_PERCENTILE)
    return float(np.mean(np.minimum(values, ceiling)))


def energy_reason(output: np.ndarray, noisy: np.ndarray) -> str | None:
    """Why ``output`` fails the energy and sign checks against ``noisy`` (one line), or None."""
    low = float(np.min(output)) if output.size else 0.0
    if low < 0.0:
        return f"negative output (min {low:.3g})"
    expected = robust_mean(np.where(np.isfinite(noisy), noisy, 0.0))
    got = robust_mean(output)
    if expected <= 0.0:
        if got > ABSOLUTE_TOLERANCE:
            return f"input is black but the output's robust mean is {got:.3g}"
        return None
    ratio = got / expected
    if not (1.0 / ENERGY_FACTOR <= ratio <= ENERGY_FACTOR):
        return f"robust mean {got:.3g} is {ratio:.3g}× the input's {expected:.3g} (allowed ×{1 / ENERGY_FACTOR:g}..×{ENERGY_FACTOR:g})"
    return None


# --------------------------------------------------------------------------------------------------
# frame builders


def _frame(
    family: str = "shapes", width: int = BASE_SIZE, height: int = BASE_SIZE, spp: int = BASE_SPP, seed: int = 0
) -> Frame:
    return render(make_scene(family, width, height, seed), spp, seed + 1, samples=True, reference_samples=4)


def _recompute(frame: Frame, names: Iterable[str]) -> Frame:
    """Means and variances of ``names`` from the frame's (modified) samples, in place."""
    spp = frame.samples["color"].shape[0]
    for name in names:
        data = np.asarray(frame.samples[name], np.float64)
        frame.buffers[name] = data.mean(axis=0).astype(np.float32)
        if f"{name}_var" in frame.buffers:
            var = data.var(axis=0, ddof=1) / spp if spp > 1 else np.zeros_like(data[0])
            frame.buffers[f"{name}_var"] = var.astype(np.float32)
    return frame


def _sequence(*frames: Frame) -> Sequence:
    return Sequence(scene=frames[0].scene, spp=frames[0].spp, frames=list(frames))


def _fireflies() -> Sequence:
    frame = _frame(seed=11)
    rng = np.random.default_rng(5)
    spp, height, width, _ = frame.samples["color"].shape
    samples = dict(frame.samples)
    color, diffuse = samples["color"].copy(), samples["diffuse"].copy()
    # isolated: one sample in each of a few pixels at least 4 pixels apart
    for k in range(6):
        y, x = 2 + (5 * k) % (height - 4), 3 + (9 * k) % (width - 6)
        value = 10.0 ** rng.uniform(5.0, 6.0)
        color[k % spp, y, x] = value
        diffuse[k % spp, y, x] = value
    samples["color"], samples["diffuse"] = color, diffuse
    frame.samples = samples
    return _sequence(_recompute(frame, ("color", "diffuse")))


def _black_frame() -> Sequence:
    frame = _frame(seed=12)
    frame.buffers = {name: np.zeros_like(array) for name, array in frame.buffers.items()}
    frame.samples = {name: np.zeros_like(array) for name, array in frame.samples.items()}
    frame.reference = np.zeros_like(frame.reference)
    return _sequence(frame)


def _zero_albedo() -> Sequence:
    frame = _frame("textured", seed=13)
    frame.samples = {**frame.samples, "albedo": np.zeros_like(frame.samples["albedo"])}
    return _sequence(_recompute(frame, ("albedo",)))


def _dynamic_range() -> Sequence:
    frame = _frame("glossy", seed=14)
    width = frame.width
    gain = np.logspace(-6.0, 6.0, width, dtype=np.float64)[None, None, :, None]  # over x
    samples = dict(frame.samples)
    for name in ("color", "diffuse", "specular"):
        samples[name] = (samples[name] * gain).astype(np.float32)
    frame.samples = samples
    frame.reference = (frame.reference * gain[0]).astype(np.float32)
    return _sequence(_recompute(frame, ("color", "diffuse", "specular")))


def _nan_inf() -> Sequence:
    frame = _frame(seed=15)
    rng = np.random.default_rng(6)
    buffers = {name: array.copy() for name, array in frame.buffers.items()}
    samples = {name: array.copy() for name, array in frame.samples.items()}
    for name in ("color", "albedo", "normal", "depth"):
        for target in (buffers[name], samples[name]):
            flat = target.reshape(-1)
            picks = rng.choice(flat.size, size=max(3, flat.size // 50), replace=False)
            flat[picks[0::3]] = np.nan
            flat[picks[1::3]] = np.inf
            flat[picks[2::3]] = -np.inf
    frame.buffers, frame.samples = buffers, samples
    return _sequence(frame)


def _constant_features() -> Sequence:
    frame = _frame(seed=16)
    constants = {
        "albedo": [0.5, 0.5, 0.5],
        "normal": [0.0, 0.0, 1.0],
        "depth": [1.0],
        "position": [0.0, 0.0, 1.0],
        "roughness": [0.5],
    }
    samples = dict(frame.samples)
    for name, value in constants.items():
        samples[name] = np.broadcast_to(np.asarray(value, np.float32), samples[name].shape).copy()
    frame.samples = samples
    return _sequence(_recompute(frame, constants))


CASES: tuple[HardCase, ...] = (
    HardCase(
        "fireflies",
        "isolated samples of 1e5..1e6",
        _fireflies,
        hint="clamp or down-weight outlier samples (e.g. clip colour at a high percentile of its neighbourhood, "
        "or filter in log space) instead of spreading them over the kernel",
    ),
    HardCase(
        "black_frame",
        "every buffer and sample zero",
        _black_frame,
        hint="guard every division by brightness, variance or a feature with an epsilon; a zero input gives a zero output",
    ),
    HardCase(
        "zero_albedo",
        "albedo zero everywhere",
        _zero_albedo,
        hint="demodulate by albedo + eps (e.g. color / (albedo + 1e-2)) and remodulate with the same eps",
    ),
    HardCase(
        "dynamic_range",
        "colour spans 1e-6..1e6",
        _dynamic_range,
        hint="filter in a range-compressed space (log1p, or x / (1 + x)) and map back; no absolute thresholds",
    ),
    HardCase(
        "nan_inf",
        "NaN/Inf in color and features",
        _nan_inf,
        expect_sanitized=True,
        hint="inputs arrive sanitised (finite); a non-finite output comes from the denoiser's own arithmetic: "
        "guard divisions and logs with an epsilon",
    ),
    HardCase(
        "constant_features",
        "every feature constant",
        _constant_features,
        hint="normalise features by their spread + eps (a feature without variance must not get an infinite weight)",
    ),
    HardCase(
        "one_spp",
        "1 sample per pixel",
        lambda: _sequence(_frame(spp=1, seed=17)),
        hint="every variance is 0 at 1 spp: add an epsilon where dividing by it, or estimate it from neighbours",
    ),
    HardCase(
        "odd_size",
        "67×45 pixels",
        lambda: _sequence(_frame(width=67, height=45, seed=18)),
        hint="pad to the network's or tile's multiple and crop back to the frame's H×W",
    ),
    HardCase(
        "tiny",
        "3×3 pixels",
        lambda: _sequence(_frame(width=3, height=3, seed=19)),
        hint="clip the kernel radius and padding to the image size (reflect padding needs pad < size)",
    ),
    HardCase(
        "one_frame_sequence",
        "a sequence of one frame",
        lambda: _sequence(_frame("motion_blur", seed=20)),
        hint="reset() must leave the denoiser ready for a first frame with no previous one",
    ),
)


def failure_hint(case: HardCase, reason: str) -> str:
    """One line: what ``case`` tests and what usually fixes a denoiser that failed it with ``reason``."""
    if reason.startswith("raised") or " raised " in reason:
        return f"tests {case.description}; the denoiser raised: check-plugin --verbose (or --json) shows where"
    if "returned shape" in reason or "returned dtype" in reason or "not a numpy array" in reason:
        fix = "return an H×W×3 float32 array, e.g. np.asarray(out, np.float32)[..., :3]"
    elif "negative output" in reason:
        fix = "clip the output at 0 (np.maximum(out, 0)); radiance is never negative"
    else:
        fix = case.hint
    return f"tests {case.description}; usual fix: {fix}" if fix else f"tests {case.description}"


def case_names() -> list[str]:
    return [case.name for case in CASES]


def hard_cases(names: Iterable[str] | None = None) -> list[HardCase]:
    """The cases called ``names`` (all when None); ValueError naming an unknown one."""
    if names is None:
        return list(CASES)
    by_name = {case.name: case for case in CASES}
    unknown = [name for name in names if name not in by_name]
    if unknown:
        raise ValueError(f"unknown hard case(s) {', '.join(unknown)}; known: {', '.join(by_name)}")
    return [by_name[name] for name in names]


def run_case(denoiser: object, case: HardCase, *, name: str | None = None) -> CaseResult:
    """Run ``denoiser`` on one case under the runner's contract and judge it."""
    sequence = case.make()
    results = run_sequence(denoiser, sequence, name=name)
    seconds = sum(r.seconds or 0.0 for r in results)
    sanitized = sum(r.sanitized_total for r in results)
    outcome = CaseResult(case.name, False, seconds=seconds, sanitized=sanitized, results=results)
    for frame, result in zip(sequence, results):
        if not result.ok:
            outcome.reason = f"frame {frame.index}: {result.error}"
            outcome.traceback = result.traceback
            outcome.hint = failure_hint(case, result.error or "")
            return outcome
        reason = energy_reason(result.output, frame.color)
        if reason is not None:
            outcome.reason = f"frame {frame.index}: {reason}"
            outcome.hint = failure_hint(case, reason)
            return outcome
    if case.expect_sanitized and sanitized == 0:
        outcome.reason = "the input's NaN/Inf values were not counted as sanitised"
        outcome.hint = failure_hint(case, outcome.reason)
        return outcome
    outcome.passed = True
    return outcome


def check_denoiser(
    denoiser: object, names: Iterable[str] | None = None, *, name: str | None = None
) -> list[CaseResult]:
    """Every case (or those named) for one denoiser; failures are recorded, never raised."""
    return [run_case(denoiser, case, name=name) for case in hard_cases(names)]
