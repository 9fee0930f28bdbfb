"""Benchmark denoisers on a dataset split and write a report (also installed as ``run-benchmark``).

Every denoiser runs over every sequence of the split at every input spp (temporal ones frame by
frame, reset() between sequences); every metric is computed per frame and every call timed. Results
go to a SQLite database (--db) with the dataset's hash, the config and software versions; a failing
denoiser is recorded with its error and the run goes on. Rerunning the same command after a kill
completes what is missing. The report folder (--out) gets index.html (self-contained, works
offline), report.md, results.json, results.csv and figures/.

Untrusted input is checked before anything is measured: every dataset file's sha256 against the
manifest (--no-verify skips it, and the run records that), every manifest path confined to the
dataset folder, --out and --db writable, every --option naming a denoiser that is run and a
keyword its constructor takes. Plugins (every denoiser that is not a built-in) run in worker
processes of their own under --time-limit and --memory-limit (see docs/sandbox.md).

A denoiser or sampler named on the command line that cannot be loaded (import error, missing
attribute, wrong protocol) is bad input: exit 2 with the line check-plugin gives, before anything
is written. --denoisers all runs every denoiser that can run on this dataset; the others are named
in one line each with what would enable them (rpf, rpf_fast and lightfield need generate-dataset
--samples), and are not counted as failed. A run resumes only what it would compute the same way:
a plugin's identity includes a hash of its code (its file, or its package's files and its
distribution's version), so an edited plugin is measured again in a new run, and the output names
the run it replaces.

Exit codes: 0 every unit measured; 3 the run completed but some units failed (warnings name them,
the report lists them); 2 bad input (one line, nothing written); 1 internal failure; 130
interrupted (Ctrl-C or SIGTERM; the same command resumes).
"""

from __future__ import annotations

import json
import sys
import time
from pathlib import Path

from denoisebench.analysis.time_model import parse_size
from denoisebench.benchmark.run import run_benchmark
from denoisebench.benchmark.runner import BenchmarkConfig
from denoisebench.benchmark.stability import stability_table
from denoisebench.benchmark.timing import AUTO, DEFAULT_TIME_BUDGET, measure_run_timings
from denoisebench.dataset import disk_space, open_dataset
from denoisebench.denoisers.registry import check_denoiser_spec
from denoisebench.errors import UserInputError
from denoisebench.metrics.ours.robust import check_trim
from denoisebench.outputs import check_writable_dir, check_writable_file
from denoisebench.plugins import DEFAULT_MEMORY_LIMIT_MB, DEFAULT_TIME_LIMIT
from denoisebench.plugins.proxy import PluginProxy, limits_from_args
from denoisebench.plugins.proxy import add_arguments as add_isolation_arguments
from denoisebench.plugins.sandbox import protect
from denoisebench.reports.build import write_report
from denoisebench.results.store import ResultsStore, utc_now
from denoisebench.sampling.registry import check_sampler_spec

#: Exit status of a run that completed with some failed units (distinct from bad input, 2, and internal failure, 1).
EXIT_UNITS_FAILED = 3

EPILOG = """examples:
  run-benchmark --data out/dataset --out report/
  run-benchmark --data out/dataset --denoisers identity,oidn --spp 1,4 --db results.sqlite
  run-benchmark --data out/dataset --denoiser my_pkg.filters:MyDenoiser --option my_pkg.filters:MyDenoiser:radius=5
  run-benchmark --data out/dataset --denoiser plugins/slow.py:Slow --time-limit 600 --memory-limit 8192
  run-benchmark --data out/dataset --metrics noisebase,cvvdp   # Noisebase's table beside ColorVideoVDP
  run-benchmark --data out/dataset --trim 0.002   # robust scores drop the worst 0.2 % of pixels
  run-benchmark --data out/dataset --time-at 3840x2160 --time-size 512x512   # times for 4K frames
  run-benchmark --data out/dataset --samplers uniform,ci_stop,dual_buffer,hachisuka2008 --denoisers none,oidn

exit codes: 0 done, 3 some units failed (the run and its report are complete), 2 bad input, 1 internal
failure, 130 interrupted (rerun the same command to resume)

documentation:
  docs/metrics.md    --metrics, --trim, --include-unresolved: robust and corrected scores, aggregation, flicker
  docs/time.md       --time-at, --time-size, --time-budget, --no-render-probe: accuracy against time
  docs/samplers.md   --samplers: live adaptive samplers and their spp maps
  docs/sandbox.md    --isolation, --time-limit, --memory-limit, --no-verify: untrusted plugins and data
  docs/scale-out.md  --executor ray
"""


def _int_list(text: str) -> list[int]:
    try:
        values = [int(v) for v in text.split(",") if v.strip()]
    except ValueError:
        raise UserInputError(f"--spp wants comma-separated integers, got {text!r}") from None
    if not values or any(v < 1 for v in values):
        raise UserInputError(f"--spp wants positive integers, got {text!r}")
    return values


