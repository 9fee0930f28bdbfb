"""Run denoisers under the harness contract: sanitise inputs, time ``denoise()`` only, check outputs,
contain failures.

Everything that calls a denoiser (the benchmark, ``check-plugin``, tests) goes through here:

* **Inputs.** NaN and ±Inf in every buffer and per-sample array are replaced before the denoiser
  sees them, by the median of the finite values among the element's 3×3 spatial neighbours in the
  same channel (0 when none is finite), and counted per buffer (:attr:`DenoiseResult.sanitized`).
  The reference image is withheld, and so is every ``meta`` entry but :data:`PUBLIC_META` (no
  reference path, value or layers, no file paths). Every array is passed as a read-only **copy
  backed by immutable bytes**: a read-only view alone is not enough, as ``setflags(write=True)``
  on it (or on its ``base``) succeeds and would reach the next denoiser's input; numpy refuses to
  make an array over ``bytes`` writable. (An isolated denoiser gets its copy in its worker.)
  The built-ins (classes of this package, trusted not to flip the flag) get read-only views
  instead: the copy costs 0.33 ms per 128×128 frame (0.9 ms with per-sample data), 3 % of
  ``cross_bilateral_fast``'s time.
* **Isolation.** An :class:`~.isolation.IsolatedDenoiser` (a plugin in its own worker process)
  goes through the same steps; its time is the worker's time inside ``denoise()``, and a worker
  that exits, crashes, runs over its time or memory limit fails the call with that reason.
* **Needs.** A frame that lacks a buffer the denoiser ``needs`` is a failure without a call.
  Per-sample data (large: S×H×W×C per buffer) goes only to a denoiser whose ``needs`` holds
  ``"samples"``; buffers all go (features are used when present).
* **Timing.** :func:`time.perf_counter` around ``denoise(frame)`` only: sanitising, checking and
  any I/O are outside it.
* **Outputs.** Must be a numpy array of shape H×W×3, dtype float32, every value finite. Anything
  else (an exception, NaN output, wrong shape or dtype) is recorded as ``status="failed"`` with a
  one-line reason; the run goes on. ``KeyboardInterrupt`` and ``SystemExit`` still propagate.
* **Tracebacks.** A denoiser that raises (in this process or in its worker) keeps its traceback in
  :attr:`DenoiseResult.traceback`, and the first of each distinct failure of a denoiser is logged
  with it (:func:`denoisebench.plugins.proxy.log_failure`: a warning on the logger
  ``denoisebench.plugins``, which reaches stderr where logging is not configured).
* **Sequences.** ``reset()`` is called before each sequence, then the frames go in order.
"""

from __future__ import annotations

import time
import warnings
from collections.abc import Iterable, Mapping
from dataclasses import dataclass, field

import numpy as np

from denoisebench.dataset.frame import Frame, Sequence
from denoisebench.denoisers.isolation import IsolatedDenoiser
from denoisebench.denoisers.protocol import describe
from denoisebench.errors import one_line
from denoisebench.interrupts import raise_if_requested
from denoisebench.plugins import PluginFailure
from denoisebench.plugins.proxy import log_failure

STATUS_OK = "ok"
STATUS_FAILED = "failed"
#: The only ``Frame.meta`` entries a denoiser sees (render cost of its own input; no paths).
PUBLIC_META = ("seconds", "seconds_per_spp", "rel_se")


@dataclass
class DenoiseResult:
    """One call of one denoiser on one frame."""

    denoiser: str
    scene: str
    frame: int
    status: str
    error: str | None = None
    seconds: float | None = None  # time inside denoise(); None when it was not called
    output: np.ndarray | None = None  # H×W×3 float32 when status is "ok"
    sanitized: dict[str, int] = field(default_factory=dict)  # buffer -> NaN/Inf values replaced
    traceback: str | None = None  # the denoiser's traceback where it raised

    @property
    def ok(self) -> bool:
        return self.status == STATUS_OK

    @property
    def sanitized_total(self) -> int:
        return sum(self.sanitized.values())


