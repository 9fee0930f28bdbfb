"""Studies that combine generate, train and benchmark to answer one question.

``denoisebench study data-value`` trains the same model (kpcn, rae: small configurations) at the
same budget (steps × batch × crop pixels) on several training sets drawn from a pool of generated
family scenes, scores every checkpoint on one or more third-party datasets (pooled) through the normal benchmark (split
all, corrected scores with 95 % intervals over scenes) beside the noisy input, cross_bilateral and
OIDN, and writes OUT/study.md, OUT/study.json and OUT/scaling.png (error against the number of
training scenes). Re-running the same command skips what is done and resumes a stopped training
run from its last checkpoint. See docs/study.md.

Exit codes: 0 done, 2 bad input (no such dataset, an unknown training set, a pool scene in the
third-party dataset), 1 internal failure.
"""

from __future__ import annotations

import argparse
from pathlib import Path

from denoisebench.errors import UserInputError
from denoisebench.models.names import MODEL_NAMES

EPILOG = """examples:
  generate-dataset --out data/pool --families all --scenes 3 --frames 2 --width 64 --height 64 --spp 1,4 --ref-spp 512
  generate-dataset --out data/tp --scene-list denoisebench/scenes/lists/mitsuba_docs.toml --root ~/mitsuba-data \\
      --frames 2 --width 64 --height 64 --spp 1,4,16 --ref-spp 2048
  generate-dataset --out data/tp_usd --scene-list usd_wg_assets --root ~/assets \\
      --frames 2 --width 64 --height 64 --spp 1,4,16 --ref-spp 2048
  denoisebench study data-value --pool data/pool --third-party data/tp --out study/ --steps 300 --scaling 8,16
  denoisebench study data-value --pool data/pool --third-party data/tp --third-party data/tp_usd --out study/ \\
      --models kpcn --sets full,family:cornell,without:textures,loo:glass_env --seeds 0,1

documentation:
  docs/study.md   the study, its training sets, its figures and what they say
"""


def _ints(text: str, option: str) -> tuple[int, ...]:
    try:
        return tuple(int(part) for part in text.split(",") if part.strip())
    except ValueError:
        raise UserInputError(f"{option} expects comma-separated integers (got {text!r})") from None


def _names(text: str) -> tuple[str, ...]:
    return tuple(part.strip() for part in text.split(",") if part.strip())


def add_arguments(parser) -> None:
    sub = parser.add_subparsers(dest="study", metavar="STUDY")
    sub.required = True
    p = sub.add_parser(
        "data-value",
        help="what the generator's scenes are worth on third-party scenes",
        description=__doc__.split("\n\n")[1],
        epilog=EPILOG,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("--pool", required=True, help="dataset of generated family scenes to draw training sets from")
    p.add_argument(
        "--third-party",
        required=True,
        action="append",
        help="dataset of third-party scenes to score on (e.g. made by --scene-list); repeat it (or give "
        "A,B) to pool several, e.g. one rendered from the scenes' own sensors and one from the orbit",
    )
    p.add_argument("--out", required=True, help="study folder (created; re-running resumes it)")
    p.add_argument("--models", default="kpcn,rae", help="models to train, small configurations (default kpcn,rae)")
    p.add_argument(
        "--sets",
        default="full,family:cornell,without:textures",
        help="training sets: full, family:F, without:EFFECT, loo:F (leave family F out), n:K "
        "(default full,family:cornell,without:textures; full is always added)",
    )
    p.add_argument(
        "--scaling", default="", help="scaling-curve points in training scenes, e.g. 8,16 (default none: full only)"
    )
    p.add_argument("--seeds", default="0", help="training seeds, one run each, e.g. 0,1,2 (default 0)")
    p.add_argument("--steps", type=int, default=300, help="optimisation steps per run (default 300)")
    p.add_argument("--batch-size", type=int, default=8, help="crops per step (default 8)")
    p.add_argument("--crop", type=int, default=32, help="crop side in pixels (default 32)")
    p.add_argument("--lr", type=float, default=1e-3, help="Adam learning rate, constant (default 1e-3)")
    p.add_argument("--spp", type=int, default=4, help="input spp the third-party scores are at (default 4)")
    p.add_argument(
        "--references",
        default="cross_bilateral,oidn",
        help="reference denoisers beside the noisy input (default cross_bilateral,oidn)",
    )
    p.add_argument("--threads", type=int, default=1, help="torch CPU threads for training (default 1)")
    p.add_argument(
        "--report-only",
        action="store_true",
        help="train nothing: report the finished parts, score checkpoints already trained to the budget, "
        "list the rest as not run",
    )
    p.add_argument("--quiet", action="store_true", help="no progress bars")


def run(args) -> int:
    from denoisebench.study.data_value import StudyOptions, run_study
    from denoisebench.study.report import write_report

    thirds = tuple(Path(folder) for given in args.third_party for folder in _names(given))
    for option, folder in (("--pool", args.pool), *(("--third-party", folder) for folder in thirds)):
        if not (Path(folder) / "dataset.json").is_file():
            raise UserInputError(f"{option} {folder}: not a dataset folder (no dataset.json)")
    models = _names(args.models)
    unknown = [m for m in models if m not in MODEL_NAMES]
    if not models or unknown:
        raise UserInputError(
            f"--models: unknown model {unknown[0] if unknown else args.models!r} ({', '.join(MODEL_NAMES)})"
        )
    options = StudyOptions(
        out=Path(args.out),
        pool=Path(args.pool),
        third_party=thirds,
        models=models,
        sets=_names(args.sets),
        scaling=_ints(args.scaling, "--scaling"),
        seeds=_ints(args.seeds, "--seeds") or (0,),
        steps=args.steps,
        batch_size=args.batch_size,
        crop=args.crop,
        lr=args.lr,
        spp=args.spp,
        references=_names(args.references),
        threads=args.threads,
        progress=not args.quiet,
        report_only=args.report_only,
    )
    result = run_study(options, on_part=lambda partial: write_report(partial, options.out))
    path = write_report(result, options.out)
    print(f"report: {path.resolve()}")
    return 0
