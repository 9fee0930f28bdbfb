"""Check the figures docs/ quotes from a demo report against that report's results.json.

Every figure a demo report can confirm is quoted in a marked table of a page under docs/ (the page's
prose points to it), one row per figure:

    <!-- figures: denoisebench demo --out demo_out -->
    | figure | value | results.json |
    |---|---|---|
    | rendering's fixed seconds per frame at 1920×1080 | 2.95 | `time_model.render.offset_s` |
    <!-- /figures -->

The first comment names the run the figures come from; the third column says where results.json
holds each one: keys joined by dots, ``[key=value]`` picks the first item of a list whose ``key`` is
``value``, ``[key!=value]`` keeps the items whose ``key`` is not ``value``, ``[n]`` the n-th item,
and a trailing ``#`` counts. A number matches when the report's value, rounded to the digits quoted,
is the quoted number (``2.95`` matches 2.9512); a list of numbers (``1, 2, 4``) matches item by
item; anything else matches as text.

Usage:

    scripts/check_doc_figures.py --report demo_out/report/results.json            # check; exit 1 on a mismatch
    scripts/check_doc_figures.py --report demo_out/report/results.json --update   # rewrite the tables' values

``--update`` writes the report's values into the tables (rounded to the digits each quoted) and says
what changed: after a new demo, run it, read the diff of docs/ and fix the prose that reads them.
Exit status: 0 every figure matches (or was updated), 1 a figure differs, 2 bad input (no report, a
table whose path results.json does not have).
"""

from __future__ import annotations

import argparse
import json
import math
import re
import sys
from dataclasses import dataclass
from pathlib import Path

BEGIN = re.compile(r"^<!-- figures: (?P<source>.+?) -->\s*$")
END = "<!-- /figures -->"
ROW = re.compile(r"^\|(?P<figure>[^|]+)\|(?P<value>[^|]+)\|\s*`(?P<path>[^`]+)`\s*\|\s*$")
STEP = re.compile(
    r"\[(?P<key>[^\]=!]+)(?P<op>!?=)(?P<value>[^\]]*)\]|\[(?P<index>\d+)\]|(?P<name>[^.\[#]+)|(?P<count>#)"
)


class BadInput(Exception):
    """A report or a table the check cannot read."""


@dataclass(frozen=True, kw_only=True)
class Figure:
    page: Path
    line: int  # 0-based line of the row in the page
    source: str
    figure: str
    quoted: str
    path: str


def figures(docs: Path) -> list[Figure]:
    """Every row of every marked table under ``docs`` (``*.md``, recursively)."""
    found = []
    for page in sorted(docs.rglob("*.md")):
        source = None
        for n, line in enumerate(page.read_text().splitlines()):
            begin = BEGIN.match(line)
            if begin:
                source = begin.group("source")
            elif line.strip() == END:
                source = None
            elif source is not None:
                row = ROW.match(line)
                if row and not set(row.group("value").strip()) <= set("-:"):
                    found.append(
                        Figure(
                            page=page,
                            line=n,
                            source=source,
                            figure=row.group("figure").strip(),
                            quoted=row.group("value").strip(),
                            path=row.group("path").strip(),
                        )
                    )
    return found


def lookup(report: dict, path: str):
    """The value at ``path`` in ``report`` (the path language of the module docstring)."""
    here = report
    position = 0
    for part in path.split("."):
        for step in STEP.finditer(part):
            position += 1
            if step.group("name") is not None:
                if not isinstance(here, dict) or step.group("name") not in here:
                    raise BadInput(f"{path}: no key {step.group('name')!r}")
                here = here[step.group("name")]
            elif step.group("index") is not None:
                here = here[int(step.group("index"))]
            elif step.group("count"):
                here = len(here)
            else:
                key, op, value = step.group("key"), step.group("op"), step.group("value")
                items = [item for item in here if (str(item.get(key)) == value) == (op == "=")]
                if op == "=":
                    if not items:
                        raise BadInput(f"{path}: no item with {key} = {value}")
                    here = items[0]
                else:
                    here = items
    return here


