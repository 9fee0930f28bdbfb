"""Floor-corrected scores against a modest reference, checked against a 16× more expensive one.

For each scene family: one frame rendered at ``--spp`` (the noisy input) and two independent
references, at ``--ref-spp`` and at ``--factor`` × that. The noisy input and OIDN's output of it are
scored (relMSE and its robust form) against both: the corrected score against the cheap reference
(``score − floor``, ± 1.96 se: :mod:`denoisebench.metrics.floors.closed_form`) beside the raw score against the
expensive one. Agreement within the interval is what lets a report lead with corrected scores on a
user's modest references (issue 42).

The last columns say what the correction saves: the reference spp a **raw** score needs for its
floor to be at most ``--accuracy`` of the score (``ref_spp · floor / (accuracy · score)``: the floor
falls as 1/spp), against the spp the **corrected** score needs for its 95 % half-width to be that
small (the se falls as 1/sqrt(spp) while the error dominates it: ``ref_spp · (1.96 se / (accuracy ·
score))²``), both read off the cheap reference's own floor and se.

    .venv/bin/python bench/reference_correction.py --size 64 --spp 4 --ref-spp 256 --factor 16
"""

from __future__ import annotations

import argparse
import math
import sys
import tempfile
from dataclasses import dataclass
from pathlib import Path

import numpy as np

FAMILIES = ("cornell", "glossy_fireflies", "depth_of_field", "motion_blur")
METRICS = ("relmse", "relmse_robust")
Z95 = 1.959963984540054


@dataclass
class Row:
    family: str
    label: str
    metric: str
    corrected: float  # score − floor against the cheap reference
    se: float  # its standard error (the cheap reference's noise)
    floor: float
    raw_cheap: float
    raw_dear: float  # raw score against the expensive reference
    floor_dear: float
    se_dear: float
    noisy_share: float  # the cheap reference's share of values too noisy for a floor

    @property
    def agrees(self) -> bool:
        """Corrected (cheap) within 1.96 × the combined se of the dear reference's corrected score."""
        return abs(self.corrected - (self.raw_dear - self.floor_dear)) <= Z95 * math.hypot(self.se, self.se_dear)

    def spp_needed(self, ref_spp: int, accuracy: float) -> tuple[float, float]:
        """(reference spp for the raw score, for the corrected score) to be within ``accuracy`` of the truth."""
        truth = max(self.corrected, 1e-12)
        raw = ref_spp * self.floor / (accuracy * truth)
        corrected = ref_spp * (Z95 * self.se / (accuracy * truth)) ** 2
        return raw, corrected


def _render(stage: Path, name: str, seed: int, size: int, spp: tuple[int, ...], ref_spp: int | None):
    from denoisebench.generator.frame_jobs import FrameJob, render_job

    job = FrameJob(name, 0, f"{name}-{stage}", str(stage), spp, ref_spp, size, size, seed, {})
    return render_job(job)


def _scores(pred: np.ndarray, ref: np.ndarray, ref_var: np.ndarray, metric: str) -> tuple[float, float, float]:
    """(raw score, floor, se) of ``metric`` for ``pred`` against a reference with variance ``ref_var``."""
    from denoisebench.metrics import get_metric

    m = get_metric(metric)
    floor = m.floor_fn(pred, ref, ref_var)
    return float(m.fn(pred, ref)), float(floor.floor), float(floor.se)


