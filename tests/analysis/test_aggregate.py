"""Scores that rank right: aggregation rules over scenes, floors through the store and
report, results-store migration, indistinguishable pairs, frame strips.

Synthetic, no rendering: units are measured by the real runner (``measure_unit``) on in-memory
sequences, or written with planted values whose provenance is the issue's own measurement.
"""

from __future__ import annotations

import math
import sqlite3

import numpy as np
import pytest

from denoisebench.analysis import aggregate as agg
from denoisebench.analysis.summary import indistinguishable_pairs, summary_table
from denoisebench.benchmark.measure import measure_unit
from denoisebench.dataset.frame import Frame, Sequence
from denoisebench.reports import strips
from denoisebench.reports.run_inputs import run_data
from denoisebench.results import crops
from denoisebench.results.names import NOISY
from denoisebench.results.records import FrameRecord, UnitRecord
from denoisebench.results.schema import SCHEMA_VERSION
from denoisebench.results.store import ResultsStore
from tests.support.paths import REPO

SCENES = {"dark": 0.05, "plain": 1.0, "glossy_fireflies": 300.0}  # very different brightness


class Blur:
    """A denoiser-like smooth prediction: a Gaussian blur of the noisy frame."""

    name = "blur"
    needs = frozenset({"color"})
    temporal = False

    def reset(self):
        pass

    def denoise(self, frame):
        from scipy.ndimage import gaussian_filter

        return gaussian_filter(frame.color, sigma=(1.5, 1.5, 0)).astype(np.float32)


def _sequence(scene: str, scale: float, spp: int, frames: int = 8, size: int = 24) -> Sequence:
    rng = np.random.default_rng([spp, int(scale * 100)])
    yy, xx = np.mgrid[0:size, 0 : size + frames]
    base = scale * (0.3 + 0.5 * np.sin(xx / 5.0) ** 2 + 0.4 * (yy / size))[..., None] * np.array([1.0, 0.8, 0.6])
    out = []
    for t in range(frames):
        ref = base[:, t : t + size].astype(np.float32)
        noisy = (ref * rng.gamma(spp, 1.0 / spp, ref.shape)).astype(np.float32)  # mean-preserving MC-like noise
        motion = np.zeros((size, size, 2), np.float32)
        motion[..., 0] = 1.0  # the camera pans: the point at x was at x + 1 in the previous frame
        var = (0.01 * ref) ** 2  # a reference 1 % noisy
        out.append(
            Frame(
                {"color": noisy, "motion": motion}, spp, scene, t, ref, meta={"reference_buffers": {"color_var": var}}
            )
        )
    return Sequence(scene, spp, out)


def _store_with_units(path, units, labels=(NOISY, "blur")) -> tuple[ResultsStore, str]:
    store = ResultsStore(path)
    store.ensure_run(
        "run1", dataset_hash="hash", dataset_path="/nowhere", config={"denoisers": list(labels)}, versions={}
    )
    for label in labels:
        store.add_denoiser(
            run_id="run1",
            label=label,
            spec=label,
            kind="input" if label == NOISY else "denoiser",
            needs={"color"},
            temporal=False,
            load_error=None,
        )
    for unit in units:
        assert store.write_unit("run1", unit)
    return store, "run1"


LEAD = ("temporal_relmse", "tpsnr", "hfen", "grad_l1", "temporal_l1", "temporal_l1_warped")


@pytest.fixture(scope="module")
def measured(tmp_path_factory):
    spatial = ["relmse", "mse", "hfen", "grad_l1"]
    temporal = ["temporal_relmse", "tpsnr", "temporal_l1", "temporal_l1_warped"]
    units = []
    for spp in (1, 4):
        for scene, scale in SCENES.items():
            seq = _sequence(scene, scale, spp)
            units.append(measure_unit(NOISY, None, seq, spatial=spatial, temporal=temporal))
            units.append(measure_unit("blur", Blur(), seq, spatial=spatial, temporal=temporal))
    store, run_id = _store_with_units(tmp_path_factory.mktemp("scores") / "r.sqlite", units)
    data = run_data(store, run_id)
    return store, data, summary_table(data)


