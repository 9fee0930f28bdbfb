"""Digest what denoisebench writes, so that a refactor can show its outputs are unchanged.

Usage::

    .venv/bin/python scripts/golden_snapshot.py --out /tmp/golden_before   # on the commit before
    .venv/bin/python scripts/golden_snapshot.py --out /tmp/golden_after    # on the commit after
    diff /tmp/golden_before/digest.json /tmp/golden_after/digest.json     # empty: same outputs

It generates one small dataset (two procedural families, 16 px, 2 frames, spp 1,2, fixed seed),
benchmarks two built-in denoisers on it without the render probe, and writes ``digest.json``: the
sha256 of every dataset image, the manifest and ``results.json`` with measured seconds masked, and
every row of the dataset's and the store's databases without their timed columns. What is masked varies run to run by nature (wall-clock seconds and
what is derived from them: time verdicts and the accuracy readings that quote seconds, spreads, equal-time tables);
everything else is compared.
"""

from __future__ import annotations

import argparse
import hashlib
import json
import re
import sqlite3
import subprocess
import sys
from pathlib import Path

_TIMED = re.compile(
    r"second|time|reading|timing|probe|spread|verdict|equal_|started|finished|duration|created|host|version|path|elapsed"
)


def _masked(value):
    if isinstance(value, dict):
        return {k: ("<masked>" if _TIMED.search(k) else _masked(v)) for k, v in value.items()}
    if isinstance(value, list):
        return [_masked(v) for v in value]
    return value


def _digest(out: Path) -> dict:
    data, report = out / "data", out / "report"
    files = {
        str(p.relative_to(data)): hashlib.sha256(p.read_bytes()).hexdigest()
        for p in sorted(data.rglob("*"))
        if p.is_file() and p.suffix not in (".json", ".sqlite")
    }
    manifest = _masked(json.loads((data / "dataset.json").read_text()))
    results = _masked(json.loads((report / "results.json").read_text()))
    return {
        "files": files,
        "manifest": manifest,
        "results": results,
        "dataset_rows": _rows(data / "dataset.sqlite"),
        "store_rows": _rows(out / "benchmark.sqlite"),
    }


def _rows(database: Path) -> dict:
    """Every row of every table but the timed ones, without its timed columns, sorted."""
    if not database.exists():
        return {}
    conn = sqlite3.connect(database)
    tables = [r[0] for r in conn.execute("select name from sqlite_master where type='table' order by name")]
    rows = {}
    for table in tables:
        columns = [r[1] for r in conn.execute(f"pragma table_info({table})")]
        kept = [c for c in columns if not _TIMED.search(c)]
        if _TIMED.search(table) or not kept:
            continue
        rows[table] = sorted(
            json.dumps([_masked(_maybe_json(v)) for v in r], default=str)
            for r in conn.execute(f"select {', '.join(kept)} from {table}")
        )
    return rows


def _maybe_json(value):
    if isinstance(value, str) and value[:1] in "{[":
        try:
            return json.loads(value)
        except ValueError:
            return value
    if isinstance(value, bytes):
        return hashlib.sha256(value).hexdigest()
    return value


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--out", type=Path, required=True, help="empty folder for the dataset, store and digest")
    args = parser.parse_args()
    args.out.mkdir(parents=True, exist_ok=True)
    bin_ = Path(sys.executable).parent
    subprocess.run(
        [bin_ / "denoisebench", "generate", "--out", args.out / "data", "--families", "glossy_fireflies,depth_of_field",
         "--scenes", "1", "--frames", "2", "--width", "16", "--height", "16", "--spp", "1,2", "--ref-spp", "32",
         "--ref-error", "0", "--seed", "5", "--quiet"],
        check=True,
    )  # fmt: skip
    subprocess.run(
        [bin_ / "run-benchmark", "--data", args.out / "data", "--denoisers", "identity,cross_bilateral",
         "--split", "all", "--out", args.out / "report", "--db", args.out / "benchmark.sqlite", "--no-render-probe"],
        check=True,
    )  # fmt: skip
    (args.out / "digest.json").write_text(json.dumps(_digest(args.out), indent=1, sort_keys=True) + "\n")
    print(args.out / "digest.json")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
