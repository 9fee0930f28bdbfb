"""The data-value study's report: ``study.md`` (summary with paired ratios to the full mix, training
set × third-party scene, the scaling curve), ``study.json`` and the scaling figure ``scaling.png``.

Runs nothing: it reads a :class:`~denoisebench.study.data_value.StudyResult` (also one loaded back
from ``study.json``, so a report can be redrawn without rescoring).
"""

from __future__ import annotations

import json
from dataclasses import asdict
from pathlib import Path

from denoisebench.analysis.lead import LEAD_RULE, SCENE_TRIM
from denoisebench.models.names import MODEL_NAMES
from denoisebench.study.data_value import FIGURE, METRICS, REPORT_JSON, REPORT_MD, StudyResult, seed_summary

# Lazy imports: numpy for the paired bootstrap, matplotlib for the figure.


#: The reference every row is also compared with, scene by scene (the classic a learned model must beat).
PEER = "cross_bilateral"
#: Bootstrap resamples of the paired ratios (seed 0: the same parts give the same report).
PAIRED_RESAMPLES = 2000


def paired_ratio(parts: list[dict], full: list[dict], metric: str, kept: list[str]) -> dict:
    """Geometric mean over the kept scenes of this set's score ÷ the same model's ``full`` score
    (per scene, means over seeds), with a 95 % percentile bootstrap over scenes: the comparison
    in which a scene's own difficulty cancels. Scenes where either score is not positive are left
    out (a black scene scores 0 for every model)."""
    import numpy as np

    def per_scene(group):
        out = {}
        for scene in kept:
            values = [p["scores"][metric]["per_scene"].get(scene) for p in group]
            values = [v for v in values if v is not None]
            if values:
                out[scene] = sum(values) / len(values)
        return out

    mine, base = per_scene(parts), per_scene(full)
    logs = np.array([np.log(mine[s] / base[s]) for s in kept if mine.get(s, 0) > 0 and base.get(s, 0) > 0])
    if logs.size == 0:
        return {"value": None, "low": None, "high": None, "scenes": 0}
    rng = np.random.default_rng(0)
    draws = logs[rng.integers(0, logs.size, (PAIRED_RESAMPLES, logs.size))].mean(axis=1)
    low, high = np.percentile(draws, [2.5, 97.5])
    return {
        "value": float(np.exp(logs.mean())),
        "low": float(np.exp(low)),
        "high": float(np.exp(high)),
        "scenes": int(logs.size),
    }


# --------------------------------------------------------------------------- report


def _num(value, digits: int = 4) -> str:
    return "–" if value is None else f"{value:.{digits}g}"


def _cell(summary: dict) -> str:
    text = _num(summary.get("value"))
    if summary.get("low") is not None and summary.get("high") is not None:
        text += f" [{_num(summary['low'], 3)}, {_num(summary['high'], 3)}]"
    if summary.get("spread"):
        text += f" (seeds {_num(summary['spread'][0], 3)}–{_num(summary['spread'][1], 3)})"
    return text