def test_every_lead_temporal_and_gradient_score_ranks_the_smooth_prediction_above_the_input(measured):
    _, data, summary = measured
    from denoisebench.metrics import get_metric

    for spp in (1, 4):
        rows = {r.denoiser: r for r in summary if r.spp == spp}
        for metric in LEAD:
            m = get_metric(metric)
            blur, noisy = rows["blur"].metrics[metric].value, rows[NOISY].metrics[metric].value
            assert m.better(blur, noisy), (spp, metric, blur, noisy)
            cell = rows[NOISY].metrics[metric]
            if m.aggregate == "relative_to_input":  # under its own rule the input is 1 at every spp
                assert (cell.by_rule if cell.by_rule_name else cell.value) == pytest.approx(1.0)
            if cell.anchor_spp == spp:  # the lead aggregate: a share of the input's error at the lowest spp
                assert noisy == pytest.approx(1.0)


def test_floors_and_corrected_values_travel_through_the_store(measured):
    store, data, summary = measured
    row = next(r for r in summary if r.denoiser == "blur" and r.spp == 1)
    for metric in ("relmse", "mse", "temporal_relmse"):
        cell = row.metrics[metric]
        assert cell.floor is not None and cell.floor > 0, metric
        # the corrected aggregate leads (value); the raw score stays beside it
        assert cell.corrected == cell.value
        assert (
            cell.value == pytest.approx(cell.raw - cell.floor, rel=1e-9)
            if cell.rule == "mean" and not cell.at_resolution
            else cell.value < cell.raw
        )
    assert row.metrics["hfen"].floor is None  # not an MSE-family score
    frames = store.frames("run1")
    assert all("relmse" in f.floors and "relmse" in f.ref_se for f in frames if f.status == "ok")
    seq = [s for s in store.sequence_metrics("run1") if s.metric == "temporal_relmse"]
    assert seq and all(s.floor > 0 and s.ref_se > 0 for s in seq)


def test_a_bright_scene_no_longer_decides_a_linear_score():
    # the numbers: temporal_l1 of glossy_fireflies 1.07 (noisy) vs 1.44 (oidn), the other
    # scenes 0.01-0.18: the arithmetic mean ranks noisy first, the per-scene rule ranks oidn first
    noisy = {"cornell": 0.18, "dof": 0.05, "motion_blur": 0.06, "glossy_fireflies": 1.07}
    oidn = {"cornell": 0.02, "dof": 0.01, "motion_blur": 0.012, "glossy_fireflies": 1.44}
    assert np.mean(list(noisy.values())) < np.mean(list(oidn.values()))
    relative = agg.aggregate("relative_to_input", oidn, noisy)[0]
    assert relative < agg.aggregate("relative_to_input", noisy, noisy)[0] == pytest.approx(1.0)
    assert agg.aggregate("geomean", oidn)[0] < agg.aggregate("geomean", noisy)[0]
    # a brightness factor on one scene changes neither rule's ranking
    brighter = {k: v * (1000 if k == "glossy_fireflies" else 1) for k, v in oidn.items()}
    noisy_brighter = {k: v * (1000 if k == "glossy_fireflies" else 1) for k, v in noisy.items()}
    assert agg.aggregate("relative_to_input", brighter, noisy_brighter)[0] == pytest.approx(relative)


def test_bootstrap_interval_widens_with_the_reference_uncertainty():
    values = [0.10, 0.12, 0.11, 0.13]
    plain = agg.bootstrap_mean(values)
    wide = agg.bootstrap_mean(values, [0.05] * 4)
    assert wide[0] < plain[0] and wide[1] > plain[1]
    assert agg.bootstrap_mean([0.1]) == (None, None)