# --------------------------------------------------------------------------------------------------
# input sanitising


def sanitize_array(array: np.ndarray) -> tuple[np.ndarray, int]:
    """``array`` (…×H×W×C) with NaN/±Inf replaced by the 3×3 neighbour median; and how many were.

    Returns the input itself (no copy) when everything is finite or the dtype is not floating.
    """
    array = np.asarray(array)
    if not np.issubdtype(array.dtype, np.floating):
        return array, 0
    bad = ~np.isfinite(array)
    count = int(np.count_nonzero(bad))
    if count == 0:
        return array, 0
    out = np.array(array, copy=True)
    out[bad] = np.nan
    if out.ndim < 3:
        flat = out.reshape(-1)
        finite = flat[np.isfinite(flat)]
        out[np.isnan(out)] = np.median(finite) if finite.size else 0.0
        return out, count
    # pad H and W (axes -3, -2) with NaN and gather the 3×3 neighbours of each bad element
    pad = [(0, 0)] * (out.ndim - 3) + [(1, 1), (1, 1), (0, 0)]
    padded = np.pad(out, pad, constant_values=np.nan)
    index = list(np.nonzero(bad))
    neighbours = []
    for dy in (-1, 0, 1):
        for dx in (-1, 0, 1):
            shifted = list(index)
            shifted[-3] = index[-3] + 1 + dy
            shifted[-2] = index[-2] + 1 + dx
            neighbours.append(padded[tuple(shifted)])
    stack = np.stack(neighbours, axis=-1)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)  # all-NaN neighbourhoods
        median = np.nanmedian(stack, axis=-1)
    out[tuple(index)] = np.where(np.isfinite(median), median, 0.0)
    return out, count


def _read_only(array: np.ndarray, copy: bool) -> np.ndarray:
    """``array`` as a copy over immutable bytes (``copy``), or as a read-only view."""
    if copy:
        array = np.ascontiguousarray(array)
        return np.frombuffer(array.tobytes(), dtype=array.dtype).reshape(array.shape)
    view = array.view()
    view.flags.writeable = False
    return view


def _builtin(denoiser: object) -> bool:
    """True for an instance of this package's own code (a built-in), which is trusted."""
    return type(denoiser).__module__.split(".")[0] == "denoisebench"


def sanitize_frame(frame: Frame, *, samples: bool = True, copy: bool = True) -> tuple[Frame, dict[str, int]]:
    """A copy of ``frame`` for a denoiser: finite, read-only, without the reference; and the counts.

    Per-sample arrays are counted as ``samples.<name>``; ``samples=False`` leaves them out.
    ``copy=False`` gives read-only views instead of copies: only for a consumer that copies
    anyway (an isolated denoiser's transfer) or a built-in (trusted not to make them writable),
    never for a plugin in this process.
    """
    counts: dict[str, int] = {}
    buffers = {}
    for name, array in frame.buffers.items():
        clean, count = sanitize_array(array)
        if count:
            counts[name] = count
        buffers[name] = _read_only(clean, copy)
    kept = None
    if samples and frame.samples is not None:
        kept = {}
        for name, array in frame.samples.items():
            clean, count = sanitize_array(array)
            if count:
                counts[f"samples.{name}"] = count
            kept[name] = _read_only(clean, copy)
    safe = Frame(
        buffers=buffers,
        spp=frame.spp,
        scene=frame.scene,
        index=frame.index,
        reference=None,
        samples=kept,
        meta={key: frame.meta[key] for key in PUBLIC_META if key in frame.meta},
    )
    return safe, counts


# --------------------------------------------------------------------------------------------------
# output checks


def check_output(output: object, height: int, width: int) -> str | None:
    """Why ``output`` breaks the contract (one line), or None when it is a finite H×W×3 float32 array."""
    if not isinstance(output, np.ndarray):
        return f"returned {type(output).__name__}, not a numpy array"
    if output.shape != (height, width, 3):
        return f"returned shape {output.shape}, expected {(height, width, 3)}"
    if output.dtype != np.float32:
        return f"returned dtype {output.dtype}, expected float32"
    bad = int(np.count_nonzero(~np.isfinite(output)))
    if bad:
        nans = int(np.count_nonzero(np.isnan(output)))
        return f"returned {bad} non-finite values ({nans} NaN, {bad - nans} Inf) of {output.size}"
    return None


