"""Rank denoisers by one metric at one input spp across every run on one dataset of a results database.

Each denoiser is shown from the newest run that measured it (its run id and date in the table);
``noisy`` is the input itself, the line every denoiser has to beat. Failed denoisers rank last, equal
scores share a rank. The numbers are the run's report's: the same scenes (those its report sets apart
are left out), corrected scores, and seconds projected to the report's resolution; the lines under
the heading say so.
"""

from __future__ import annotations

from denoisebench.analysis.time_model import parse_size
from denoisebench.reports.leaderboard import leaderboard
from denoisebench.results.store import ResultsStore

EPILOG = """examples:
  denoisebench leaderboard --db benchmark.sqlite
  denoisebench leaderboard --db benchmark.sqlite --metric flip --spp 4
  denoisebench leaderboard --metric flicker --dataset 3fa9c1    # temporal_relmse (scale-free)
  denoisebench leaderboard --sampler ci_stop                     # only ci_stop's live pairs
  denoisebench leaderboard --run 89bf6baa --split test           # one run's numbers, as its report shows them

documentation:
  docs/metrics.md   --metric: the robust and corrected scores and how they aggregate over scenes
  docs/samplers.md  --sampler: live samplers as a dimension of a run
"""


def add_arguments(parser) -> None:
    parser.add_argument("--db", default="benchmark.sqlite", help="results database (default benchmark.sqlite)")
    parser.add_argument(
        "--metric",
        default="relmse_robust",
        help="metric to rank by (default relmse_robust: relMSE without the worst 0.1 %% of pixels; relmse for the "
        "raw score); combined over scenes by the metric's aggregation rule",
    )
    parser.add_argument("--spp", type=int, default=None, help="input spp (default the lowest measured)")
    parser.add_argument(
        "--dataset", default=None, help="dataset hash prefix or folder (default the dataset of the newest run)"
    )
    parser.add_argument("--run", default=None, help="rank only this run (a run id or its prefix, as reports show it)")
    parser.add_argument("--split", default=None, help="rank only runs on this split (test, all, ...)")
    parser.add_argument(
        "--include-unresolved",
        action="store_true",
        help="keep the scenes a run's report sets apart (as run-benchmark --include-unresolved)",
    )
    parser.add_argument(
        "--time-at",
        default="1920x1080",
        help="resolution of the seconds, projected as the run's report does (default 1920x1080)",
    )
    parser.add_argument(
        "--sampler",
        default=None,
        help="rank only the entries whose input this live sampler made ('none': only the dataset's stored inputs; "
        "default every entry)",
    )


def run(args) -> int:
    with ResultsStore(args.db, readonly=True) as store:
        sampler = "" if args.sampler == "none" else args.sampler
        ranking = leaderboard(
            store,
            args.metric,
            args.spp,
            dataset=args.dataset,
            sampler=sampler,
            run=args.run,
            split=args.split,
            include_unresolved=args.include_unresolved,
            time_at=parse_size(args.time_at, "--time-at"),
        )
        print(ranking.text())
    return 0