def _unit(label, scene, value, se, frames=2):
    records = [
        FrameRecord(
            frame=i,
            status="ok",
            error=None,
            render_seconds=1.0,
            denoise_seconds=0.1,
            total_seconds=1.1,
            sanitized=0,
            metrics={"relmse": value},
            floors={"relmse": 0.001},
            ref_se={"relmse": se},
        )
        for i in range(frames)
    ]
    return UnitRecord(denoiser=label, scene=scene, spp=1, status="ok", error=None, frames=records)


def test_pairs_within_the_reference_noise_are_marked_not_distinguishable(tmp_path):
    # a and b differ by 0.0005 with a per-frame reference se of 0.002: not resolvable; c is far off
    units = []
    for scene in ("s1", "s2"):
        units += [
            _unit(NOISY, scene, 0.5, 0.002),
            _unit("a", scene, 0.0500, 0.002),
            _unit("b", scene, 0.0505, 0.002),
            _unit("c", scene, 0.0800, 0.002),
        ]
    store, run_id = _store_with_units(tmp_path / "r.sqlite", units, (NOISY, "a", "b", "c"))
    data = run_data(store, run_id)
    pairs = {(p.a, p.b) for p in indistinguishable_pairs(data, summary_table(data))}
    assert ("a", "b") in pairs
    assert not {("a", "c"), ("b", "c"), (NOISY, "a")} & pairs
    # resolution: 1.96 × sqrt(Σ (se_a + se_b)²) / scenes, with the scene se = frame se / sqrt(2 frames)
    se = 0.002 / math.sqrt(2)
    assert agg.reference_resolution(
        "mean", {"s1": 0.05, "s2": 0.05}, {"s1": se, "s2": se}, {"s1": 0.05, "s2": 0.05}, {"s1": se, "s2": se}
    ) == pytest.approx(agg.Z95 * math.sqrt(2 * (2 * se) ** 2) / 2)


def test_a_version_1_database_stays_readable_and_is_migrated_when_written(tmp_path):
    path = tmp_path / "old.sqlite"
    store, _ = _store_with_units(path, [_unit(NOISY, "s1", 0.5, 0.002)], (NOISY,))
    store.close()
    with sqlite3.connect(path) as conn:  # make it a version-1 file: no floor columns, no strips table
        for table in ("frame_metrics", "sequence_metrics"):
            conn.execute(f"ALTER TABLE {table} DROP COLUMN floor")
            conn.execute(f"ALTER TABLE {table} DROP COLUMN ref_se")
        conn.execute("DROP TABLE strips")
        conn.execute("ALTER TABLE run_denoisers DROP COLUMN trained_on")
        conn.execute("UPDATE schema_version SET version = 1")
    with ResultsStore(path, readonly=True) as old:
        assert old.version == 1
        ((frame, *_),) = [old.frames("run1")[:1]]
        assert frame.metrics["relmse"] == 0.5 and frame.floors == {}
        assert old.strip("run1", NOISY, spp=1, scene="s1") is None and old.integrity_problems() == []
        assert all(d.trained_on == [] for d in old.denoisers("run1"))
    with ResultsStore(path) as migrated:
        # 4: the not_applicable table; 5: the sampler dimension; 6: images keyed by frame
        assert migrated.version == SCHEMA_VERSION
        assert [d.trained_on for d in migrated.denoisers("run1")] == [[]] * len(migrated.denoisers("run1"))
        assert migrated.frames("run1")[0].floors == {}  # old rows: no floor
        assert migrated.write_unit("run1", _unit("x", "s1", 0.1, 0.002))
        assert [f.floors for f in migrated.frames("run1") if f.denoiser == "x"][0] == {"relmse": 0.001}
        assert migrated.integrity_problems() == []
    with sqlite3.connect(path) as conn:
        conn.execute(f"UPDATE schema_version SET version = {SCHEMA_VERSION + 1}")
    with pytest.raises(Exception, match=f"schema version {SCHEMA_VERSION + 1}"):
        ResultsStore(path, readonly=True)


