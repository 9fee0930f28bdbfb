"""Reference noise floor of a scene family at several reference spp: does the reference converge?

Renders ``--scenes`` scenes of one family (one frame each, ``--size`` pixels) with references
forced to their cap (``--ref-error 1e-12``) at every ``--ref-spp``, and prints per scene and
cap: the floor estimate (``reference_adaptive.floor``: the larger of the batch-means and the
pooled estimate, the relMSE a perfect denoiser would score), ``spp × floor`` (constant once every
kind of path is sampled often: the floor then falls as 1/spp) and ``floor_growth`` (``spp ×
floor`` at all rounds over the same at half of them; above 1.25 the estimate is still rising:
rare bright paths are still being found, the reference cannot resolve a score). The last
column is the ratio of the floors at the lowest and highest cap against the ratio of the caps
(1.0: it falls as 1/spp).

Used for issue 29 (glossy_fireflies redesign: fireflies from paths that next-event estimation
resolves, measured before and after)::

    .venv/bin/python bench/reference_floor.py --family glossy_fireflies --ref-spp 256,1024 --size 64 --scenes 3
"""

from __future__ import annotations

import argparse
import subprocess
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent


def floors(
    family: str, ref_spp: int, size: int, scenes: int, seed: int, out: Path, max_depth: int | None = None
) -> dict[str, dict]:
    """{scene: reference_adaptive of its frame 0} from one generate-dataset run."""
    cmd = [
        str(ROOT / ".venv" / "bin" / "generate-dataset"),
        "--out",
        str(out),
        "--families",
        family,
        "--scenes",
        str(scenes),
        "--seed",
        str(seed),
        "--frames",
        "1",
        "--width",
        str(size),
        "--height",
        str(size),
        "--spp",
        "1",
        "--ref-spp",
        str(ref_spp),
        "--ref-error",
        "1e-12",
        "--quiet",
    ] + (["--max-depth", str(max_depth)] if max_depth else [])
    subprocess.run(cmd, check=True, stdout=subprocess.DEVNULL)
    from denoisebench.dataset import open_dataset

    dataset = open_dataset(out)
    result = {}
    for name in sorted(dataset.scenes):
        frames = dataset.scene(name).record["renders"]["reference"]
        result[name] = next(iter(frames.values()))["reference_adaptive"]
    return result


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--family", default="glossy_fireflies")
    parser.add_argument("--ref-spp", default="256,1024", help="comma-separated reference caps (default 256,1024)")
    parser.add_argument("--size", type=int, default=64, help="frame width and height in pixels (default 64)")
    parser.add_argument("--scenes", type=int, default=3, help="scenes of the family, seeds --seed... (default 3)")
    parser.add_argument("--seed", type=int, default=900)
    parser.add_argument("--max-depth", type=int, default=None, help="restrict path depth (diagnosis: 2 = direct light)")
    args = parser.parse_args(argv)
    caps = sorted(int(s) for s in args.ref_spp.split(","))
    table: dict[int, dict] = {}
    with tempfile.TemporaryDirectory() as tmp:
        for i, cap in enumerate(caps):
            print(
                f"rendering {args.scenes} {args.family} reference(s) at {cap} spp, {args.size} px ...", file=sys.stderr
            )
            table[cap] = floors(
                args.family, cap, args.size, args.scenes, args.seed, Path(tmp) / f"d{i}", args.max_depth
            )
    print(f"{'scene':28s} {'spp':>6s} {'floor':>10s} {'spp×floor':>10s} {'growth':>7s}")
    for scene in sorted(table[caps[0]]):
        for cap in caps:
            a = table[cap][scene]
            floor, growth = a.get("floor"), a.get("floor_growth")
            print(
                f"{scene:28s} {a['spp']:6d} {floor:10.4g} {floor * a['spp']:10.4g} "
                f"{growth if growth is not None else float('nan'):7.2f}"
            )
        lo, hi = table[caps[0]][scene], table[caps[-1]][scene]
        if lo.get("floor") and hi.get("floor"):
            print(
                f"{'':28s} floor {lo['spp']} / floor {hi['spp']} = {lo['floor'] / hi['floor']:.2f} "
                f"(1/spp: {hi['spp'] / lo['spp']:.2f})"
            )
    return 0


if __name__ == "__main__":
    sys.exit(main())
