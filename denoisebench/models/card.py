"""Model cards: the Markdown file shipped beside a weight file (``<model>_<config>.md``).

:func:`render_card` formats a checkpoint's metadata and a test-split evaluation (from
``denoisebench train --evaluate``) into the card: what the network is, the exact commands that
made the data and the weights, the dataset config and hash, training time, validation figures,
and relMSE on held-out scenes against identity and cross_bilateral with the margin stated and,
when the evaluation carries them, 95% bootstrap intervals (scenes resampled). Every stage of a
multi-stage run (``meta["stages"]``, one per ``denoisebench train`` command) is listed with its own
steps, learning rate, schedule and loss. Weights fine-tuned on another dataset (``train --init-from``)
list every earlier run first (``meta["earlier_runs"]``, :mod:`~denoisebench.models.provenance`): its
data, commands and stages, and held-out scenes are checked against the train scenes of every run.
Pure formatting: no torch, no metrics.
"""

from __future__ import annotations

import shlex

from denoisebench.models.provenance import all_train_scenes

DESCRIPTIONS = {
    "dpcn": "Direct-prediction convolutional network after Bako et al. 2017: two branches (albedo-demodulated "
    "diffuse, log specular), each a plain convolution stack that outputs the denoised colour of its lobe.",
    "kpcn": "Kernel-predicting convolutional network after Bako et al. 2017: two branches (albedo-demodulated "
    "diffuse, log specular), each predicting a softmax-normalised 21×21 kernel per pixel that is applied to "
    "the noisy lobe.",
    "rae": "Recurrent denoising autoencoder after Chaitanya et al. 2017: a U-Net with a recurrent block at "
    "every encoder level and the bottleneck, trained on 7-frame sequences with 0.8·L_s + 0.1·L_g + 0.1·L_t. "
    "Temporal: frames in order, reset() between sequences. With `residual` (the small configuration) the "
    "last layer outputs a correction to the input's own log colour rather than the colour itself.",
    "lbf": "Learning-based filter after Kalantari, Bako & Sen 2015: a per-pixel multi-layer perceptron reads "
    "feature statistics (block means and deviations, gradients, mean and median absolute deviations, colour "
    "variance) and predicts the bandwidths α, β, γ_k of a cross-bilateral filter (screen distance, log colour, "
    "albedo, normal, depth), which is applied differentiably; trained end to end on the filtered image with "
    "relative MSE.",
}


def generate_command(config: dict, out: str) -> str:
    """The generate-dataset command line that reproduces a dataset config written by ``denoisebench generate``."""
    if config.get("generator") != "denoisebench.generate":
        return f"# dataset {out} made by {config.get('generator', 'an unknown generator')}, not generate-dataset"
    parts = ["generate-dataset", "--out", out]
    if config.get("families"):
        parts += ["--families", ",".join(config["families"])]
    for key, flag in (("scenes", "--scenes"), ("frames", "--frames"), ("width", "--width"), ("height", "--height")):
        if key in config:
            parts += [flag, str(config[key])]
    if "spp" in config:
        parts += ["--spp", ",".join(str(s) for s in config["spp"])]
    if "ref_spp" in config:
        parts += ["--ref-spp", str(config["ref_spp"])]
    if "ref_error" in config:  # None: a fixed --ref-spp reference
        parts += ["--ref-error", "0" if config["ref_error"] is None else f"{config['ref_error']:g}"]
    if config.get("max_depth") is not None:
        parts += ["--max-depth", str(config["max_depth"])]
    if config.get("samples"):
        parts.append("--samples")
    parts += ["--seed", str(config.get("seed", 0))]
    return shlex.join(parts)