def test_strips_cut_the_same_crop_for_every_unit_and_show_consecutive_frames(measured):
    store, data, _ = measured
    a = store.strip("run1", NOISY, spp=1, scene="plain")
    b = store.strip("run1", "blur", spp=1, scene="plain")
    assert a is not None and b is not None
    assert (a.top, a.left, a.side) == (b.top, b.left, b.side)
    assert a.crops.shape == (crops.STRIP_FRAMES, a.side, a.side, 3)
    import io

    from PIL import Image

    png = Image.open(io.BytesIO(strips.strip_png(a.crops, scale=2)))
    assert png.size == (crops.STRIP_FRAMES * (2 * a.side + 2) - 2, 2 * a.side)
    animated = Image.open(io.BytesIO(strips.strip_apng(a.crops, scale=2)))
    assert getattr(animated, "n_frames", 1) == crops.STRIP_FRAMES


def test_the_demo_renders_sequences_long_enough_to_flicker():
    from denoisebench.commands.demo import DEMO_FRAMES

    assert DEMO_FRAMES >= 8  # three frames gave two frame differences, two points per line


def test_the_demo_scores_shipped_weights_on_scenes_none_of_them_trained_on():
    """A scene name is its family and seed, so the same name is the same stage (geometry, materials, lights)."""

    from denoisebench.commands.demo import DEMO_DATASET_FAMILIES, DEMO_DATASET_SEED
    from denoisebench.generator.dataset_scenes import family_scene_names
    from denoisebench.models.checkpoint import load_checkpoint
    from denoisebench.models.provenance import all_train_scenes

    demo = {name for _, _, name in family_scene_names(list(DEMO_DATASET_FAMILIES), 1, DEMO_DATASET_SEED)}
    shipped = sorted((REPO / "denoisebench" / "models" / "weights").glob("*.pt"))
    assert len(shipped) >= 4
    for path in shipped:
        trained = all_train_scenes(load_checkpoint(path)["meta"])
        assert trained and not demo & trained, (path.name, sorted(demo & trained))


def test_report_files_carry_floors_flicker_per_spp_and_strips(tmp_path):
    import csv
    import json

    from denoisebench.benchmark.run import run_benchmark
    from denoisebench.benchmark.runner import BenchmarkConfig
    from denoisebench.dataset import open_dataset
    from denoisebench.dataset.synthetic import make_synthetic_dataset
    from denoisebench.reports.build import write_report

    data = open_dataset(make_synthetic_dataset(tmp_path / "ds", scenes=1, frames=4, height=16, width=16, spp=(1, 4)))
    with ResultsStore(tmp_path / "r.sqlite") as store:
        plan = run_benchmark(
            data,
            BenchmarkConfig(denoisers=["cross_bilateral_fast"], spp=[1, 4], split="all", metrics=["relmse"]),
            store,
            progress=False,
        )
        index = write_report(store, plan.run_id, data, tmp_path / "report")
    results = json.loads((tmp_path / "report" / "results.json").read_text())
    for row in results["summary"]:
        relmse = row["metrics"]["relmse"]
        assert relmse["aggregate"] == "anchored_trimmed_geomean" and relmse["floor"] > 0
        assert relmse["by_rule"]["aggregate"] == "mean" and relmse["relative_to"] == {"label": NOISY, "spp": 1}
        assert relmse["corrected"] is True and relmse["at_resolution"] == 0
        # one scene: the lead share is the corrected score over the input's corrected 1-spp score, and
        # the arithmetic mean beside it is that corrected score in relMSE's units
        assert relmse["arithmetic_mean"] == pytest.approx(relmse["by_rule"]["mean"])
        noisy_1 = next(r for r in results["summary"] if r["denoiser"] == NOISY and r["spp"] == 1)
        anchor = noisy_1["metrics"]["relmse"]["arithmetic_mean"]
        assert relmse["mean"] == pytest.approx(relmse["arithmetic_mean"] / anchor)
        assert relmse["floor_closed_form"] is not None and "floor_measured" in relmse
        assert row["metrics"]["temporal_relmse"]["floor"] > 0
        # the robust scores (always computed, they lead) carry floors too
        assert row["metrics"]["relmse_robust"]["floor"] > 0
        assert row["metrics"]["temporal_relmse_robust"]["floor"] > 0
    assert results["flicker"]["metrics"] == ["temporal_relmse_robust", "temporal_relmse", "tpsnr"]
    assert set(results["flicker"]["series"]["temporal_relmse"]) == {"1", "4"}  # one panel per input spp
    header = next(csv.reader((tmp_path / "report" / "results.csv").open()))
    assert {"relmse_floor", "relmse_corrected", "flicker.temporal_relmse", "flicker.tpsnr"} <= set(header)
    markdown = (tmp_path / "report" / "report.md").read_text()
    assert "relmse floor" in markdown and "temporal\\_relmse ↓" in markdown
    html = index.read_text()
    assert (
        html.count('alt="frames of ') == 3 and html.count('alt="animated crop of ') == 3
    )  # noisy, denoiser, reference


