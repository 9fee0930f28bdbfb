"""The leaderboard's records and schema: typed store rows, one finite filter, one per-scene value, one
unit set, the plan the Ray executor sends, and samplers as a dimension of a run (store schema 5).

Synthetic, no rendering: sampler pairs are registered and written with planted frame values (their
live rendering is covered by tests/sampling/test_live.py); the two consumers of per-scene values
(the report's summary table and ``denoisebench leaderboard``) are compared on a run the real runner
measured.
"""

from __future__ import annotations

import pickle
import sqlite3

import numpy as np
import pytest

from denoisebench.analysis import ranking as table
from denoisebench.analysis.summary import summary_table
from denoisebench.benchmark.ray_executor import light_plan, needed_denoisers
from denoisebench.benchmark.run import run_benchmark
from denoisebench.benchmark.runner import BenchmarkConfig, LoadedDenoiser, RunPlan, pending_groups
from denoisebench.benchmark.sampler_units import SamplerPair, register_pairs
from denoisebench.dataset import open_dataset
from denoisebench.dataset.synthetic import make_synthetic_dataset
from denoisebench.reports.leaderboard import leaderboard
from denoisebench.reports.run_inputs import run_data
from denoisebench.results.finite import finite_mean, finite_or_none, finite_values, is_finite
from denoisebench.results.names import NOISY
from denoisebench.results.records import EntryRow, FrameRecord, FrameRow, UnitRecord, UnitRow
from denoisebench.results.schema import SCHEMA_VERSION, sampler_dimension
from denoisebench.results.store import ResultsStore

# ----------------------------------------------------------------------------------------------- finite


def test_one_finite_filter_drops_none_nan_and_inf_and_keeps_order():
    values = [1.0, None, float("nan"), 2.5, float("inf"), -float("inf"), np.float32(3.0), 0.0]
    assert finite_values(values) == [1.0, 2.5, 3.0, 0.0]
    assert [is_finite(v) for v in values] == [True, False, False, True, False, False, True, True]
    assert finite_or_none(float("nan")) is None and finite_or_none(None) is None and finite_or_none(np.int64(2)) == 2.0
    assert finite_mean(values) == pytest.approx(6.5 / 4) and finite_mean([None, float("nan")]) is None


# ----------------------------------------------------------------------------------------------- unit set


def _plan(labels=("a", "b"), samplers=()) -> RunPlan:
    denoisers = [
        LoadedDenoiser(label=label, spec=label, instance=object(), needs=frozenset({"color"}), temporal=False)
        for label in labels
    ]
    return RunPlan(
        run_id="run",
        scenes=["s1", "s2"],
        spp=[1, 4],
        denoisers=denoisers,
        spatial=["relmse"],
        temporal=[],
        resumed=False,
        samplers=list(samplers),
    )


def test_the_unit_set_is_every_label_scene_and_spp_once_and_pending_groups_are_what_is_missing():
    plan = _plan()
    keys = plan.unit_keys()
    assert len(keys) == len(set(keys)) == plan.total_units == 3 * 2 * 2  # noisy, a, b × 2 scenes × 2 spp
    assert set(keys) == {(lab, s, p) for lab in (NOISY, "a", "b") for s in ("s1", "s2") for p in (1, 4)}
    done = {(NOISY, "s1", 1), ("a", "s1", 1), ("b", "s1", 1), ("a", "s2", 4)}
    assert set(plan.missing(done)) == set(keys) - done
    groups = pending_groups(plan, done)
    assert [(s, p) for s, p, _ in groups] == [("s1", 4), ("s2", 1), ("s2", 4)]  # ("s1", 1) is complete
    assert {(lab, s, p) for s, p, labels in groups for lab in labels} == set(keys) - done
    assert plan.missing(set(keys)) == [] and pending_groups(plan, set(keys)) == []


# ----------------------------------------------------------------------------------------------- Ray plan


