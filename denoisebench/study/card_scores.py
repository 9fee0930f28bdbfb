"""A trained model's scores on third-party scenes, for its model card (``train --ship --third-party DIR``).

The data-value study asks what the generator's scenes are worth; a model card asks the narrower
question its reader has: how do *these* weights do on scenes nobody here wrote, beside the noisy
input and the classics. :func:`score_checkpoint` benchmarks the checkpoint with the references
(:data:`~denoisebench.study.data_value.REFERENCES`: cross_bilateral, OIDN) on every third-party
dataset at every input spp they all have, pooled as the study pools them
(:func:`~denoisebench.study.data_value.pooled_run_data`), and reads corrected scores with their
intervals over scenes as a report reads them (:func:`~denoisebench.study.data_value.read_scores`).
:func:`card_section` writes the card's "Third-party scenes" section from that record: a table per
metric and spp, and each spp's paired comparison with the noisy input and with cross_bilateral
(the geometric mean over scenes of the per-scene ratio, with its bootstrap interval:
:func:`~denoisebench.study.report.paired_ratio`), worded "beats" / "ties" / "loses to" by whether
the interval lies below 1, holds 1, or lies above it.

Scenes a report would set apart (:func:`~denoisebench.reports.run_inputs.set_apart_of`) are judged
at every spp from the run that holds the checkpoint and the references, and the union is left out
of every cell, so all spp compare over the same scenes.

Pitfalls: the results store (``OUT/study.sqlite``) resumes: the checkpoint's sha256 is part of
its runs' identity (retrained weights are scored anew), the references' runs are reused. The
judgement of which scenes to set apart depends on which denoisers are in the run (a scene no
denoiser separates from its floor cannot be ranked), so the card's kept scenes may differ from a
study's that scored other references.
"""

from __future__ import annotations

import hashlib
from pathlib import Path

from denoisebench.errors import UserInputError
from denoisebench.results.names import NOISY
from denoisebench.results.store import ResultsStore
from denoisebench.study.data_value import (
    METRICS,
    REFERENCES,
    STORE_NAME,
    benchmark_third_party,
    kept_scenes,
    open_third_party,
    pooled_run_data,
    read_scores,
    set_apart_in,
)
from denoisebench.study.report import PEER, paired_ratio


def score_checkpoint(
    model: str,
    checkpoint: Path,
    folders,
    out: Path,
    references=REFERENCES,
    progress: bool = True,
) -> dict:
    """Benchmark ``checkpoint`` (of ``model``) and ``references`` on the pooled third-party datasets
    ``folders`` at every spp they share; return ``{"datasets", "spp", "kept", "set_apart",
    "scores": {spp: {label: read_scores(...)}}}`` (labels: the noisy input, ``model``, the references)."""
    folders = [Path(f) for f in folders]
    thirds = open_third_party(folders)
    spps = sorted(set.intersection(*[{s for name in t.scenes for s in t.scene(name).spp} for t in thirds]))
    if not spps:
        raise UserInputError("--third-party: the datasets share no input spp to score at")
    digest = hashlib.sha256(Path(checkpoint).read_bytes()).hexdigest()
    extra = {
        "options": {model: {"checkpoint": str(Path(checkpoint).resolve())}},
        "nonce": f"checkpoint sha256 {digest}",
    }
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    runs, apart = {}, {}
    with ResultsStore(out / STORE_NAME) as store:
        for spp in spps:
            runs[spp] = benchmark_third_party(folders, spp, store, [model, *references], extra, progress)
            scenes, here = set_apart_in(store, runs[spp], thirds)
            apart.update({scene: f"{reason} (at {spp} spp)" for scene, reason in here.items()})
        kept = kept_scenes(scenes, apart)
        scores = {}
        for spp in spps:
            pooled = pooled_run_data(store, runs[spp])
            scores[spp] = {label: read_scores(pooled, label, spp, kept) for label in [NOISY, model, *references]}
    return {
        "datasets": [{"path": str(f), "scenes": list(t.scenes)} for f, t in zip(folders, thirds)],
        "spp": spps,
        "kept": kept,
        "set_apart": apart,
        "checkpoint_sha256": digest,
        "scores": scores,
    }


def _cell(score: dict) -> str:
    if score.get("value") is None:
        return "–"
    return f"{score['value']:.3g} [{score['low']:.3g}, {score['high']:.3g}]"


def verdict(ratio: dict) -> str:
    """'beats' / 'loses to' when the paired interval lies wholly below / above 1, else 'ties'."""
    if ratio.get("value") is None:
        return "cannot be compared with"
    if ratio["high"] < 1:
        return "beats"
    if ratio["low"] > 1:
        return "loses to"
    return "ties"


def paired(record: dict, model: str, other: str, spp: int, metric: str) -> dict:
    """``model`` ÷ ``other`` per kept scene at ``spp``, geometric mean with its interval, and on how many scenes it is lower."""
    scores = record["scores"][spp]
    ratio = paired_ratio([{"scores": scores[model]}], [{"scores": scores[other]}], metric, record["kept"])
    mine, theirs = scores[model][metric]["per_scene"], scores[other][metric]["per_scene"]
    ratio["better"] = sum(1 for s in record["kept"] if s in mine and s in theirs and mine[s] < theirs[s])
    return ratio


def card_section(model: str, record: dict) -> list[str]:
    """The card's "Third-party scenes" section (Markdown lines) from :func:`score_checkpoint`'s record."""
    spps, kept = record["spp"], record["kept"]
    labels = [model, NOISY, *[label for label in record["scores"][spps[0]] if label not in (model, NOISY)]]
    datasets = "; ".join(f"`{Path(d['path']).name}` ({len(d['scenes'])} scenes)" for d in record["datasets"])
    lines = [
        "## Third-party scenes (scenes nobody here wrote)",
        "",
        f"Beside the held-out seeds above: {datasets}, scored as one "
        f"(`train --ship --third-party DIR`, repeated; `denoisebench.study.card_scores`). "
        f"{len(kept)} scenes scored"
        + (
            "; set apart as the report sets them apart: "
            + ", ".join(f"{scene} ({why})" for scene, why in sorted(record["set_apart"].items()))
            if record["set_apart"]
            else ""
        )
        + ". relmse_robust is floor-corrected and aggregated as the report's lead (each scene's score ÷ the "
        "noisy input's at the same spp, trimmed geometric mean: the input reads 1); FLIP is the mean over scenes; "
        "95 % bootstrap intervals over scenes. Paired: the geometric mean over scenes of the per-scene ratio, with its "
        "interval; a row beats another where that interval lies below 1.",
        "",
        "| denoiser | " + " | ".join(f"{metric} {spp} spp" for metric in METRICS for spp in spps) + " |",
        "|---|" + "---|" * (len(METRICS) * len(spps)),
    ]
    for label in labels:
        cells = [_cell(record["scores"][spp][label][metric]) for metric in METRICS for spp in spps]
        lines.append(f"| {label} | " + " | ".join(cells) + " |")
    lines.append("")
    for spp in spps:
        parts = []
        for other in (NOISY, PEER):
            if other not in record["scores"][spp]:
                continue
            said = []
            for metric in METRICS:
                ratio = paired(record, model, other, spp, metric)
                said.append(
                    f"{verdict(ratio)} it by {metric} ({_cell(ratio)}, better on {ratio['better']}/{len(kept)} scenes)"
                )
            parts.append(f"against {'the noisy input' if other == NOISY else other}: " + "; ".join(said))
        lines.append(f"* {spp} spp, {model} " + "; ".join(parts) + ".")
    lines.append("")
    return lines