def test_the_leaderboard_command_ranks_a_linear_flicker_score_per_scene_against_the_input(tmp_path):
    from denoisebench.reports.leaderboard import leaderboard

    # the temporal_l1 per scene: an arithmetic mean would rank noisy (0.34) above oidn (0.37)
    noisy = {"cornell": 0.18, "dof": 0.05, "motion_blur": 0.06, "glossy_fireflies": 1.07}
    oidn = {"cornell": 0.02, "dof": 0.01, "motion_blur": 0.012, "glossy_fireflies": 1.44}
    units = []
    for label, values in ((NOISY, noisy), ("oidn", oidn)):
        for scene, value in values.items():
            frames = [
                FrameRecord(
                    frame=i,
                    status="ok",
                    error=None,
                    render_seconds=1.0,
                    denoise_seconds=0.1,
                    total_seconds=1.1,
                    sanitized=0,
                    metrics={"relmse": 0.1},
                )
                for i in range(2)
            ]
            units.append(
                UnitRecord(
                    denoiser=label,
                    scene=scene,
                    spp=4,
                    status="ok",
                    error=None,
                    frames=frames,
                    sequence_metrics={"temporal_l1": value},
                )
            )
    store, _ = _store_with_units(tmp_path / "r.sqlite", units, (NOISY, "oidn"))
    ranking = leaderboard(store, "temporal_l1", 4)
    metric, spp, ranked = ranking.metric, ranking.spp, ranking.entries
    assert metric.aggregate == "relative_to_input" and spp == 4
    assert [e.denoiser for e in ranked] == ["oidn", NOISY]
    assert ranked[1].value == pytest.approx(1.0)


# --------------------------------------------------------------------------------------------------
# references that cannot resolve a score (item 5)


class _Run:
    """A RunData stand-in: per-scene values, floors and ses of one metric, keyed (label, spp, scene)."""

    def __init__(self, values, floors, ses=None, metric="relmse_robust"):
        self.values, self.floors, self.ses, self.metric = values, floors, ses or {}, metric
        self.scenes = sorted({k[2] for k in values})
        self.labels = sorted({k[0] for k in values})
        self.spp = sorted({k[1] for k in values})
        self.frame_metric_names, self.sequence_metric_names = [metric, "relmse"], []

    def per_scene(self, label, spp, metric, scenes=None):
        assert metric == self.metric  # the robust score is judged when the run has it
        out = [{}, {}, {}]
        for scene in scenes or self.scenes:
            if (label, spp, scene) in self.values:
                out[0][scene] = self.values[label, spp, scene]
                out[1][scene] = self.floors[label, spp, scene]
                if (label, spp, scene) in self.ses:
                    out[2][scene] = self.ses[label, spp, scene]
        return tuple(out)