def _options(items: list[str]) -> dict[str, dict]:
    """``SPEC:KEY=VALUE`` (SPEC may itself contain ':') → {spec: {key: value}}; values parsed as JSON when they can be."""
    options: dict[str, dict] = {}
    for item in items:
        head, eq, value = item.rpartition("=")
        spec, colon, key = head.rpartition(":")
        if not eq or not colon or not spec or not key:
            raise UserInputError(f"--option wants SPEC:KEY=VALUE, got {item!r}")
        try:
            parsed = json.loads(value)
        except json.JSONDecodeError:
            parsed = value
        options.setdefault(spec, {})[key] = parsed
    return options


def add_arguments(parser) -> None:
    parser.add_argument("--data", required=True, help="dataset folder (with dataset.json)")
    parser.add_argument(
        "--denoisers",
        default=None,
        help="comma-separated built-in/entry-point names, or 'all' (default all, or none when --denoiser is given)",
    )
    parser.add_argument(
        "--denoiser",
        action="append",
        default=[],
        metavar="MODULE:ATTR",
        help="a plugin denoiser as module:attr or path/to/file.py:attr (repeatable; added to --denoisers)",
    )
    parser.add_argument(
        "--samplers",
        default="",
        help="comma-separated samplers (built-in, entry point of denoisebench.samplers, module:attr) rendered live on "
        "the dataset's scenes at each spp, alone and with each denoiser ('none' in --denoisers: only alone)",
    )
    parser.add_argument(
        "--option", action="append", default=[], metavar="SPEC:KEY=VALUE", help="constructor option of a denoiser"
    )
    parser.add_argument(
        "--spp", default=None, help="input spp to benchmark, e.g. 1,4,16 (default: every spp of the split)"
    )
    parser.add_argument(
        "--split",
        default="test",
        choices=("train", "val", "test", "all"),
        help="dataset split, or all for every scene of a benchmark-only dataset (default test)",
    )
    parser.add_argument(
        "--metrics",
        default="",
        help="comma-separated metrics or metric sets (noisebase: Noisebase's definitions, nb_*; "
        "oidn: the PSNR and SSIM of OIDN's compare_image.py, oidn_*); default every registered metric "
        "outside the sets; relmse and flip always",
    )
    parser.add_argument(
        "--trim",
        type=float,
        default=None,
        metavar="FRACTION",
        help="fraction of the highest per-pixel errors the robust scores (relmse_robust, "
        "temporal_relmse_robust) drop, in [0, 0.5) (default 0.001 = 0.1 %%; recorded in the run)",
    )
    parser.add_argument(
        "--include-unresolved",
        action="store_true",
        help="keep scenes whose reference cannot resolve the headline scores (floor still growing, or above "
        "a tenth of the best score) in the report's aggregates; by default they are listed apart",
    )
    parser.add_argument("--out", default="report", help="report folder (default report)")
    parser.add_argument("--db", default="benchmark.sqlite", help="results database (default benchmark.sqlite)")
    parser.add_argument("--executor", default="local", choices=("local", "ray"), help="where units run (default local)")
    parser.add_argument(
        "--new-run", action="store_true", help="measure everything again as a new run instead of resuming"
    )
    parser.add_argument("--no-report", action="store_true", help="only measure; write no report")
    parser.add_argument(
        "--no-verify",
        action="store_true",
        help="skip the sha256 check of the dataset's files before the run (recorded in the run)",
    )

    parser.add_argument(
        "--time-at",
        default="1920x1080",
        metavar="WxH",
        help="resolution the report's times are for, projected from fixed + per-pixel costs (default 1920x1080)",
    )
    parser.add_argument(
        "--time-size",
        default="auto",
        metavar="WxH",
        help="second size each denoiser and the render probe are timed at after the run, on tiled copies of a frame "
        "(default auto: 8 times the dataset's width and height, at most 1024x1024, e.g. 256x256 for 32-px frames; "
        "none: no timing, times stay at the dataset's resolution; e.g. --time-size 1024x1024)",
    )
    parser.add_argument(
        "--time-budget",
        type=float,
        default=DEFAULT_TIME_BUDGET,
        metavar="SECONDS",
        help=f"a denoiser expected to take longer at --time-size is timed smaller (default {DEFAULT_TIME_BUDGET:g})",
    )
    parser.add_argument(
        "--no-render-probe",
        action="store_true",
        help="do not time renders of the dataset's stage (colour only, and the buffers each denoiser reads) at "
        "--time-size: rendering alone and every denoiser are then charged the dataset's own render seconds, offsets "
        "held fixed (default: timed; e.g. --no-render-probe)",
    )

    add_isolation_arguments(parser)


def few_scenes_line(split: str, scenes: int, total: int) -> str | None:
    """One line when the split holds fewer scenes than the report's tables need (None otherwise)."""
    if scenes >= 2:
        return None
    other = f"; --split all scores all {total}" if total > scenes and split != "all" else ""
    return (
        f"note: split {split!r} holds {scenes} of the dataset's {total} scene(s): the report has no interval over "
        f"scenes and no per-effect column (each needs 2 scenes){other}"
    )


def run(args) -> int:
    need = lambda: disk_space.store_need(args.db)  # noqa: E731
    with disk_space.full_disk_is_one_line(Path(args.db).absolute().parent, "--db", "the results store", need):
        return _run(args)


