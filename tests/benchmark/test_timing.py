"""The timing stage: which buffer set each alternative is charged a render of, the render probe's lines, and the
timing size ``--time-size auto`` picks.

The charging test plants a render cost law in the probe (:func:`denoisebench.benchmark.timing.render_rungs`
renders for real, for the buffers it makes, and returns the law's seconds): every expected second is computed by
hand from that law, and no clock decides a verdict (speed is measured in bench/, never in unit tests)."""

from __future__ import annotations

import dataclasses
import textwrap

import pytest

from denoisebench.benchmark import timing
from denoisebench.results.names import NOISY
from denoisebench.results.timings import COLOUR_ONLY, SAMPLES

FEATURES = ("albedo", "normal", "depth", "position", "roughness", "motion")
CHANNELS = {"albedo": 3, "normal": 3, "depth": 1, "position": 3, "roughness": 1, "motion": 2}
HD = 1920 * 1080


def test_auto_time_size_is_eight_times_the_frame_at_most_one_megapixel():
    assert timing.auto_time_size(32, 32) == (256, 256)
    assert timing.auto_time_size(64, 64) == (512, 512)  # the demo's former fixed 512x512
    assert timing.auto_time_size(128, 128) == (1024, 1024)
    width, height = timing.auto_time_size(400, 200)  # aspect kept, within 1 MP
    assert width == 2 * height and width * height <= 1024 * 1024 < (width + 2) * (height + 1)
    assert timing.auto_time_size(2000, 1000) == (4000, 2000)  # a frame beyond 1 MP: 4x its pixels, never less


def test_each_alternative_is_charged_the_buffers_it_reads():
    assert timing.render_buffers({"color"}, FEATURES, True) == COLOUR_ONLY  # a plain-function plugin
    oidn_like = timing.denoiser_reads({"color"}, type("OIDN", (), {"uses": frozenset({"albedo", "normal"})})())
    assert timing.render_buffers(oidn_like, FEATURES, True) == (*COLOUR_ONLY, "albedo", "normal")
    reads = {"color", "color_var", "depth", "albedo_var", "roughness"}  # variances count as their buffer
    assert timing.render_buffers(reads, FEATURES, False) == (*COLOUR_ONLY, "albedo", "depth", "roughness")
    assert timing.render_buffers({"samples"}, FEATURES, True) == (*COLOUR_ONLY, *FEATURES, SAMPLES)
    # a dataset without per-sample data cannot render them for it; a feature the plan lacks is not charged
    assert timing.render_buffers({"samples"}, FEATURES, False) == COLOUR_ONLY
    assert timing.render_buffers({"color", "albedo"}, ("normal",), True) == COLOUR_ONLY
    assert timing.denoiser_reads({"color"}, type("Bad", (), {"uses": "albedo"})()) == {"color"}  # malformed: none


def test_the_built_ins_that_read_features_when_present_say_so():
    from denoisebench.baselines.cross_bilateral import CrossBilateral
    from denoisebench.baselines.oidn import OIDN

    assert timing.denoiser_reads(OIDN.needs, OIDN("fast")) == {"color", "albedo", "normal"}
    assert timing.denoiser_reads(OIDN.needs, OIDN("fast", use_normal=False)) == {"color", "albedo"}

    reads = timing.denoiser_reads(CrossBilateral.needs, CrossBilateral("fast"))
    assert reads >= {"color", "albedo", "normal"}
    assert timing.render_buffers(reads, FEATURES, True)[len(COLOUR_ONLY) :] == tuple(
        f for f in FEATURES if f in CrossBilateral("fast").feature_sigmas
    )


PLUGINS = textwrap.dedent(
    """
    import numpy as np

    class ColourOnly:
        name = "colour_only"
        needs = frozenset({"color"})
        temporal = False
        def reset(self):
            pass
        def denoise(self, frame):
            return np.asarray(frame.color, np.float32)

    class Features(ColourOnly):
        name = "features"
        needs = frozenset({"color", "albedo", "normal", "depth"})
    """
)


def _law(plan_features, width: int, height: int, spp: int) -> float:
    """Planted seconds of a render: 10 ms + 0.2 µs per pixel, and 0.1 µs per pixel-sample for each of colour's
    3 channels and each feature channel the plan makes."""
    pixels = width * height
    channels = 3 + sum(CHANNELS[f] for f in plan_features)
    return 0.01 + 2e-7 * pixels + 1e-7 * channels * pixels * spp


@pytest.fixture(scope="module")
def dataset(tmp_path_factory):
    from denoisebench.cli import main
    from denoisebench.dataset import open_dataset

    out = tmp_path_factory.mktemp("charged") / "ds"
    args = ["generate", "--out", str(out), "--families", "cornell", "--scenes", "1", "--frames", "2"]
    args += ["--width", "16", "--height", "16", "--spp", "1,2,4", "--ref-spp", "16", "--quiet"]
    assert main(args) == 0
    return open_dataset(out)


