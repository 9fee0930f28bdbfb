"""Every example of every --help and of the README parses with the real parsers; the cheap ones run.

The examples are read from the parsers themselves (each command's and each ``scenes`` action's
epilog) and from the README's code blocks: every line that starts a ``denoisebench``,
``generate-dataset`` or ``run-benchmark`` command (continuation lines joined, comments dropped).
Parsing one is what argparse does on the command line: a wrong flag, a missing required option
or a bad choice exits 2.
"""

from __future__ import annotations

import argparse
import re
import shlex
from pathlib import Path

import pytest

from denoisebench import cli
from tests.support.paths import REPO as REPO_ROOT

PROGRAMS = {"denoisebench": [], "generate-dataset": ["generate"], "run-benchmark": ["benchmark"]}


def command_lines(text: str) -> list[str]:
    """The command lines of ``text`` (a --help epilog or a README), joined at a trailing backslash."""
    lines, pending = [], ""
    for raw in text.splitlines():
        line = raw.strip()
        if pending:
            line = pending + " " + line
            pending = ""
        elif line.split(" ", 1)[0] not in PROGRAMS:
            continue
        if line.endswith("\\"):
            pending = line[:-1].rstrip()
            continue
        lines.append(line)
    return lines


def argv_of(line: str) -> list[str]:
    words = shlex.split(line, comments=True)
    return PROGRAMS[words[0]] + words[1:]


def _subparsers(parser: argparse.ArgumentParser):
    yield parser
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            for sub in action.choices.values():
                yield from _subparsers(sub)


def help_examples() -> list[str]:
    return [line for p in _subparsers(cli.build_parser()) for line in command_lines(p.epilog or "")]


def readme_examples() -> list[str]:
    blocks = re.findall(r"```[a-z]*\n(.*?)```", (REPO_ROOT / "README.md").read_text(), re.S)
    return [line for block in blocks for line in command_lines(block)]


def test_examples_are_found():
    helps = help_examples()
    assert len(helps) >= 40 and any(line.startswith("denoisebench scenes make") for line in helps)
    assert len(readme_examples()) >= 20


@pytest.mark.parametrize("line", help_examples() + readme_examples())
def test_example_parses(line):
    parser = cli.build_parser()
    try:
        args = parser.parse_args(argv_of(line))
    except SystemExit as error:
        pytest.fail(f"{line!r} does not parse (exit {error.code})")
    if getattr(args, "option", None) and args.command == "benchmark":  # SPEC:KEY=VALUE, as the command reads it
        from denoisebench.commands.benchmark import _options

        _options(args.option)


def test_every_scenes_action_has_a_description_an_example_and_its_defaults():
    scenes = next(p for p in _subparsers(cli.build_parser()) if p.prog.endswith(" scenes"))
    actions = next(a for a in scenes._actions if isinstance(a, argparse._SubParsersAction)).choices
    assert sorted(actions) == ["check", "list", "make", "preview"]
    for name, parser in actions.items():
        assert parser.description and len(parser.description) > 40, name
        assert f"denoisebench scenes {name}" in (parser.epilog or ""), name
        for action in parser._actions:
            if action.default not in (None, False, [], argparse.SUPPRESS) and action.option_strings:
                assert "default" in (action.help or ""), f"scenes {name} {action.option_strings[0]}"


def test_a_wrong_example_would_be_caught():
    with pytest.raises(SystemExit):
        cli.build_parser().parse_args(argv_of("denoisebench scenes make cornell --sed 3 --out x"))
    from denoisebench.commands.benchmark import _options
    from denoisebench.errors import UserInputError

    with pytest.raises(UserInputError):  # the example train --help gave before
        _options(["checkpoint=kpcn.pt"])


def test_cheap_examples_run(tmp_path, monkeypatch):
    """The help's scene examples, the README's plugin (all hard cases pass) and its benchmark line, on tiny data."""
    monkeypatch.chdir(tmp_path)
    assert cli.main(argv_of("denoisebench scenes list")) == 0
    assert cli.main(argv_of("denoisebench scenes make cornell --out scenes/cornell_0 --frames 2")) == 0
    assert cli.main(argv_of("denoisebench scenes check scenes/cornell_0/scene.usda")) == 0
    small = "denoisebench scenes preview scenes/cornell_0/scene.usda --out small.png --width 16 --height 16 --spp 4"
    assert cli.main(argv_of(small)) == 0 and Path("small.png").stat().st_size > 0
    readme = (REPO_ROOT / "README.md").read_text()
    plugin = re.search(r"```python\n(# my_denoiser.py\n.*?)```", readme, re.S).group(1)
    Path("my_denoiser.py").write_text(plugin)
    assert cli.main(argv_of("denoisebench check-plugin my_denoiser.py:denoise")) == 0
    generate = "generate-dataset --out data/small --families cornell --frames 2 --width 16 --height 16 --spp 1,4"
    assert cli.main(argv_of(generate + " --ref-spp 64 --ref-error 0 --quiet")) == 0
    line = next(x for x in readme_examples() if "--denoiser my_denoiser.py:denoise" in x)
    argv = argv_of(line) + ["--split", "all", "--time-size", "none", "--no-render-probe", "--no-report"]
    assert cli.main(argv) == 0  # 0: every unit measured, none failed