def _command_block(meta: dict, train_commands: list[str], data_dir: str) -> list[str]:
    """The card's commands: the training data's generate-dataset, the train commands; for weights scored on
    another dataset (``meta["evaluated_on"]``) that dataset's generate-dataset before the last (scoring) command;
    for fine-tuned weights every earlier run's generate-dataset and train commands first."""
    earlier: list[str] = []
    made = None  # the dataset hash the last generate-dataset line made (a run on the same data needs none)
    for run in meta.get("earlier_runs", []):  # fine-tuned weights: the runs they started from, oldest first
        if run.get("dataset_hash") != made:
            earlier.append(generate_command(run.get("dataset_config", {}), run.get("dataset") or "DATA"))
            made = run.get("dataset_hash")
        earlier += run.get("commands", [])
    elsewhere = meta.get("evaluated_on")
    own = (
        []
        if made is not None and meta.get("dataset_hash") == made
        else [  # the training data, where it was made
            generate_command(meta.get("dataset_config", {}), meta.get("dataset") or "DATA" if elsewhere else data_dir)
        ]
    )
    if not elsewhere:
        return [*earlier, *own, *train_commands]
    return [
        *earlier,
        *own,
        *train_commands[:-1],
        generate_command(elsewhere.get("dataset_config", {}), data_dir),
        *train_commands[-1:],
    ]


def _overlap_line(evaluation: dict, meta: dict) -> str:
    """Whether any test scene shares a name (family and seed) with a train scene of any run."""
    seen = sorted(set(evaluation["scenes"]) & all_train_scenes(meta))
    return (
        f"Test scenes that share a name (family and seed) with a training scene: {', '.join(seen)}."
        if seen
        else "None of its test scenes shares a name (family and seed) with a training scene."
    )


def _earlier_run_lines(meta: dict) -> list[str]:
    """Fine-tuned weights: one bullet per earlier run (its data, scenes, steps and own validation)."""
    lines = []
    for number, run in enumerate(meta.get("earlier_runs", []), 1):
        val = run.get("validation") or {}
        lines.append(
            f"* run {number} (the weights this one started from, `{run.get('checkpoint')}`): {run.get('steps')} steps on "
            f"dataset config hash `{run.get('dataset_hash')}`, config `{run.get('dataset_config')}`; train scenes "
            f"({len(run.get('train_scenes', []))}): {', '.join(run.get('train_scenes', []))}; val scenes: "
            f"{', '.join(run.get('val_scenes', [])) or 'none'}"
            + (f"; its val relMSE {val['relmse']:.5f} (noisy {val['relmse_noisy']:.5f})" if val else "")
        )
    if lines:
        lines.append(
            f"* run {len(lines) + 1} (this card's weights), fine-tuned from run {len(lines)} on the data below:"
        )
    return lines


def _scored_elsewhere_lines(elsewhere: dict, meta: dict, evaluation: dict) -> list[str]:
    """The scoring dataset's hash, val figure and whether its test scenes share names with training scenes."""
    if not elsewhere:
        return []
    lines = [
        "",
        f"Scored on another dataset than the training one: config hash `{elsewhere.get('dataset_hash')}`, "
        f"config `{elsewhere.get('dataset_config')}`.",
    ]
    val = elsewhere.get("validation") or {}
    if val:
        lines.append(
            f"On its val split: relMSE {val['relmse']:.5f} against the noisy input's {val['relmse_noisy']:.5f} "
            f"(ratio {val['relmse_ratio']:.3f}) over {val['frames']} frames."
        )
    lines.append(_overlap_line(evaluation, meta))
    return lines


def _machine(meta: dict) -> str:
    """The training machine as the checkpoint recorded it (``meta["machines"]``, one entry per stage)."""
    machines = meta.get("machines") or []
    if not machines:
        return "a machine the checkpoint does not record"
    return " and ".join(dict.fromkeys(machines))


def _threads(used: list[int]) -> str:
    """'one CPU thread', 'two CPU threads', or '1 and 2 CPU threads' when the commands differed."""
    words = {1: "one", 2: "two"}
    if len(used) == 1:
        n = used[0]
        return f"{words.get(n, n)} CPU thread{'s' if n != 1 else ''}"
    return f"{' and '.join(str(n) for n in used)} CPU threads (see the commands)"


