"""Run a denoiser through the hard-case suite and print a pass/fail table.

SPEC is a built-in name, an entry point of the group ``denoisebench.denoisers`` or MODULE:ATTR
(also path/to/file.py:ATTR). Every case is run under the harness contract (inputs sanitised,
outputs checked, failures contained); a case passes when every output is a finite H×W×3 float32
array, non-negative, with a robust mean within ×4 of the input's (see
``denoisebench.denoisers.hard_cases``).

A plugin (anything but a built-in) runs in a worker process of its own, as in the benchmark, under
--time-limit and --memory-limit: a plugin that exits, crashes, hangs or bloats fails its cases with
the reason instead of ending this command, and its inputs are copies it cannot use to change what
the check compares against.

A failing case's line says what it tests and what usually fixes it; where the denoiser raised,
--verbose prints its traceback below the table and --json carries it (``traceback``).

Exit codes: 0 every case passed, 1 some case failed, 2 the denoiser cannot be found or built
(or an unknown --case / malformed or unknown --option).
"""

from __future__ import annotations

import contextlib
import json
import logging
import sys
import traceback

from tqdm import tqdm

from denoisebench.denoisers.registry import available_denoisers
from denoisebench.errors import UserInputError
from denoisebench.plugins.proxy import add_arguments as add_isolation_arguments
from denoisebench.plugins.proxy import limits_from_args
from denoisebench.sampling.checks import check_sampler
from denoisebench.sampling.registry import available_samplers

# Lazy imports: the hard cases (scipy, 0.3 s) only when a denoiser is checked, so that --help and
# --sampler stay quick.

EPILOG = """examples:
  denoisebench check-plugin cross_bilateral
  denoisebench check-plugin rpf --case fireflies --case tiny
  denoisebench check-plugin my_package.denoise:MyDenoiser --option strength=0.5
  denoisebench check-plugin plugins/median.py:Median --json
  denoisebench check-plugin plugins/mine.py:denoise --verbose      # a plain function; tracebacks shown
  denoisebench check-plugin plugins/slow.py:Slow --time-limit 300 --memory-limit 8192
  denoisebench check-plugin --list
  denoisebench check-plugin --sampler hachisuka2008
  denoisebench check-plugin --sampler my_package.sampling:MySampler --option rounds=8 --json

documentation:
  docs/plugins.md   writing a denoiser plugin: what frame holds, what to return, the hard cases
  docs/samplers.md  --sampler: the sampler protocol and its convergence check
  docs/sandbox.md   --isolation, --time-limit, --memory-limit: how plugins are isolated and sandboxed
"""


def add_arguments(parser) -> None:
    parser.add_argument("spec", nargs="?", help="denoiser: built-in name, entry-point name or MODULE:ATTR")
    parser.add_argument(
        "--option",
        action="append",
        default=[],
        metavar="KEY=VALUE",
        help="constructor keyword (VALUE parsed as JSON when it parses, else a string); repeatable",
    )
    parser.add_argument("--case", action="append", default=None, metavar="NAME", help="run only this case; repeatable")
    parser.add_argument("--json", action="store_true", help="print the results as JSON instead of a table")
    parser.add_argument(
        "--verbose",
        action="store_true",
        help="print the traceback of every case where the denoiser raised (and of a plugin that fails to load)",
    )
    parser.add_argument("--list", action="store_true", help="list the known denoisers and the hard cases, then exit")
    parser.add_argument(
        "--sampler",
        action="store_true",
        help="SPEC is a sampler (group denoisebench.samplers): run its convergence check on a frame of known truth "
        "(denoisebench.sampling.checks) instead of the hard cases; a plugin sampler runs in a worker process",
    )

    add_isolation_arguments(parser)


def parse_options(items: list[str]) -> dict:
    """``["radius=7", "preset=fast"]`` → ``{"radius": 7, "preset": "fast"}`` (JSON values when they parse)."""
    options = {}
    for item in items:
        key, sep, value = item.partition("=")
        if not sep or not key.strip().isidentifier():
            raise UserInputError(f"--option {item!r}: expected KEY=VALUE with KEY a Python identifier")
        try:
            options[key.strip()] = json.loads(value)
        except json.JSONDecodeError:
            options[key.strip()] = value
    return options


