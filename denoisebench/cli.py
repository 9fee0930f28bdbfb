"""Command line: ``denoisebench <command>``, plus the ``generate-dataset`` and ``run-benchmark`` aliases.

Each command lives in ``denoisebench/commands/<name>.py`` with two functions:
``add_arguments(parser)`` and ``run(args) -> int``. This file only wires them up and maps errors
to exit codes (docs/architecture.md): 0 success, 2 bad input with a one-line message and no traceback,
1 internal failure, 130 interrupted (SIGINT or SIGTERM: :mod:`denoisebench.interrupts`); a command may
document one more (``benchmark``: 3, some units failed).
"""

from __future__ import annotations

import argparse
import importlib
import sys
import textwrap

from denoisebench import __version__
from denoisebench.errors import UserInputError
from denoisebench.interrupts import EXIT_INTERRUPTED, exit_interrupted, handling_signals
from denoisebench.interrupts import requested as interrupted

#: command name -> (module under denoisebench.commands, one-line help). Order is the --help order.
COMMANDS: dict[str, tuple[str, str]] = {
    "scenes": ("scenes", "list scene families, author a scene as USD, preview a stage"),
    "generate": ("generate", "render a dataset of noisy/reference EXR sequences (alias: generate-dataset)"),
    "demo": ("demo", "preview every family, render a small dataset, benchmark it, write the report (make demo)"),
    "train": ("train", "train a learned denoiser (dpcn, kpcn, rae, lbf) on a dataset's train split"),
    "benchmark": ("benchmark", "run denoisers over a dataset split into SQLite and write a report (run-benchmark)"),
    "leaderboard": ("leaderboard", "rank denoisers across the runs on one dataset in a results database"),
    "check-plugin": ("check_plugin", "run a denoiser through the hard-case suite; print a pass/fail table"),
    "export": ("export", "export a dataset for OIDN's training toolkit or Noisebase's loaders"),
    "study": ("study", "train, then benchmark on third-party scenes: what the generated data is worth (data-value)"),
}

EPILOG = textwrap.dedent(
    """\
    examples:
      denoisebench scenes list
      denoisebench scenes make cornell --seed 3 --out scenes/cornell_3
      denoisebench scenes preview scenes/cornell_3/scene.usda --out cornell.png --frame 2
    """
)


class _Parser(argparse.ArgumentParser):
    """argparse exits 2 on bad arguments already; keep its message to one line plus usage."""


def build_parser() -> argparse.ArgumentParser:
    parser = _Parser(
        prog="denoisebench",
        description="Dataset generation and benchmarking for Monte Carlo denoisers.",
        epilog=EPILOG,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )

    parser.add_argument("--version", action="version", version=f"denoisebench {__version__}")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    sub.required = True
    for name, (module_name, help_text) in COMMANDS.items():
        module = importlib.import_module(f"denoisebench.commands.{module_name}")
        command_parser = sub.add_parser(
            name,
            help=help_text,
            description=(module.__doc__ or help_text).strip(),
            formatter_class=argparse.RawDescriptionHelpFormatter,
            epilog=getattr(module, "EPILOG", None),
        )
        module.add_arguments(command_parser)
        command_parser.set_defaults(_run=module.run)
    return parser


def run_parsed(args: argparse.Namespace) -> int:
    """Run a parsed command with the exit-code contract."""
    try:
        with handling_signals():
            return int(args._run(args) or 0)
    except UserInputError as error:
        print(f"error: {error}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("interrupted", file=sys.stderr)
        return EXIT_INTERRUPTED


def main(argv: list[str] | None = None) -> int:
    try:
        with handling_signals():  # from the first import of a command on: a signal is exit 130
            args = build_parser().parse_args(argv)
            code = run_parsed(args)
    except KeyboardInterrupt:
        print("interrupted", file=sys.stderr)
        code = EXIT_INTERRUPTED
    if code == EXIT_INTERRUPTED and interrupted():
        exit_interrupted()  # a real signal: within 2 s, without the interpreter's slow shutdown
    return code


def _alias_main(command: str, argv: list[str] | None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    return main([command, *argv])


def generate_dataset_main(argv: list[str] | None = None) -> int:
    """``generate-dataset ...`` is ``denoisebench generate ...``."""
    return _alias_main("generate", argv)


def run_benchmark_main(argv: list[str] | None = None) -> int:
    """``run-benchmark ...`` is ``denoisebench benchmark ...``."""
    return _alias_main("benchmark", argv)


if __name__ == "__main__":
    sys.exit(main())
