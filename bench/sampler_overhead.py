"""Each built-in sampler's decision time as a fraction of its render time, beside uniform, in one run.

A sampler's seconds are render seconds (what the renderer reports for its rounds, kernel
compilation excluded) plus decision seconds (its own work between rounds, and the harness's: see
``denoisebench/sampling/harness.py``). At an equal mean spp the renders cost about the same, so
the decision share is what adaptive sampling must win back in accuracy to be worth it at equal
time. Every sampler spends the same budget on fresh frames of the same scene; each is run once to
warm up, then ``--repeats`` times, interleaved, and the medians are printed with the ratio of its
total seconds to uniform's.

``--renderer mitsuba`` renders a ``--family`` scene live through the feature renderer's
progressive frame (``generator/render/progressive.py``); ``synthetic`` uses
``SyntheticProgressiveFrame`` (``sampling/synthetic.py``: numpy draws, much cheaper per sample than
path tracing, so the decision shares it prints are upper bounds). ``auto`` (default) takes mitsuba
when it renders a non-uniform round here and says which it used.

    .venv/bin/python bench/sampler_overhead.py [--renderer auto|mitsuba|synthetic] [--family cornell]
        [--size 64] [--spp 16] [--repeats 3] [--seeds 5]

A second table, always on synthetic frames of known truth (``sampling/synthetic.py``), says what
the decisions buy and how noisy the error maps are: relMSE to the truth on ``check_frame`` (mean of
``--seeds`` seeds) over uniform's at the same spp, and the spread of the spp map (coefficient of
variation; 0 is right) on a constant image with the same noise everywhere, where any spread is the
error map's own noise.
"""

from __future__ import annotations

import argparse
import statistics
import sys
import tempfile
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from denoisebench.sampling import synthetic  # noqa: E402
from denoisebench.sampling.harness import run_sampler  # noqa: E402
from denoisebench.sampling.protocol import Budget  # noqa: E402
from denoisebench.sampling.registry import BUILTINS, load_sampler  # noqa: E402