def test_the_plan_sent_to_ray_tasks_keeps_trained_scenes_and_sampler_pairs_without_instances():
    pair = SamplerPair(label="uniform+a", sampler="uniform", denoiser="a")
    plan = _plan(samplers=[SamplerPair(label="uniform", sampler="uniform", denoiser=None), pair])
    plan.denoisers[0].trained_scenes = frozenset({"s1", "elsewhere"})
    plan.denoisers[1].load_error = "no module named b"
    light = pickle.loads(pickle.dumps(light_plan(plan)))  # what travels to a task
    assert all(d.instance is None for d in light.denoisers) and all(d.instance is not None for d in plan.denoisers)
    for sent, kept in zip(light.denoisers, plan.denoisers):
        assert (sent.label, sent.spec, sent.needs, sent.temporal, sent.load_error, sent.trained_scenes) == (
            kept.label,
            kept.spec,
            kept.needs,
            kept.temporal,
            kept.load_error,
            kept.trained_scenes,
        )
    assert light.trained_on() == plan.trained_on() == {"a": ["s1"]}
    assert light.samplers == plan.samplers and light.unit_keys() == plan.unit_keys()
    # a task measuring only the pair still loads the pair's denoiser
    assert needed_denoisers(light, ["uniform+a"]) == {"a"} and needed_denoisers(light, ["uniform", NOISY]) == {NOISY}


# ----------------------------------------------------------------------------------------------- typed rows


def _frame(index: int, relmse: float, seconds: float = 0.01) -> FrameRecord:
    return FrameRecord(
        frame=index,
        status="ok",
        error=None,
        render_seconds=0.1,
        denoise_seconds=seconds,
        total_seconds=0.1 + seconds,
        metrics={"relmse": relmse},
    )


PLANTED = {NOISY: 0.8, "box": 0.2, "uniform": 0.6, "uniform+box": 0.1}  # relMSE of each label's frame 0


def _sampler_store(path) -> ResultsStore:
    """One run: noisy and ``box`` on the stored inputs, ``uniform`` alone and with ``box``, planted relMSE."""
    store = ResultsStore(path)
    store.ensure_run(
        "run1",
        dataset_hash="hash",
        dataset_path="/nowhere",
        config={"denoisers": ["box"], "samplers": ["uniform"]},
        versions={},
    )
    plain = dict(run_id="run1", needs={"color"}, temporal=False, load_error=None)
    store.add_denoiser(label=NOISY, spec=NOISY, kind="input", **plain)
    store.add_denoiser(label="box", spec="box", kind="denoiser", **plain)
    box = LoadedDenoiser(label="box", spec="box", instance=object(), needs=frozenset({"color"}), temporal=False)
    register_pairs(
        store,
        "run1",
        [
            SamplerPair(label="uniform", sampler="uniform", denoiser=None),
            SamplerPair(label="uniform+box", sampler="uniform", denoiser="box"),
        ],
        [box],
    )
    for label, value in PLANTED.items():
        for scene, factor in (("s1", 1.0), ("s2", 3.0)):
            frames = [_frame(t, value * factor * (1 + 0.1 * t)) for t in range(2)]
            assert store.write_unit(
                "run1", UnitRecord(denoiser=label, scene=scene, spp=4, status="ok", error=None, frames=frames)
            )
    return store


DIMENSION = {NOISY: (None, None), "box": (None, "box"), "uniform": ("uniform", None), "uniform+box": ("uniform", "box")}


def test_the_store_returns_typed_rows_read_by_attribute_and_written_to_json_with_the_dicts_keys(tmp_path):
    with _sampler_store(tmp_path / "r.sqlite") as store:
        frames, units, entries = store.frames("run1"), store.units("run1"), store.denoisers("run1")
        run = store.run("run1")
    assert all(isinstance(f, FrameRow) for f in frames) and all(isinstance(u, UnitRow) for u in units)
    assert all(isinstance(d, EntryRow) for d in entries) and run.config["samplers"] == ["uniform"]
    f = frames[0]
    assert f.floors == {} and f.as_dict()["metrics"] is f.metrics
    with pytest.raises(TypeError):  # no key access: a row is read by attribute
        f["metrics"]
    assert not hasattr(f, "get")
    assert list(f.as_dict()) == [
        "denoiser", "scene", "spp", "frame", "status", "error", "render_seconds", "denoise_seconds",
        "total_seconds", "sanitized", "metrics", "floors", "ref_se",
    ]  # fmt: skip
    # results.json's "denoisers" keep their keys; the sampler dimension is an attribute
    assert list(entries[0].as_dict()) == ["label", "spec", "kind", "needs", "temporal", "load_error", "trained_on"]
    assert {d.label: (d.sampler, d.denoiser_label) for d in entries} == DIMENSION
    with ResultsStore(tmp_path / "r.sqlite", readonly=True) as store:
        data = run_data(store, "run1")
    assert {label: (data.entry(label).sampler, data.entry(label).denoiser_label) for label in data.labels} == DIMENSION
    assert data.entry("nope") is None and data.entries == entries
    assert data.frame_rows == frames and data.run == run