def measure(
    families=FAMILIES,
    *,
    size: int = 32,
    spp: int = 4,
    ref_spp: int = 64,
    factor: int = 16,
    seed: int = 100,
    metrics=METRICS,
    out=None,
) -> list[Row]:
    """Rows for the noisy input and OIDN on one frame of each family (see the module docstring)."""
    from denoisebench.baselines.oidn import OIDN
    from denoisebench.dataset.frame import Frame
    from denoisebench.metrics.floors.closed_form import noisy_value_share
    from denoisebench.scenes import get_family

    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        root = Path(out or tmp)
        denoiser = OIDN()
        for family in families:
            stage = Path(get_family(family).author(str(root / family), seed=seed, frames=1))
            noisy = _render(stage, family, seed, size, (spp,), None).noisy[0]
            # two references independent of the input and of each other (their own seeds)
            cheap = _render(stage, family, seed + 1_000, size, (), ref_spp).reference
            dear = _render(stage, family, seed + 2_000, size, (), ref_spp * factor).reference
            color = noisy.buffers["color"]
            frame = Frame({k: v for k, v in noisy.buffers.items() if not k.endswith("_var")}, spp, family)
            outputs = {"noisy": color, "oidn": np.asarray(denoiser.denoise(frame), dtype=np.float32)}
            share = noisy_value_share(cheap.buffers["color"], cheap.buffers["color_var"])
            for label, pred in outputs.items():
                for metric in metrics:
                    raw_c, floor_c, se_c = _scores(pred, cheap.buffers["color"], cheap.buffers["color_var"], metric)
                    raw_d, floor_d, se_d = _scores(pred, dear.buffers["color"], dear.buffers["color_var"], metric)
                    rows.append(
                        Row(family, label, metric, raw_c - floor_c, se_c, floor_c, raw_c, raw_d, floor_d, se_d, share)
                    )
    return rows


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--families", default=",".join(FAMILIES))
    parser.add_argument("--size", type=int, default=64, help="frame width and height in pixels (default 64)")
    parser.add_argument("--spp", type=int, default=4, help="the noisy input's spp (default 4)")
    parser.add_argument("--ref-spp", type=int, default=256, help="the cheap reference's spp (default 256)")
    parser.add_argument("--factor", type=int, default=16, help="the expensive reference is this × dearer (16)")
    parser.add_argument("--accuracy", type=float, default=0.1, help="stated accuracy of the headline (0.1: 10 %%)")
    parser.add_argument("--seed", type=int, default=100)
    args = parser.parse_args(argv)
    families = [f.strip() for f in args.families.split(",") if f.strip()]
    print(
        f"rendering {len(families)} famil(ies) at {args.size} px: input {args.spp} spp, references "
        f"{args.ref_spp} and {args.ref_spp * args.factor} spp ...",
        file=sys.stderr,
    )
    rows = measure(families, size=args.size, spp=args.spp, ref_spp=args.ref_spp, factor=args.factor, seed=args.seed)
    dear = args.ref_spp * args.factor
    print(
        f"{'family':17s} {'entry':6s} {'metric':14s} {'corr@' + str(args.ref_spp):>10s} {'±1.96se':>9s} "
        f"{'raw@' + str(args.ref_spp):>10s} {'truth@' + str(dear):>11s} {'corr off':>8s} {'raw off':>8s} "
        f"{'in CI':>5s} {'noisy%':>6s} {'spp raw':>9s} {'spp corr':>9s} {'saving':>8s}"
    )
    savings, corr_off, raw_off = [], [], []
    for r in rows:
        raw_spp, corr_spp = r.spp_needed(args.ref_spp, args.accuracy)
        saving = raw_spp / corr_spp if corr_spp > 0 else math.inf
        truth = r.raw_dear - r.floor_dear
        off_c, off_r = abs(r.corrected - truth) / truth, abs(r.raw_cheap - truth) / truth
        if r.metric == "relmse_robust":
            savings.append(saving)
            corr_off.append(off_c)
            raw_off.append(off_r)
        print(
            f"{r.family:17s} {r.label:6s} {r.metric:14s} {r.corrected:10.4g} {Z95 * r.se:9.2g} {r.raw_cheap:10.4g} "
            f"{truth:11.4g} {100 * off_c:7.1f}% {100 * off_r:7.1f}% {'yes' if r.agrees else 'no':>5s} "
            f"{100 * r.noisy_share:6.2f} {raw_spp:9.0f} {corr_spp:9.0f} {saving:7.1f}x"
        )
    agree = sum(r.agrees for r in rows)
    print(f"within the corrected score's 95 % interval of the truth: {agree}/{len(rows)}")
    if savings:
        print(
            f"relmse_robust: corrected off by {100 * min(corr_off):.1f}-{100 * max(corr_off):.1f} % "
            f"(median {100 * float(np.median(corr_off)):.1f} %), raw by {100 * min(raw_off):.1f}-"
            f"{100 * max(raw_off):.1f} % (median {100 * float(np.median(raw_off)):.1f} %)"
        )
        print(
            f"reference spp saved for relmse_robust within {100 * args.accuracy:g} % of the truth: median "
            f"{float(np.median(savings)):.0f}x (range {min(savings):.0f}x to {max(savings):.0f}x)"
        )
    return 0


if __name__ == "__main__":
    sys.exit(main())