def mitsuba_frames(family: str, size: int):
    """A factory of fresh progressive frames of one ``family`` scene, or None with the reason."""
    try:
        from denoisebench.generator.contract.render_plan import RenderOptions, make_render_plan
        from denoisebench.generator.dataset_scenes import author_family_scene
        from denoisebench.generator.usd.translate import translate_usd
        from denoisebench.sampling.live import LiveScene
        from denoisebench.scenes import get_family

        folder = Path(tempfile.mkdtemp(prefix="sampler-overhead-"))
        author_family_scene(get_family(family), folder, 0, 1, size, size)
        translated = translate_usd(folder / "scene.usda")
        plan = make_render_plan(translated.effects, RenderOptions(), stage_max_depth=translated.max_depth)
        live = LiveScene(folder / "scene.usda", plan, width=size, height=size, render_seed=1)
        probe = live.open(0)
        probe.render_round(np.ones((size, size), dtype=np.int32))
        uneven = np.zeros((size, size), dtype=np.int32)
        uneven[:, size // 2 :] = 2
        probe.render_round(uneven)
    except Exception as error:  # noqa: BLE001 - the bench falls back to the synthetic frame and says why
        return None, f"{type(error).__name__}: {str(error).splitlines()[0] if str(error) else ''}"
    return (lambda: live.open(0)), f"mitsuba, {family} scene"


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--renderer", choices=("auto", "mitsuba", "synthetic"), default="auto")
    parser.add_argument("--family", default="cornell")
    parser.add_argument("--size", type=int, default=64)
    parser.add_argument("--spp", type=float, default=16)
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--seeds", type=int, default=5)
    args = parser.parse_args(argv)

    make_frame, label = None, "synthetic (SyntheticProgressiveFrame.check_frame; numpy, not path tracing)"
    if args.renderer != "synthetic":
        make_frame, why = mitsuba_frames(args.family, args.size)
        if make_frame is None:
            if args.renderer == "mitsuba":
                print(f"error: the progressive renderer does not render here: {why}", file=sys.stderr)
                return 2
            print(f"note: progressive renderer unavailable ({why}); using the synthetic frame", file=sys.stderr)
        else:
            label = why
    if make_frame is None:
        make_frame = lambda: synthetic.check_frame(args.size, args.size, seed=3)  # noqa: E731

    names = list(BUILTINS)
    budget = Budget(spp=args.spp)
    runs: dict[str, list] = {name: [] for name in names}
    for name in names:  # warm-up: kernels compile, scipy imports
        run_sampler(load_sampler(name), make_frame(), budget)
    for _ in range(args.repeats):
        for name in names:
            result = run_sampler(load_sampler(name), make_frame(), budget)
            if result.error:
                print(f"error: {name}: {result.error}", file=sys.stderr)
                return 1
            runs[name].append(result)

    def median(name, attribute):
        return statistics.median(getattr(r, attribute) for r in runs[name])

    base = median("uniform", "seconds")
    print(f"renderer: {label}")
    print(f"{args.size}x{args.size} px, {args.spp:g} spp mean, medians of {args.repeats} runs after a warm-up")
    header = (
        f"{'sampler':<15} {'rounds':>6} {'render s':>9} {'decide s':>9} {'decide/render':>13} {'total/uniform':>13}"
    )
    print(header)
    for name in names:
        render, decide = median(name, "render_seconds"), median(name, "decision_seconds")
        rounds = statistics.median(len(r.rounds) for r in runs[name])
        print(
            f"{name:<15} {rounds:>6g} {render:>9.4f} {decide:>9.4f} {decide / max(render, 1e-12):>13.3f} "
            f"{median(name, 'seconds') / base:>13.3f}"
        )
    if "mitsuba" in label:
        print()
        print_round_costs(make_frame, args.size, int(args.spp), args.repeats)
    print()
    print(f"synthetic frames of known truth, {args.size}x{args.size} px, {args.spp:g} spp, {args.seeds} seeds")
    print(f"{'sampler':<15} {'relMSE':>9} {'/uniform':>9} {'spp spread on flat noise':>25}")
    quality = {name: quality_figures(name, args.size, budget, args.seeds) for name in names}
    for name, (error, spread) in quality.items():
        print(f"{name:<15} {error:>9.4f} {error / quality['uniform'][0]:>9.3f} {spread:>25.3f}")
    return 0


def print_round_costs(make_frame, size: int, spp: int, repeats: int) -> None:
    """What a round costs the renderer: the same samples in 1 round, in 7, and one uneven round."""
    shape = (size, size)
    uneven = np.ones(shape, dtype=np.int32)
    uneven[size // 2, size // 2] = 4 * spp
    cases = {
        f"uniform {spp} spp, 1 round": [np.full(shape, spp, dtype=np.int32)],
        f"uniform {spp} spp, 7 rounds": [
            np.full(shape, n, dtype=np.int32) for n in np.diff(np.linspace(0, spp, 8).round())
        ],
        f"1 spp + one pixel at {4 * spp}, 1 round": [uneven],
    }
    print(f"round cost of the renderer, {size}x{size} px (median of {repeats})")
    print(f"{'rounds':<34} {'samples':>8} {'render s':>9} {'s per sample / uniform 1 round':>31}")
    base = None
    for label, rounds in cases.items():
        times = []
        for _ in range(repeats + 1):
            frame = make_frame()
            times.append(sum(frame.render_round(c.astype(np.int32)).seconds for c in rounds if c.any()))
        seconds, samples = statistics.median(times[1:]), int(sum(c.sum() for c in rounds))
        base = base or seconds / samples
        print(f"{label:<34} {samples:>8} {seconds:>9.4f} {seconds / samples / base:>31.2f}")


def quality_figures(name: str, size: int, budget: Budget, seeds: int) -> tuple[float, float]:
    """(mean relMSE to the truth on check_frame, coefficient of variation of spp on a flat noisy frame)."""
    errors, spreads = [], []
    for seed in range(seeds):
        frame = synthetic.check_frame(size, size, seed=seed)
        image = run_sampler(load_sampler(name), frame, budget).buffers["color"].astype(np.float64)
        errors.append(np.mean((image - frame.truth) ** 2 / (frame.truth**2 + 0.01)))
        spp = run_sampler(load_sampler(name), synthetic.constant(size, size, noise=0.5, seed=seed), budget).spp
        spreads.append(spp.std() / spp.mean())
    return float(np.mean(errors)), float(np.mean(spreads))


if __name__ == "__main__":
    sys.exit(main())