# ----------------------------------------------------------------------------------------------- samplers


@pytest.mark.parametrize(
    ("kind", "label", "spec", "expected"),
    [
        ("input", NOISY, NOISY, (None, None)),
        ("denoiser", "oidn#2", "oidn", (None, "oidn#2")),
        ("sampler", "ci_stop", "sampler ci_stop", ("ci_stop", None)),
        ("sampler", "ci_stop+oidn#2", "sampler ci_stop + oidn", ("ci_stop", "oidn#2")),
        ("sampler", "/p/s.py:Var+kpcn", "sampler /p/s.py:Var + kpcn:ckpt=x", ("/p/s.py:Var", "kpcn")),
    ],
)
def test_the_sampler_dimension_of_a_row_from_its_kind_label_and_spec(kind, label, spec, expected):
    assert sampler_dimension(kind, label, spec) == expected


def _make_version_4(path) -> None:
    with sqlite3.connect(path) as conn:
        conn.execute("ALTER TABLE run_denoisers DROP COLUMN sampler")
        conn.execute("ALTER TABLE run_denoisers DROP COLUMN denoiser_label")
        conn.execute("UPDATE schema_version SET version = 4")


def test_a_version_4_store_reads_and_migrates_to_the_same_sampler_dimension(tmp_path):
    path = tmp_path / "old.sqlite"
    _sampler_store(path).close()
    _make_version_4(path)
    with ResultsStore(path, readonly=True) as old:
        assert old.version == 4
        assert {d.label: (d.sampler, d.denoiser_label) for d in old.denoisers("run1")} == DIMENSION
        before = leaderboard(old, "relmse", 4).entries
    with ResultsStore(path) as migrated:
        assert migrated.version == SCHEMA_VERSION
        assert {d.label: (d.sampler, d.denoiser_label) for d in migrated.denoisers("run1")} == DIMENSION
        after = leaderboard(migrated, "relmse", 4).entries
    with sqlite3.connect(path) as conn:  # the migration stored the columns
        stored = dict(
            (r[0], (r[1], r[2])) for r in conn.execute("SELECT label, sampler, denoiser_label FROM run_denoisers")
        )
    assert stored == DIMENSION and before == after


def test_the_leaderboard_ranks_one_sampler_or_the_stored_inputs_and_groups_by_sampler(tmp_path):
    with _sampler_store(tmp_path / "r.sqlite") as store:
        every = leaderboard(store, "relmse", 4).entries
        uniform = leaderboard(store, "relmse", 4, sampler="uniform").entries
        stored = leaderboard(store, "relmse", 4, sampler="").entries
    assert [e.denoiser for e in every] == ["uniform+box", "box", "uniform", NOISY]  # planted: 0.1 < 0.2 < 0.6 < 0.8
    assert [(e.denoiser, e.sampler, e.denoiser_label) for e in uniform] == [
        ("uniform+box", "uniform", "box"),
        ("uniform", "uniform", None),
    ]
    assert [e.denoiser for e in stored] == ["box", NOISY]
    groups = table.by_sampler(every)
    assert {k: [e.denoiser for e in v] for k, v in groups.items()} == {
        "uniform": ["uniform+box", "uniform"],
        None: ["box", NOISY],
    }
    # the entries keep their values whatever the filter; relMSE leads with the anchored trimmed geometric
    # mean (analysis.lead): each scene's frame mean (planted value × scene factor × mean(1, 1.1)) as a share
    # of the noisy input's on that scene at the run's lowest spp, so the planted ratio to the input
    by_label = {e.denoiser: e.value for e in every}
    assert {e.denoiser: e.value for e in uniform} == {k: by_label[k] for k in ("uniform+box", "uniform")}
    assert by_label == pytest.approx({k: v / PLANTED[NOISY] for k, v in PLANTED.items()}, rel=1e-12)