def _stage_lines(meta: dict) -> list[str]:
    """One bullet per training stage (command); a checkpoint from before stages were recorded gets its summary.

    Fine-tuned weights list the earlier runs' stages first, each stage with its run's number."""
    earlier = meta.get("earlier_runs", [])
    stages = [(number, stage) for number, run in enumerate(earlier, 1) for stage in run.get("stages", [])]
    stages += [(len(earlier) + 1, stage) for stage in meta.get("stages") or []]
    stages = [(run, stage) for run, stage in stages if stage["steps"] > 0]  # a --steps 0 command trained nothing
    if not stages:
        return [
            f"* {meta.get('steps')} steps of batch {meta.get('batch_size')} × {meta.get('crop')}² crops"
            + f", spp {meta.get('spp')}, Adam lr {meta.get('lr')} (of the last command), seed {meta.get('seed')}, torch {meta.get('torch')}"
        ]
    lines = [
        f"* {meta.get('steps')} steps in {len(stages)} stage(s), seed {meta.get('seed')}, torch {meta.get('torch')}:"
    ]
    for number, (run, stage) in enumerate(stages, 1):
        lines.append(
            f"  {number}. {f'run {run}, ' if earlier else ''}steps {stage['from_step']}–{stage['from_step'] + stage['steps']}: batch {stage['batch_size']} × "
            f"{stage['crop']}² crops, spp {stage['spp']}, Adam lr {stage['lr']} ({stage['lr_schedule']}), "
            f"loss {stage['loss']}, {stage['device']}, {stage['threads']} thread(s)"
        )
    return lines


def _interval(evaluation: dict, key: str, name: str) -> str:
    ci = (evaluation.get(key) or {}).get(name)
    return f" [95% CI {ci[0]:.5f}–{ci[1]:.5f}]" if ci else ""


def _ratio_interval(evaluation: dict, peer: str) -> str:
    ci = (evaluation.get("ratio_ci95") or {}).get(peer)
    return f"; ratio's 95% CI {ci[0]:.3f}–{ci[1]:.3f}" if ci else ""


def _pct(ours: float, peer: float) -> str:
    return f"{100.0 * (1.0 - ours / peer):.1f}% lower" if ours <= peer else f"{100.0 * (ours / peer - 1.0):.1f}% HIGHER"