def test_a_scene_is_set_apart_only_when_its_corrected_scores_cannot_rank():
    # a floor above a tenth of the best score no longer sets a scene apart; a still-growing
    # floor, a reference too noisy for the floor's expansion, or scores the reference cannot tell apart do
    values, floors, ses = {}, {}, {}
    scenes = (
        ("clean", 0.02, 0.001, 1e-4),
        ("high_floor", 0.02, 0.005, 2e-4),  # floor 1/4 of the best score: corrected, still ranks
        ("growing", 0.05, 0.001, 1e-4),
        ("noisy_ref", 0.02, 0.001, 1e-4),
        ("unrankable", 0.02, 0.01, 0.5),  # se larger than every gap
    )
    for scene, best, floor, se in scenes:
        for label, factor in ((NOISY, 10.0), ("oidn", 1.0)):
            for spp, s in ((1, 4.0), (4, 1.0)):
                values[label, spp, scene] = best * factor * s
                floors[label, spp, scene] = floor
                ses[label, spp, scene] = se
    refs = {s[0]: {"spp": 256, "floor_growth": 1.05, "noisy_share": 0.001} for s in scenes}
    refs["growing"] = {"spp": 512, "floor_growth": 1.6}
    refs["noisy_ref"]["noisy_share"] = 0.2
    found = agg.unresolved_references(_Run(values, floors, ses), refs)
    assert [(u.scene, u.reason) for u in found] == [
        ("growing", "floor_growing"),
        ("noisy_ref", "reference_too_noisy"),
        ("unrankable", "cannot_rank"),
    ]
    grow, noisy, unrankable = found
    # growing: at least twice its spp (its floor alone would need less)
    assert (grow.needed_spp, grow.needed_is_lower_bound, grow.floor_growth) == (1024, True, 1.6)
    assert "at least 1024 spp" in grow.sentence() and "still growing" in grow.sentence()
    assert "20.0 %" in noisy.sentence() and noisy.noisy_share == 0.2
    # floor 0.01 against the best 0.02 (oidn at 4 spp): 256 · 0.01 / 0.002 = 1280 spp
    assert (unrankable.best, unrankable.label, unrankable.spp, unrankable.needed_spp) == (0.02, "oidn", 4, 1280)
    assert "no two entries there differ" in unrankable.sentence() and "1280 spp" in unrankable.sentence()
    assert agg.excluded_scenes(found) == ["growing", "noisy_ref", "unrankable"]
    assert found[2].as_dict()["sentence"] == unrankable.sentence()
    # a looser noise limit keeps the noisy reference; without stored ses nothing is judged unrankable
    loose = agg.unresolved_references(_Run(values, floors, ses), refs, noisy_limit=0.5)
    assert [u.scene for u in loose] == ["growing", "unrankable"]
    assert [u.scene for u in agg.unresolved_references(_Run(values, floors), {})] == []


def test_corrected_values_are_unbiased_and_raised_to_the_resolution():
    corrected, raised = agg.corrected_values(
        {"a": 0.05, "b": 0.011, "c": 0.02}, {"a": 0.01, "b": 0.01, "c": 0.0}, {"a": 1e-3, "b": 5e-3}
    )
    assert corrected["a"] == pytest.approx(0.04)
    assert corrected["b"] == pytest.approx(5e-3) and raised == ["b"]  # 0.001 < se: at the resolution
    assert corrected["c"] == pytest.approx(0.02)  # no se stored: kept as measured


