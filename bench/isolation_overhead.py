"""What running a built-in in a worker process costs, on demo-sized frames (issue 16's target ≤ 5 %),
and what the sandbox adds to that worker (issue 33's targets: start-up ≤ 0.5 s, per frame unchanged).

    .venv/bin/python bench/isolation_overhead.py [--size 128] [--spp 4] [--frames 3] [--repeats 2] [--only identity,rpf]

Every built-in that loads runs the same synthetic sequence (``denoisebench.denoisers.synthetic``,
textured family, with features and per-sample data, like the demo's 128×128 frames at 4 spp)
through the harness runner twice: in this process (the default for built-ins) and in an
:class:`~denoisebench.denoisers.isolation.IsolatedDenoiser` (``--isolation all``). The figure is

    overhead = median per call of (proxy's wall around a call − the worker's time inside denoise())
               / in-process denoise time per frame

i.e. what the transfer into and out of the worker adds to each frame (shared-memory copy in, copy
out into the worker's own arrays, the output back, two pipe messages). The walls of whole
sequences are printed too, but on a shared machine their difference is dominated by scheduling
noise (seen: −14 % to +43 % at a load average of 11 on 2 cores), which the per-call figure
avoids. Denoise time is the runner's (inside ``denoise()``), the minimum over ``--repeats``
sequences after a warm-up. The worker's start-up (interpreter, imports, construction) is paid once
per denoiser per run and reported apart.

The same denoiser then runs in a sandboxed worker (:mod:`denoisebench.plugins.sandbox`, the
default for plugins), beside the plain worker process (``--isolation process``), in the same run:

    start-up ratio  = sandboxed start-up / plain worker start-up   (and the difference in seconds)
    per-frame ratio = sandboxed overhead per call / plain worker overhead per call

Start-up is the median of ``--starts`` constructions (``IsolatedDenoiser`` until the plugin is
loaded), alternating the two kinds so that a change in the machine's load hits both.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from denoisebench.denoisers.isolation import IsolatedDenoiser  # noqa: E402
from denoisebench.denoisers.registry import BUILTINS, load_denoiser  # noqa: E402
from denoisebench.denoisers.runner import run_sequence  # noqa: E402
from denoisebench.denoisers.synthetic import synthetic_sequence  # noqa: E402
from denoisebench.plugins import sandbox  # noqa: E402


def _measure(denoiser, sequence, repeats: int, per_call: list | None = None) -> tuple[float, float]:
    """(min wall of run_sequence, min total denoise seconds) over ``repeats`` after one warm-up;
    ``per_call`` collects an isolated denoiser's overhead of every measured call."""
    run_sequence(denoiser, sequence)
    walls, inner = [], []
    for _ in range(repeats):
        before = getattr(denoiser, "overhead_seconds", 0.0)
        started = time.perf_counter()
        results = run_sequence(denoiser, sequence)
        walls.append(time.perf_counter() - started)
        if not all(r.ok for r in results):
            raise RuntimeError(next(r.error for r in results if not r.ok))
        inner.append(sum(r.seconds for r in results))
        if per_call is not None:
            per_call.append((denoiser.overhead_seconds - before) / len(results))
    return min(walls), min(inner)


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--size", type=int, default=128)
    parser.add_argument("--spp", type=int, default=4)
    parser.add_argument("--frames", type=int, default=3)
    parser.add_argument("--repeats", type=int, default=2)
    parser.add_argument("--only", default="", help="comma-separated built-ins (default every one that loads)")
    parser.add_argument("--starts", type=int, default=3, help="constructions per kind for the start-up medians")
    args = parser.parse_args()
    if sandbox.unavailable_reason():
        print(f"no sandbox here: {sandbox.unavailable_reason()}", file=sys.stderr)
        return 2
    names = [n for n in args.only.split(",") if n] or list(BUILTINS)
    sequence = synthetic_sequence("textured", args.size, args.size, args.spp, args.frames, samples=True)
    print(f"{args.size}x{args.size}, {args.spp} spp, {args.frames} frames, per-sample data; min of {args.repeats}")
    print(
        f"{'denoiser':<22}{'denoise s/frame':>16}{'in-proc wall':>14}{'isolated wall':>15}"
        f"{'overhead ms/frame':>19}{'overhead':>10}{'start-up s':>12}"
    )
    total_denoise = total_extra = 0.0
    sandbox_rows = []
    for name in names:
        try:
            local = load_denoiser(name)
        except Exception as error:  # noqa: BLE001 - e.g. OIDN without pyoidn
            print(f"{name:<22} not loaded: {error}")
            continue
        wall_local, denoise = _measure(local, sequence, args.repeats)
        starts = {False: [], True: []}
        for _ in range(args.starts):
            for boxed in (False, True):
                started = time.perf_counter()
                IsolatedDenoiser(name, sandboxed=boxed).close()
                starts[boxed].append(time.perf_counter() - started)
        startup = float(np.median(starts[False]))
        per_call: list[float] = []
        boxed_per_call: list[float] = []
        remote = IsolatedDenoiser(name, sandboxed=False)
        boxed = IsolatedDenoiser(name, sandboxed=True)
        try:
            for _ in range(2):  # alternate the two, so that the machine's load falls on both
                wall_remote, _ = _measure(remote, sequence, args.repeats, per_call)
                _measure(boxed, sequence, args.repeats, boxed_per_call)
        finally:
            remote.close()
            boxed.close()
        boxed_extra = float(np.median(boxed_per_call))
        frame_denoise = denoise / len(sequence)
        extra = float(np.median(per_call))
        total_denoise += frame_denoise
        total_extra += extra
        print(
            f"{name:<22}{frame_denoise:>16.4f}{wall_local:>14.4f}{wall_remote:>15.4f}{1e3 * extra:>19.2f}"
            f"{100 * extra / max(frame_denoise, 1e-9):>9.1f}%{startup:>12.2f}"
        )
        sandbox_rows.append((name, startup, float(np.median(starts[True])), extra, boxed_extra))
    if total_denoise > 0:
        print(
            f"{'all (sum per frame)':<22}{total_denoise:>16.4f}{'':>14}{'':>15}{1e3 * total_extra:>19.2f}"
            f"{100 * total_extra / total_denoise:>9.1f}%"
        )
    if sandbox_rows:
        print(f"\nsandbox ({sandbox.version()}) against a plain worker process, medians of {args.starts} starts:")
        print(
            f"{'denoiser':<22}{'start-up s':>12}{'sandboxed s':>13}{'ratio':>8}{'+ s':>8}"
            f"{'overhead ms/frame':>19}{'sandboxed':>11}{'ratio':>8}"
        )
        for name, plain, boxed_start, extra, boxed_extra in sandbox_rows:
            print(
                f"{name:<22}{plain:>12.3f}{boxed_start:>13.3f}{boxed_start / plain:>8.2f}{boxed_start - plain:>8.3f}"
                f"{1e3 * extra:>19.2f}{1e3 * boxed_extra:>11.2f}{boxed_extra / max(extra, 1e-9):>8.2f}"
            )
        plain = float(np.median([r[1] for r in sandbox_rows]))
        boxed_start = float(np.median([r[2] for r in sandbox_rows]))
        ratios = [r[4] / max(r[3], 1e-9) for r in sandbox_rows]
        print(
            f"{'median':<22}{plain:>12.3f}{boxed_start:>13.3f}{boxed_start / plain:>8.2f}{boxed_start - plain:>8.3f}"
            f"{'':>19}{'':>11}{float(np.median(ratios)):>8.2f}"
        )
    return 0


if __name__ == "__main__":
    sys.exit(main())