# ----------------------------------------------------------------------------------------------- per-scene


@pytest.fixture(scope="module")
def measured_run(tmp_path_factory):
    root = tmp_path_factory.mktemp("records")
    data = open_dataset(make_synthetic_dataset(root / "ds", scenes=2, frames=3, height=16, width=16, spp=(1, 4)))
    store = ResultsStore(root / "r.sqlite")
    config = BenchmarkConfig(
        denoisers=["identity", "cross_bilateral_fast"],
        spp=[1, 4],
        split="all",
        metrics=["relmse", "ssim", "temporal_l1"],
    )
    plan = run_benchmark(data, config, store, progress=False)
    yield store, plan.run_id
    store.close()


def test_the_summary_table_and_the_leaderboard_read_the_same_per_scene_values(measured_run):
    store, run_id = measured_run
    data = run_data(store, run_id)
    summary = {(r.denoiser, r.spp): r for r in summary_table(data)}
    metrics = ["relmse", "ssim", "relmse_robust", "temporal_relmse", "tpsnr"]
    assert set(metrics) <= set(data.frame_metric_names + data.sequence_metric_names)
    for metric in metrics:
        for spp in (1, 4):
            entries = leaderboard(store, metric, spp).entries
            for e in entries:
                cell = summary[(e.denoiser, spp)].metrics[metric]
                assert e.value == pytest.approx(cell.value, rel=1e-12)
    # a temporal metric stored per frame pair too has the mean of its pairs (two of three frames: no trim),
    # one stored per sequence only the sequence's value
    scene = data.scenes[0]
    sequence = {
        s.metric: s.value
        for s in store.sequence_metrics(run_id)
        if (s.denoiser, s.spp, s.scene) == ("identity", 1, scene)
    }
    pairs = [
        f.metrics["flicker.tpsnr"]
        for f in store.frames(run_id)
        if (f.denoiser, f.spp, f.scene) == ("identity", 1, scene) and "flicker.tpsnr" in f.metrics
    ]
    assert len(pairs) == 2 and data.scene_value("identity", 1, scene, "tpsnr") == pytest.approx(sum(pairs) / 2)
    assert data.scene_value("identity", 1, scene, "tpsnr") != pytest.approx(sequence["tpsnr"], rel=1e-9)
    only = [m for m in sequence if "flicker." + m not in data.flicker_names]
    assert only and all(data.scene_value("identity", 1, scene, m) == sequence[m] for m in only)
    frames = [f.metrics["ssim"] for f in store.frames(run_id) if (f.denoiser, f.spp, f.scene) == ("identity", 1, scene)]
    # a spatial one the trimmed mean of its frames (run_index.kept_frames): of three, the median
    assert len(frames) == 3 and data.scene_value("identity", 1, scene, "ssim") == pytest.approx(sorted(frames)[1])


def test_the_leaderboard_command_takes_a_sampler_and_refuses_one_never_measured(tmp_path, capsys):
    from denoisebench.cli import main

    _sampler_store(tmp_path / "r.sqlite").close()
    args = ["leaderboard", "--db", str(tmp_path / "r.sqlite"), "--metric", "relmse", "--spp", "4"]

    def ranked(out: str) -> list[str]:  # the table's rows: after the heading, its notes and the rules
        lines = out.strip().splitlines()
        start = next(i for i, line in enumerate(lines) if line.startswith("-")) + 1
        return [line.split()[1] for line in lines[start:]]

    assert main([*args, "--sampler", "uniform"]) == 0
    assert ranked(capsys.readouterr().out) == ["uniform+box", "uniform"]
    assert main([*args, "--sampler", "none"]) == 0
    assert ranked(capsys.readouterr().out) == ["box", NOISY]
    assert main([*args, "--sampler", "hachisuka2008"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "sampler 'hachisuka2008'" in err[0] and "samplers measured: uniform" in err[0]