def test_rendering_alone_is_charged_colour_and_a_denoiser_the_buffers_it_reads(dataset, tmp_path, monkeypatch):
    from denoisebench.benchmark.run import run_benchmark
    from denoisebench.benchmark.runner import BenchmarkConfig
    from denoisebench.reports import build as report
    from denoisebench.results.store import ResultsStore
    from denoisebench.results.timings import read_timings

    real, calls = timing.render_rungs, []

    def planted(scene, camera, plan, *, width, height, spp, seed):
        _, made = real(scene, camera, plan, width=width, height=height, spp=spp, seed=seed)
        calls.append((plan.features, width))
        return [_law(plan.features, width, height, s) for s in spp], made

    monkeypatch.setattr(timing, "render_rungs", planted)
    plugin = tmp_path / "plugins.py"
    plugin.write_text(PLUGINS)
    config = BenchmarkConfig(
        denoisers=[f"{plugin}:ColourOnly", f"{plugin}:Features"],
        spp=[1, 2, 4],
        split="all",
        metrics=["relmse"],
        isolation="none",
    )
    with ResultsStore(tmp_path / "db.sqlite") as store:
        plan = run_benchmark(dataset, config, store, progress=False)
        instances = {d.label: d.instance for d in plan.denoisers}
        records = timing.measure_run_timings(store, dataset, plan, instances, (48, 48), progress=False)
        built = report.build_report(store, plan.run_id, dataset, time_at=(1920, 1080))
        assert read_timings(store, plan.run_id) == records
    feature_set = (*COLOUR_ONLY, "albedo", "normal", "depth")
    assert records["denoiser:colour_only"]["buffers"] == list(COLOUR_ONLY)
    assert records["denoiser:features"]["buffers"] == list(feature_set)
    lines = {tuple(line["buffers"]): line for line in records["render_probe"]["lines"]}
    assert set(lines) == {COLOUR_ONLY, feature_set}  # one render per set the run pays for, not one per denoiser
    assert "albedo" not in lines[COLOUR_ONLY]["made"] and "color" in lines[COLOUR_ONLY]["made"]
    assert {"albedo", "normal", "depth"} <= set(lines[feature_set]["made"]) and "position" not in lines[feature_set][
        "made"
    ]
    assert {width for _, width in calls} == {16, 48}  # the dataset's size and the timing size
    assert records["timing"] == {
        "width": 48,
        "height": 48,
        "auto": False,
        "dataset_buffers": [*COLOUR_ONLY, *FEATURES],
    }

    model = built.time_model
    assert model.projected and model.timed_size == (48, 48)
    for spp in (1, 2, 4):
        colour = model.total_seconds("colour_only", spp) - model.denoise_seconds("colour_only", spp)
        features = model.total_seconds("features", spp) - model.denoise_seconds("features", spp)
        # the law's seconds at 1920x1080, through the two sizes' lines (linear in pixels and spp: exact)
        assert colour == pytest.approx(_law((), 1920, 1080, spp), rel=1e-6)
        assert features == pytest.approx(_law(("albedo", "normal", "depth"), 1920, 1080, spp), rel=1e-6)
        assert colour < features
        assert model.total_seconds(NOISY, spp) == model.render_seconds(spp) == pytest.approx(colour)
    # the noisy curve and every equal-time budget are the colour-only render
    for at in built.accuracy:
        for point in at.points:
            if point.denoiser == NOISY:
                assert point.seconds == pytest.approx(_law((), 1920, 1080, point.spp), rel=1e-6)
    for table in built.equal_tables:
        for row in table.equal_time:
            assert row.budget_seconds == pytest.approx(_law((), 1920, 1080, row.budget_spp), rel=1e-6)
    listed = {tuple(line["buffers"]): line for line in model.as_dict()["render_lines"]}
    assert listed[COLOUR_ONLY]["paid_by"] == [NOISY, "colour_only"]
    assert listed[feature_set]["paid_by"] == ["features"]
    assert listed[feature_set]["seconds_per_megapixel_per_spp"] == pytest.approx(1e-7 * 10 * 1e6, rel=1e-6)
    assert listed[COLOUR_ONLY]["fixed_s"] == pytest.approx(0.01, rel=1e-6)

    # a resumed run with one more denoiser renders only the set its probe lacks
    calls.clear()
    more = type("Albedo", (), {"needs": frozenset({"color", "albedo"}), "denoise": lambda self, f: f.color})()
    plan.denoisers.append(dataclasses.replace(plan.denoisers[0], label="albedo_only", needs=more.needs, instance=more))
    with ResultsStore(tmp_path / "db.sqlite") as store:
        again = timing.measure_run_timings(
            store, dataset, plan, {**instances, "albedo_only": more}, (48, 48), progress=False
        )
    assert {features for features, _ in calls} == {("albedo",)}
    assert len(again["render_probe"]["lines"]) == 3