# --------------------------------------------------------------------------------------------------
# running


def run_frame(denoiser: object, frame: Frame, *, name: str | None = None, keep_output: bool = True) -> DenoiseResult:
    """Denoise one frame under the contract; never raises for a failing denoiser."""
    try:
        info = describe(denoiser, fallback_name=name or type(denoiser).__name__)
        label = name or info.name
    except Exception as error:  # noqa: BLE001
        return DenoiseResult(name or repr(denoiser), frame.scene, frame.index, STATUS_FAILED, one_line(error))
    isolated = isinstance(denoiser, IsolatedDenoiser)  # its transfer into the worker is the copy
    safe, counts = sanitize_frame(frame, samples="samples" in info.needs, copy=not (isolated or _builtin(denoiser)))
    result = DenoiseResult(label, frame.scene, frame.index, STATUS_FAILED, sanitized=counts)
    missing = sorted(need for need in info.needs if not frame.has(need))
    if missing:
        result.error = f"frame lacks buffer(s) {', '.join(missing)} that the denoiser needs"
        return result
    started = time.perf_counter()
    try:
        output = denoiser.denoise(safe)
    except PluginFailure as error:  # an isolated call: the reason is already one line
        raise_if_requested()  # a worker stopped by the interrupt has not failed
        result.seconds = denoiser.last_seconds if isolated else time.perf_counter() - started
        result.error = str(error)
        result.traceback = log_failure("denoiser", label, f"{frame.scene} frame {frame.index}", result.error, error)
        return result
    except Exception as error:  # noqa: BLE001 - contained and recorded
        raise_if_requested()  # a KeyboardInterrupt that native code handed back as another exception
        result.seconds = time.perf_counter() - started
        result.error = f"raised {one_line(error)}"
        result.traceback = log_failure("denoiser", label, f"{frame.scene} frame {frame.index}", result.error, error)
        return result
    result.seconds = denoiser.last_seconds if isolated else time.perf_counter() - started
    reason = check_output(output, frame.height, frame.width)
    if reason is not None:
        result.error = reason
        return result
    result.status = STATUS_OK
    result.output = output if keep_output else None
    return result


def run_sequence(
    denoiser: object, sequence: Sequence | Iterable[Frame], *, name: str | None = None, keep_output: bool = True
) -> list[DenoiseResult]:
    """``reset()``, then every frame in order. A failing ``reset()`` fails every frame of the sequence."""
    frames = list(sequence)
    label = name or getattr(denoiser, "name", None) or type(denoiser).__name__
    reset = getattr(denoiser, "reset", None)
    if callable(reset):
        try:
            reset()
        except Exception as error:  # noqa: BLE001
            raise_if_requested()
            reason = str(error) if isinstance(error, PluginFailure) else f"reset() raised {one_line(error)}"
            text = log_failure("denoiser", label, "reset()", reason, error)
            return [DenoiseResult(label, f.scene, f.index, STATUS_FAILED, reason, traceback=text) for f in frames]
    return [run_frame(denoiser, frame, name=label, keep_output=keep_output) for frame in frames]


def run_denoisers(
    denoisers: Mapping[str, object], sequences: Iterable[Sequence], *, keep_output: bool = True
) -> dict[str, list[DenoiseResult]]:
    """Every denoiser on every sequence; one denoiser's failures never touch another's results."""
    sequences = list(sequences)
    results: dict[str, list[DenoiseResult]] = {}
    for label, denoiser in denoisers.items():
        records: list[DenoiseResult] = []
        for sequence in sequences:
            records.extend(run_sequence(denoiser, sequence, name=label, keep_output=keep_output))
        results[label] = records
    return results