def test_reference_states_read_the_manifest_records():
    records = {
        "a": {
            "ref_spp": 1024,
            "renders": {
                "reference": {
                    "0000": {"reference_adaptive": {"spp": 256, "floor_growth": 1.02}},
                    "0001": {"reference_adaptive": {"spp": 512, "floor_growth": 1.4}},
                }
            },
        },
        "b": {"ref_spp": 64, "renders": {"reference": {"0000": {"spp": 64}}}},
        "c": {},
    }
    assert agg.reference_states(records) == {
        "a": {"spp": 512, "floor_growth": 1.4},
        "b": {"spp": 64, "floor_growth": None},
        "c": {"spp": None, "floor_growth": None},
    }


def test_the_report_leaves_unresolved_scenes_out_of_the_summary_unless_asked(tmp_path, monkeypatch):
    import json

    from denoisebench.benchmark.run import run_benchmark
    from denoisebench.benchmark.runner import BenchmarkConfig
    from denoisebench.dataset import open_dataset
    from denoisebench.dataset.synthetic import make_synthetic_dataset
    from denoisebench.reports.build import build_report, results_json

    data = open_dataset(make_synthetic_dataset(tmp_path / "ds", scenes=2, frames=2, height=16, width=16, spp=(1,)))
    with ResultsStore(tmp_path / "r.sqlite") as store:
        plan = run_benchmark(
            data,
            BenchmarkConfig(denoisers=["identity"], spp=[1], split="all", metrics=["relmse"]),
            store,
            progress=False,
        )
        scenes = sorted(data.scenes)
        states = agg.reference_states({s: data.scene(s).record for s in scenes})
        states[scenes[0]] = {"spp": 64, "floor_growth": 2.0}  # as if its floor were still growing
        monkeypatch.setattr(agg, "reference_states", lambda records: states)
        report = build_report(store, plan.run_id, data)
        kept = build_report(store, plan.run_id, data, include_unresolved=True)
    listed = report.unresolved_references.scenes
    assert scenes[0] in {u.scene for u in listed} and not report.unresolved_references.included
    excluded = {u.scene for u in listed}
    for row in report.summary:
        assert row.metrics["relmse_robust"].scenes == len(scenes) - len(excluded)
    for row in kept.summary:
        assert row.metrics["relmse_robust"].scenes == len(scenes)
    assert json.dumps(results_json(report)["unresolved_references"], allow_nan=False)
    # shown apart in report.md and index.html, with the reason and the spp it would need
    from denoisebench.reports.html import e, render_html
    from denoisebench.reports.markdown import md, render_markdown

    text = f"{scenes[0]}: its 64-spp reference's noise floor estimate was still growing"
    for page, escape in ((render_markdown(report), md), (render_html(report), e)):
        assert "References that cannot resolve a score" in page and escape(text) in page
        assert "it would need at least 128 spp" in page and "left out of the aggregates above" in page
    assert "They are included in the aggregates above" in render_markdown(kept)


def test_the_runner_passes_the_trim_to_the_robust_scores():
    from denoisebench.metrics.ours import robust

    seq = _sequence("plain", 1.0, 1, frames=3, size=24)
    spatial, temporal = ["relmse_robust"], ["temporal_relmse_robust"]
    default = measure_unit(NOISY, None, seq, spatial=spatial, temporal=temporal)
    wide = measure_unit(NOISY, None, seq, spatial=spatial, temporal=temporal, trim=0.2)
    frames = list(seq)
    for unit, trim in ((default, robust.DEFAULT_TRIM), (wide, 0.2)):
        for record, frame in zip(unit.frames, frames):
            expected = robust.relmse_robust(frame.color, frame.reference, trim=trim)
            assert record.metrics["relmse_robust"] == pytest.approx(expected, rel=1e-9)
            assert record.floors["relmse_robust"] > 0
    assert wide.sequence_metrics["temporal_relmse_robust"] < default.sequence_metrics["temporal_relmse_robust"]
    assert "flicker.temporal_relmse_robust" in default.frames[1].metrics
