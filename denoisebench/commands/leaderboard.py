"""Rank denoisers by one metric at one input spp across every run on one dataset of a results database.

Each denoiser is shown from the newest run that measured it (its run id and date in the table);
``noisy`` is the input itself, the line every denoiser has to beat. Failed denoisers rank last.
"""

from __future__ import annotations

from denoisebench.leaderboard.store import ResultsStore
from denoisebench.leaderboard.table import format_leaderboard, leaderboard

EPILOG = """examples:
  denoisebench leaderboard --db benchmark.sqlite
  denoisebench leaderboard --db benchmark.sqlite --metric flip --spp 4
  denoisebench leaderboard --metric flicker --dataset 3fa9c1    # temporal_relmse (scale-free)
  denoisebench leaderboard --sampler ci_stop                     # only ci_stop's live pairs
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
    parser.add_argument(
        "--sampler",
        default=None,
        help="rank only the entries whose input this live sampler made ('none': only the dataset's stored inputs; "
        "default every entry)",
    )


def run(args) -> int:
    with ResultsStore(args.db, readonly=True) as store:
        sampler = "" if args.sampler == "none" else args.sampler
        print(format_leaderboard(*leaderboard(store, args.metric, args.spp, args.dataset, sampler)))
    return 0