def render_card(
    model: str,
    config_name: str,
    config: dict,
    parameters: int,
    file_name: str,
    file_bytes: int,
    meta: dict,
    evaluation: dict,
    train_commands: list[str],
    data_dir: str,
    named_config: dict | None = None,
    sections: list[str] | None = None,
) -> str:
    """The card's Markdown. ``named_config``: today's keywords of ``config_name``; when the weights'
    ``config`` differs (weights made before the configuration changed, kept by ``--init-from``), the
    card says so. ``sections``: Markdown lines placed before "Limits" (the third-party scores of
    ``train --ship --third-party``, :func:`denoisebench.study.card_scores.card_section`)."""
    val = meta.get("validation") or {}
    scored_elsewhere = meta.get("evaluated_on") or {}
    relmse = evaluation["relmse"]
    ours = relmse[model]
    lines = [
        f"# {model} ({config_name}) — model card",
        "",
        DESCRIPTIONS.get(model, model),
        "",
        f"* weights: `{file_name}` ({file_bytes / 1024:.0f} KiB, {parameters:,} parameters, float32); "
        "load with `load_denoiser(\"" + model + "\")` (default) or `--option checkpoint=PATH` for your own",
        f"* configuration `{config_name}`: `{config}`"
        + (
            ""
            if named_config is None or named_config == config
            else f" (the shape these weights were first trained in; today's `{config_name}` is `{named_config}`: "
            "`--init-from` keeps a checkpoint's shape)"
        ),
        f"* inputs: {', '.join(meta.get('buffers', []))} (+ color); trained against {', '.join(meta.get('targets', []))}",
        "",
        "## How it was made (exact commands)",
        "",
        "```sh",
        *_command_block(meta, train_commands, data_dir),
        "```",
        "",
        "The last command, run with `--ship denoisebench/models/weights`"
        + (
            ""
            if list(evaluation["ratio"]) == ["identity", "cross_bilateral"]
            else f" `--peers {','.join(evaluation['ratio'])}`"
        )
        + (" and `--third-party DIR` for each dataset named under Third-party scenes" if sections else "")
        + " added, also scored the test split and wrote these weights (without optimiser state) and this card."
        + (
            " It adds no steps (`--steps 0`): it validates and ships the checkpoint the command before it wrote."
            if train_commands and " --steps 0 " in f"{train_commands[-1]} " and not scored_elsewhere
            else ""
        )
        + (
            " It adds no steps (`--steps 0`): it scores the weights the commands before it made on the val and test"
            " splits of the dataset made by the second `generate-dataset` command, not the one they were trained on."
            if scored_elsewhere
            else ""
        ),
        "",
        *_earlier_run_lines(meta),
        f"* dataset config hash `{meta.get('dataset_hash')}`; config `{meta.get('dataset_config')}`",
        f"* train scenes ({len(meta.get('train_scenes', []))}): {', '.join(meta.get('train_scenes', []))}",
        f"* val scenes: {', '.join(meta.get('val_scenes', [])) or 'none'}; test (held-out) scenes: {', '.join(evaluation['scenes'])}",
        *_stage_lines(meta),
        *([f"* sequences of {meta.get('sequence_length')} frames"] if model == "rae" else []),
        f"* training time: {meta.get('seconds', 0.0) / 60.0:.1f} min on {_threads(meta.get('threads', [1]))} of {_machine(meta)}"
        + (f" ({meta.get('skipped_steps')} non-finite steps skipped)" if meta.get("skipped_steps") else ""),
        "",
        "## Validation (val split, whole frames, during training)",
        "",
    ]
    if val:
        lines += [
            f"relMSE {val['relmse']:.5f} against the noisy input's {val['relmse_noisy']:.5f} "
            f"(ratio {val['relmse_ratio']:.3f}) over {val['frames']} frames of {', '.join(val['scenes'])} at spp {val['spp']}.",
        ]
    else:
        lines.append("The dataset had no val split.")
    lines += _scored_elsewhere_lines(scored_elsewhere, meta, evaluation)
    if meta.get("earlier_runs") and not scored_elsewhere:
        lines += ["", _overlap_line(evaluation, meta)]
    lines += [
        "",
        f"## Held-out scenes (test split: {evaluation['frames']} frames per denoiser, every spp)",
        "",
        "relMSE = mean((p−r)²/(r²+0.01)), linear HDR, mean over frames (`denoisebench.metrics`)"
        + (
            "; intervals: 95% percentile bootstrap over the test scenes (each resampled scene brings all its frames)."
            if evaluation.get("relmse_ci95")
            else "."
        ),
        "",
        "| denoiser | relMSE | " + " | ".join(f"spp {s}" for s in evaluation["relmse_by_spp"][model]) + " |",
        "|---|---|" + "---|" * len(evaluation["relmse_by_spp"][model]),
    ]
    for name, value in relmse.items():
        by_spp = evaluation["relmse_by_spp"][name]
        lines.append(
            f"| {name} | {value:.5f}{_interval(evaluation, 'relmse_ci95', name)} | "
            + " | ".join(f"{v:.5f}" for v in by_spp.values())
            + " |"
        )
    lines += [""]
    for peer, ratio in evaluation["ratio"].items():
        lines.append(
            f"* against {peer}: relMSE {ours:.5f} vs {relmse[peer]:.5f}, ratio {ratio:.3f} ({_pct(ours, relmse[peer])})"
            + _ratio_interval(evaluation, peer)
        )
    lines += ["", *(sections or [])]
    lines += [
        "## Limits",
        "",
        f"Trained for minutes on a CPU on {len(all_train_scenes(meta))} small scenes "
        f"({meta.get('dataset_config', {}).get('width', '?')}×{meta.get('dataset_config', {}).get('height', '?')} "
        "pixels): a reference point for the harness, not a production denoiser. The paper configuration "
        "(`--config paper`) is the published size and needs far more data and training.",
        "",
    ]
    return "\n".join(lines)