def _list() -> int:
    from denoisebench.denoisers.hard_cases import CASES

    print("denoisers:")
    for name, origin in available_denoisers().items():
        print(f"  {name:<22} {origin}")
    print("hard cases:")
    for case in CASES:
        print(f"  {case.name:<22} {case.description}")

    print("samplers (--sampler):")
    for name, origin in available_samplers().items():
        print(f"  {name:<22} {origin}")
    return 0


def _table(label: str, outcomes, verbose: bool = False) -> str:
    rows = [("case", "result", "seconds", "sanitised", "detail", "")]
    for outcome in outcomes:
        rows.append(
            (
                outcome.case,
                "pass" if outcome.passed else "FAIL",
                f"{outcome.seconds:.3f}",
                str(outcome.sanitized),
                outcome.reason,
                outcome.hint,
            )
        )
    widths = [max(len(row[i]) for row in rows) for i in range(4)]
    lines = [f"check-plugin {label}"]
    for row in rows:
        lines.append(("  ".join(cell.ljust(width) for cell, width in zip(row[:4], widths)) + "  " + row[4]).rstrip())
        if row[1] == "FAIL" and row[5]:
            lines.append(f"{'':<{widths[0]}}  hint: {row[5]}")
    passed = sum(outcome.passed for outcome in outcomes)
    lines.append(f"{passed}/{len(outcomes)} cases passed")
    raised = [outcome for outcome in outcomes if outcome.traceback]
    for outcome in raised if verbose else ():
        lines += ["", f"traceback of case {outcome.case}:", outcome.traceback.rstrip()]
    return "\n".join(lines)


@contextlib.contextmanager
def _tracebacks_in_the_output():
    """A plugin's tracebacks go to this command's table (--verbose) or JSON, not to the log on stderr."""
    log = logging.getLogger("denoisebench.plugins")
    level = log.level
    log.setLevel(logging.ERROR)
    try:
        yield
    finally:
        log.setLevel(level)


def _load_traceback(error: BaseException) -> str | None:
    """Where a plugin that failed to load raised: its worker's traceback, or this process's cause."""
    text = getattr(error, "traceback", None)
    if text:
        return text.rstrip()
    cause = error.__cause__
    if cause is None:
        return None
    return "".join(traceback.format_exception(type(cause), cause, cause.__traceback__)).rstrip()


def run(args) -> int:
    if args.list:
        return _list()
    if not args.spec:
        raise UserInputError("give a denoiser SPEC (or --list)")
    if args.sampler:
        limits = limits_from_args(args)
        options = parse_options(args.option)
        with _tracebacks_in_the_output():
            return check_sampler(
                args.spec, options, as_json=args.json, isolation=args.isolation, limits=limits, verbose=args.verbose
            )

    from denoisebench.denoisers import hard_cases, isolation

    limits = limits_from_args(args)
    options = parse_options(args.option)
    try:
        cases = hard_cases.hard_cases(args.case)
    except ValueError as error:
        raise UserInputError(str(error)) from None
    try:
        denoiser = isolation.load(args.spec, options, policy=args.isolation, limits=limits)
    except UserInputError as error:
        if args.verbose:  # the plugin's own traceback above the one-line error
            print(_load_traceback(error) or "(no traceback: the plugin did not raise)", file=sys.stderr)
        raise
    label = getattr(denoiser, "name", None) or args.spec
    outcomes = []
    with _tracebacks_in_the_output():
        for case in tqdm(cases, desc=f"check {label}", unit="case", file=sys.stderr, leave=False):
            outcomes.append(hard_cases.run_case(denoiser, case))
    if args.json:
        payload = {
            "denoiser": label,
            "spec": args.spec,
            "passed": all(o.passed for o in outcomes),
            "cases": [
                {
                    "case": o.case,
                    "passed": o.passed,
                    "reason": o.reason,
                    "seconds": o.seconds,
                    "sanitized": o.sanitized,
                    **({"hint": o.hint, "traceback": o.traceback} if not o.passed else {}),
                }
                for o in outcomes
            ],
        }
        print(json.dumps(payload, indent=2))
    else:
        print(_table(label, outcomes, verbose=args.verbose))
    return 0 if all(o.passed for o in outcomes) else 1
