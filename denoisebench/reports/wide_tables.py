"""Wide tables collapse: the lead columns first, the rest one click (HTML) or one table (Markdown) away.

A summary table holds every lead metric with its corrected value, raw score and floor: thirty
columns and more, which scroll sideways and hide the column that matters. :func:`lead_view` keeps
the first column (the label) and the columns whose heading names a lead metric's leading value
(not its ``raw`` or ``floor`` companions) or one of the extra headings asked for; :func:`rest_view`
keeps the label and everything else. HTML shows the lead view and the whole table inside a
``<details>`` element; Markdown prints the lead view, then the rest as a second table.

Pitfall: headings are matched by their first word (``relmse_robust ↓ corrected`` is
``relmse_robust``'s lead column), so a metric whose name is a prefix of another does not pull that
one in.
"""

from __future__ import annotations

#: Tables at most this wide are shown whole.
MAX_COLUMNS = 9


def _first_word(heading: str) -> str:
    return heading.split(" ", 1)[0]


def lead_columns(header: list[str], metrics: tuple[str, ...], extra: tuple[str, ...] = ()) -> list[int]:
    """Indices of the label column, the lead columns of ``metrics`` (in ``metrics``' order) and
    the ``extra`` headings (exact), in that order."""
    picked = [0]
    for metric in metrics:
        for i, heading in enumerate(header):
            if i and _first_word(heading) == metric and not heading.endswith((" raw", " floor")) and i not in picked:
                picked.append(i)
    picked += [i for i, heading in enumerate(header) if heading in extra and i not in picked]
    return picked


def pick(header: list[str], rows: list[list[str]], columns: list[int]) -> tuple[list[str], list[list[str]]]:
    return [header[i] for i in columns], [[row[i] for i in columns] for row in rows]


def is_wide(header: list[str]) -> bool:
    return len(header) > MAX_COLUMNS


def lead_view(header, rows, *, metrics, extra=()) -> tuple[list[str], list[list[str]]]:
    """The label and lead columns of a table (the whole table when it is not wide)."""
    if not is_wide(header):
        return header, rows
    return pick(header, rows, lead_columns(header, metrics, extra))


def rest_view(header, rows, *, metrics, extra=()) -> tuple[list[str], list[list[str]]] | None:
    """The label and the columns :func:`lead_view` leaves out; None when it leaves none out."""
    if not is_wide(header):
        return None
    kept = set(lead_columns(header, metrics, extra))
    rest = [0] + [i for i in range(1, len(header)) if i not in kept]
    return pick(header, rows, rest) if len(rest) > 1 else None