def _digits(quoted: str) -> int:
    """Significant digits of a quoted number (``0.121``: 3; ``325``: 3)."""
    mantissa = quoted.lstrip("-").split("e")[0].replace(".", "").lstrip("0")
    return max(len(mantissa), 1)


def _number(text: str) -> float | None:
    try:
        return float(text)
    except ValueError:
        return None


def _rounded(value: float, digits: int) -> float:
    return float(f"{value:.{digits}g}") if value and math.isfinite(value) else value


def _matches(quoted: str, actual) -> bool:
    if isinstance(actual, list):
        parts = [p.strip() for p in quoted.split(",")]
        return len(parts) == len(actual) and all(_matches(p, a) for p, a in zip(parts, actual))
    number = _number(quoted)
    if number is not None and isinstance(actual, (int, float)) and not isinstance(actual, bool):
        return _rounded(float(actual), _digits(quoted)) == _rounded(number, _digits(quoted))
    return quoted == str(actual)


def _as_quoted(quoted: str, actual) -> str:
    """The report's value written as ``quoted`` writes it (the same significant digits)."""
    if isinstance(actual, list):
        parts = [p.strip() for p in quoted.split(",")]
        return ", ".join(_as_quoted(parts[min(i, len(parts) - 1)], a) for i, a in enumerate(actual))
    if isinstance(actual, (int, float)) and not isinstance(actual, bool) and _number(quoted) is not None:
        if isinstance(actual, int):
            return str(actual)
        return f"{_rounded(actual, _digits(quoted)):.{_digits(quoted)}g}"
    return str(actual)


def check(report: dict, docs: Path, update: bool = False) -> tuple[list[str], int]:
    """(lines to print, number of figures that differ from the report)."""
    lines, wrong = [], 0
    rewrites: dict[Path, list[str]] = {}
    for f in figures(docs):
        actual = lookup(report, f.path)
        where = f"{f.page.name}:{f.line + 1}"
        if _matches(f.quoted, actual):
            lines.append(f"ok        {where}  {f.figure}: {f.quoted}")
            continue
        wrong += 1
        new = _as_quoted(f.quoted, actual)
        lines.append(f"{'updated ' if update else 'DIFFERS '}  {where}  {f.figure}: docs {f.quoted}, report {new}")
        if update:
            page = rewrites.setdefault(f.page, f.page.read_text().splitlines(keepends=True))
            row = page[f.line]
            cells = row.split("|")
            cells[2] = cells[2].replace(f.quoted, new, 1)
            page[f.line] = "|".join(cells)
    for page, text in rewrites.items():
        page.write_text("".join(text))
    return lines, wrong


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(
        description="Check (or --update) the figures docs/ quotes from a demo report against its results.json.",
        epilog="example: scripts/check_doc_figures.py --report demo_out/report/results.json",
    )
    parser.add_argument(
        "--report", required=True, help="results.json of a demo report (e.g. demo_out/report/results.json)"
    )
    parser.add_argument(
        "--docs", default=str(Path(__file__).resolve().parents[1] / "docs"), help="the pages to read (default docs/)"
    )
    parser.add_argument(
        "--update", action="store_true", help="write the report's values into the tables (default: check)"
    )
    args = parser.parse_args(argv)
    try:
        report_path = Path(args.report)
        if not report_path.is_file():
            raise BadInput(f"--report {args.report}: no such file")
        try:
            report = json.loads(report_path.read_text())
        except json.JSONDecodeError as exc:
            raise BadInput(f"--report {args.report}: not JSON ({exc})") from None
        if not figures(Path(args.docs)):
            raise BadInput(f"--docs {args.docs}: no figures table (<!-- figures: ... -->)")
        lines, wrong = check(report, Path(args.docs), update=args.update)
    except BadInput as exc:
        print(f"check_doc_figures: {exc}", file=sys.stderr)
        return 2
    print("\n".join(lines))
    if wrong and not args.update:
        print(f"{wrong} figure(s) differ from {args.report}: rerun with --update, then read the prose around them")
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