def _remove_store(path: str) -> None:
    """Delete the SQLite file ``path`` and its journal, WAL and shared-memory files."""
    for suffix in ("", "-journal", "-wal", "-shm"):
        Path(f"{path}{suffix}").unlink(missing_ok=True)


def _run(args) -> int:
    limits = limits_from_args(args)  # bad limits are exit 2 before anything else
    trim = None
    if args.trim is not None:
        try:
            trim = check_trim(args.trim)
        except ValueError as exc:
            raise UserInputError(f"--trim: {exc}") from None

    time_at = parse_size(args.time_at, "--time-at")
    time_size = AUTO if args.time_size.strip().lower() == AUTO else parse_size(args.time_size, "--time-size")
    if time_at is None:
        raise UserInputError("--time-at wants WIDTHxHEIGHT such as 1920x1080")
    if not args.time_budget > 0:
        raise UserInputError(f"--time-budget wants a positive number of seconds, got {args.time_budget}")

    # --denoiser alone benchmarks just those plugins; --denoisers defaults to all otherwise
    given = args.denoisers if args.denoisers is not None else ("" if args.denoiser else "all")
    specs = [s.strip() for s in given.split(",") if s.strip()] + list(args.denoiser)
    samplers = [s.strip() for s in args.samplers.split(",") if s.strip()]
    if samplers:  # "none": the samplers' images as they are (identity stands in when no denoiser is left)
        specs = [s for s in specs if s != "none"] or ["identity"]
        if args.executor != "local":
            raise UserInputError("--samplers runs with --executor local only")
    for spec in specs:  # a misspelled name is refused before any file is written
        if spec not in ("all", "none"):
            check_denoiser_spec(spec)
    for spec in samplers:
        if spec != "none":
            check_sampler_spec(spec)
    config = BenchmarkConfig(
        denoisers=specs,
        spp=_int_list(args.spp) if args.spp else [],
        split=args.split,
        metrics=[m.strip() for m in args.metrics.split(",") if m.strip()],
        options=_options(args.option),
        nonce=utc_now() if args.new_run else None,
        isolation=args.isolation,
        time_limit=None if limits.time_limit == DEFAULT_TIME_LIMIT else limits.time_limit,
        memory_limit_mb=None if limits.memory_limit_mb == DEFAULT_MEMORY_LIMIT_MB else limits.memory_limit_mb,
        verify=not args.no_verify,
        trim=trim,
        samplers=samplers,
    )
    # outputs first: a run that cannot write its results must not measure for minutes first
    check_writable_file(args.db, "--db")
    if not args.no_report:
        check_writable_dir(args.out, "--out")
    dataset = open_dataset(args.data)

    protect(dataset.root, args.db, None if args.no_report else args.out)  # hidden from every sandboxed worker
    started = time.perf_counter()
    fresh = not Path(args.db).exists()
    store = ResultsStore(args.db)
    try:
        plan = run_benchmark(dataset, config, store, executor=args.executor)
    except UserInputError:  # refused (an unknown option, ...): a store this command created goes again
        store.close()
        if fresh:
            _remove_store(args.db)
        raise
    try:
        return _finish(args, dataset, store, plan, started, time_at, time_size)
    finally:
        close_workers(plan)


def close_workers(plan) -> None:
    """Stop the worker processes of the run's isolated denoisers (plugins): a process that runs
    several benchmarks (a notebook, the test suite) would keep one idle worker per plugin per run
    until it exits."""
    for d in plan.denoisers:
        if isinstance(d.instance, PluginProxy):
            d.instance.close()


def _finish(args, dataset, store, plan, started, time_at, time_size) -> int:
    """Summary lines, timings at the second size, and the report of a measured run."""
    with store:
        units = store.units(plan.run_id)
        failed = [u for u in units if u.status != "ok"]
        print(
            f"run {plan.run_id} ({'resumed' if plan.resumed else 'new'}): {len(units)} units in {args.db}, "
            f"{len(failed)} failed, {time.perf_counter() - started:.1f} s"
        )
        for d in plan.denoisers:
            if d.load_error:
                print(f"  {d.spec}: not run: {d.load_error}")
        for old in plan.replaced:
            print(
                f"  replaces run {old.run_id} ({old.units} units): the code of {', '.join(old.specs)} changed since, "
                "so this run measures it again"
            )
        few = few_scenes_line(args.split, len(plan.scenes), len(dataset.scenes))
        if few:
            print(few)

        instances = {d.label: d.instance for d in plan.denoisers if d.instance is not None}
        measure_run_timings(
            store,
            dataset,
            plan,
            instances,
            time_size,
            budget=args.time_budget,
            render_probe=not args.no_render_probe,
        )
        code = EXIT_UNITS_FAILED if failed else 0
        if args.no_report:
            return code

        index = write_report(
            store,
            plan.run_id,
            dataset,
            Path(args.out),
            stability_table(instances) if instances else None,
            time_at,
            include_unresolved=args.include_unresolved,
        )
    print(f"report: {index.resolve()}")
    sys.stdout.flush()
    return code