def markdown(result: StudyResult) -> str:
    """The study's report: the summary table, training set × third-party scene, the scaling curve."""
    o = result.options
    spp = o["spp"]
    lines = [
        "# Data-value study",
        "",
        f"Same model, same budget ({o['steps']} steps × batch {o['batch_size']} × {o['crop']}² px crops), "
        f"trained on subsets of the pool `{result.pool['path']}`; scored on `{result.third_party['path']}` "
        f"(split all, {spp} spp) by corrected scores aggregated over the kept scenes, with 95 % bootstrap "
        "intervals over scenes. Seeds: " + ", ".join(str(s) for s in o["seeds"]) + ".",
        "",
        "Third-party scenes kept: " + ", ".join(result.third_party.get("kept", [])) + ".",
    ]
    apart = result.third_party.get("set_apart") or {}
    if apart:
        lines += [
            "Set apart (as the benchmark report does; shown per scene below): "
            + "; ".join(f"{s} ({why})" for s, why in apart.items())
            + "."
        ]
    lines += [
        "",
        f"## Summary at {spp} spp",
        "",
        "| model | training set | scenes | relmse_robust (corrected) | FLIP | relmse_robust ÷ full (paired) "
        f"| FLIP ÷ full (paired) | relmse_robust ÷ {PEER} (paired) | FLIP ÷ {PEER} (paired) |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    kept = result.third_party.get("kept", [])
    peer = [{"scores": result.references[PEER]}] if PEER in result.references else None

    def versus_peer(parts: list[dict]) -> list[str]:
        return [_cell(paired_ratio(parts, peer, m, kept)) if peer else "–" for m in METRICS]

    for label, scores in result.references.items():
        mine = versus_peer([{"scores": scores}]) if label != PEER else ["1", "1"]
        lines.append(
            f"| {label} | (reference) | – | {_cell(scores['relmse_robust'])} | {_cell(scores['flip'])} | – | – "
            f"| {mine[0]} | {mine[1]} |"
        )
    groups = _groups(result.parts)
    for (model, name), parts in groups.items():
        cells = [_cell(seed_summary(parts, m)) for m in METRICS]
        full = groups.get((model, "full"))
        ratios = [_cell(paired_ratio(parts, full, m, kept)) if full and name != "full" else "1" for m in METRICS]
        mine = versus_peer(parts)
        lines.append(
            f"| {model} | {name} | {len(parts[0]['scenes'])} | {cells[0]} | {cells[1]} | {ratios[0]} | {ratios[1]} "
            f"| {mine[0]} | {mine[1]} |"
        )
    rules = {
        m: next((sc[m].get("rule") for sc in result.references.values() if sc[m].get("rule")), None) for m in METRICS
    }
    lines += [
        "",
        "Aggregates over scenes by each metric's rule (the benchmark report's lead): "
        + "; ".join(f"{m}: {_RULES.get(r, r)}" for m, r in rules.items() if r)
        + ".",
        "",
        "÷ full: the geometric mean over the kept scenes of this set's score over the same model's `full` "
        "score on the same scene, with a 95 % bootstrap interval over scenes (a scene's difficulty cancels; "
        f"scenes scoring 0 are left out); ÷ {PEER}: the same against {PEER}'s score on each scene (below 1: "
        "better than it).",
    ]
    scenes = result.third_party.get("scenes", [])
    for metric in METRICS:
        lines += [
            "",
            f"## {metric} per third-party scene ({spp} spp; mean over seeds)",
            "",
            "| model | training set | " + " | ".join(scenes) + " |",
            "|---|---|" + "---|" * len(scenes),
        ]
        for label, scores in result.references.items():
            per = scores[metric]["per_scene"]
            lines.append(f"| {label} | (reference) | " + " | ".join(_num(per.get(s)) for s in scenes) + " |")
        for (model, name), parts in groups.items():
            row = []
            for s in scenes:
                values = [p["scores"][metric]["per_scene"].get(s) for p in parts]
                values = [v for v in values if v is not None]
                row.append(_num(sum(values) / len(values) if values else None))
            lines.append(f"| {model} | {name} | " + " | ".join(row) + " |")
    lines += [
        "",
        "## Scaling curve",
        "",
        f"Error against the number of generated training scenes (the mix's round-robin prefixes); figure: `{FIGURE}`.",
        "",
        "| model | training scenes | set | relmse_robust (corrected) | FLIP |",
        "|---|---|---|---|---|",
    ]
    for model, rows in result.scaling.items():
        for row in rows:
            lines.append(
                f"| {model} | {row['scenes']} | {row['set']} | {_cell(row['relmse_robust'])} | {_cell(row['flip'])} |"
            )
    if result.missing:
        lines += [
            "",
            "## Not run",
            "",
            "Asked for, not finished when this report was written: " + ", ".join(result.missing) + ".",
        ]
    lines += ["", "## Training sets", ""]
    for s in result.sets:
        lines.append(f"* `{s['name']}` ({s['kind']}): {len(s['scenes'])} scenes of {', '.join(s['families'])}")
    return "\n".join(lines) + "\n"


#: How the aggregate rules read in the report (analysis/aggregate.py states them exactly).
_RULES = {
    LEAD_RULE: "each scene's score over the noisy input's on that scene, geometric mean without "
    f"the top and bottom {100 * SCENE_TRIM:g} % of scenes (the noisy input reads 1)",
    "mean": "arithmetic mean",
}


def _groups(parts: list[dict]) -> dict[tuple[str, str], list[dict]]:
    groups: dict[tuple[str, str], list[dict]] = {}
    for part in parts:
        groups.setdefault((part["model"], part["set"]), []).append(part)
    return groups


def scaling_figure(result: StudyResult, path: Path) -> Path | None:
    """The scaling curve (corrected relmse_robust against training scenes, log x) as a PNG; None when empty."""
    if not any(result.scaling.values()):
        return None
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(6.6, 3.6), dpi=120)
    models = [m for m, rows in result.scaling.items() if rows]
    for i, (model, rows) in enumerate(result.scaling.items()):
        rows = [r for r in rows if r["relmse_robust"]["value"] is not None]
        if not rows:
            continue
        # a small horizontal offset per model keeps overlapping intervals apart
        shift = 1.0 + 0.03 * (i - (len(models) - 1) / 2)
        x = [r["scenes"] * shift for r in rows]
        y = [r["relmse_robust"]["value"] for r in rows]
        low = [r["relmse_robust"]["low"] if r["relmse_robust"]["low"] is not None else v for r, v in zip(rows, y)]
        high = [r["relmse_robust"]["high"] if r["relmse_robust"]["high"] is not None else v for r, v in zip(rows, y)]
        ax.errorbar(
            x,
            y,
            yerr=[[max(v - lo, 0) for v, lo in zip(y, low)], [max(hi - v, 0) for v, hi in zip(y, high)]],
            marker="o",
            capsize=3,
            label=f"{model} (trained here)",
        )
    ax.set_xscale("log")
    ax.set_yscale("log")
    counts = sorted({r["scenes"] for rows in result.scaling.values() for r in rows})
    ax.set_xticks(counts, [str(c) for c in counts])
    ax.minorticks_off()
    styles = [(0, (5, 2)), (0, (1, 1)), (0, (3, 1, 1, 1)), (0, (8, 2, 1, 2)), (0, (2, 3))]
    for k, (label, scores) in enumerate(result.references.items()):
        value = scores["relmse_robust"]["value"]
        if value is not None and value > 0:
            ax.axhline(
                value,
                linestyle=styles[k % len(styles)],
                linewidth=0.9,
                color=str(0.15 + 0.12 * (k % 5)),
                label=f"{label} {value:.3g} ({'shipped weights' if label in MODEL_NAMES else 'reference'})",
            )
    rule = next((sc["relmse_robust"].get("rule") for sc in result.references.values()), None)
    ylabel = "relmse_robust ÷ noisy input" if rule == LEAD_RULE else "relmse_robust"
    ax.set_xlabel("generated training scenes")
    ax.set_ylabel(f"{ylabel} (corrected, log)")
    ax.legend(fontsize=7, loc="center left", bbox_to_anchor=(1.01, 0.5), frameon=False)
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)
    return path


def write_report(result: StudyResult, out: Path) -> Path:
    """Write ``study.json``, ``study.md`` and the scaling figure into ``out``; return the Markdown's path."""
    out = Path(out)
    (out / REPORT_JSON).write_text(json.dumps(asdict(result), indent=1, sort_keys=True) + "\n")
    scaling_figure(result, out / FIGURE)
    path = out / REPORT_MD
    path.write_text(markdown(result))
    return path
