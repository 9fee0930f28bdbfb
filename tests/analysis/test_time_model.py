"""The time model: fixed + per-pixel costs recovered from constructed timings, projections, tiled timing frames.

Every expected value is computed by hand from a cost law the test plants (no clock is read: speed is
measured in bench/, never in unit tests)."""

from __future__ import annotations

import textwrap
from types import SimpleNamespace

import numpy as np
import pytest

from denoisebench.analysis import time_model as tm
from denoisebench.benchmark import timing
from denoisebench.dataset.frame import Frame
from denoisebench.errors import UserInputError
from denoisebench.results import timings
from denoisebench.results.names import NOISY
from denoisebench.results.timings import COLOUR_ONLY

FIXED, PER_PIXEL = 0.05, 2e-7  # a denoiser: 50 ms per call + 0.2 s per megapixel
P0, P1, HD = 80 * 80, 1024 * 1024, 1920 * 1080


def _law(pixels: int) -> float:
    return FIXED + PER_PIXEL * pixels


def test_line_through_separates_offset_and_slope_and_stays_non_negative():
    assert tm.line_through([(1, 0.92), (4, 0.98), (256, 6.02)]) == (pytest.approx(0.9), pytest.approx(0.02))
    # all offset, noisy: slope 0, the mean as offset
    assert tm.line_through([(1, 0.5), (4, 0.49)]) == (pytest.approx(0.495), 0.0)
    # a negative offset refits through the origin
    offset, slope = tm.line_through([(1, 0.0), (2, 0.3), (3, 0.5)])
    assert offset == 0.0 and slope == pytest.approx((0.3 * 2 + 0.5 * 3) / (1 + 4 + 9))
    assert tm.line_through([(4, 0.4)]) == (0.0, pytest.approx(0.1))
    assert tm.line_through([]) is None


def test_denoiser_cost_projects_fixed_plus_per_pixel_and_never_scales_a_small_frame_alone():
    cost = tm.DenoiserCost(label="d", pixels0=P0, small={1: _law(P0), 4: _law(P0) + 0.01})
    assert cost.seconds(HD, 1) is None  # one size measured: no projection by pixel ratio
    assert cost.seconds(P0, 4) == pytest.approx(_law(P0) + 0.01)
    offset, _ = tm.line_through([(P0, _law(P0)), (P1, _law(P1))])
    cost.fixed = offset
    assert cost.fixed == pytest.approx(FIXED)
    assert cost.seconds(HD, 1) == pytest.approx(_law(HD))
    assert cost.per_megapixel == pytest.approx(PER_PIXEL * 1e6)
    # the spp-dependent part (0.01 s at P0) cannot be split: the measured line is scaled whole by it
    assert cost.seconds(HD, 4) == pytest.approx(_law(HD) * (_law(P0) + 0.01) / _law(P0))
    # pure proportional scaling would have charged the 50 ms fixed cost HD/P0 = 324 times
    assert _law(P0) * HD / P0 > 10 * cost.seconds(HD, 1)


def test_render_cost_scales_the_per_sample_cost_with_pixels_and_splits_the_offset_with_a_probe():
    render = tm.RenderCost(pixels0=P0, offset0=0.3, per_spp0=0.002, measured_spp=[1, 2, 4, 8, 16])
    assert render.seconds(P0, 8) == pytest.approx(0.3 + 0.016)
    assert render.offset(HD) == 0.3  # held fixed without a probe
    assert render.per_spp(HD) == pytest.approx(0.002 * HD / P0)
    # probe at 1 MP: offset 0.3 + 1e-7 per pixel; per spp 2e-3 · P/P0 exactly
    render.probe = {"pixels": P1, "offset": 0.3 + 1e-7 * (P1 - P0), "per_spp": 0.002 * P1 / P0}
    assert render.offset(HD) == pytest.approx(0.3 + 1e-7 * (HD - P0))
    assert render.per_spp(HD) == pytest.approx(0.002 * HD / P0)


class _Data:
    """The slice of analysis.RunData the time model reads."""

    def __init__(self, frames, labels, spp):
        self.frames, self.labels, self.spp = frames, labels, spp

    def frames_of(self, label):
        return [f for f in self.frames if f.denoiser == label]

    def ok_frames(self, label, spp):
        return [f for f in self.frames_of(label) if f.spp == spp]


def _frames():
    out = []
    for spp in (1, 2, 4):
        render = 0.3 + 0.002 * spp
        for label, denoise in ((NOISY, 0.0), ("d", _law(P0)), ("e", 0.01)):
            out += [SimpleNamespace(denoiser=label, spp=spp, render_seconds=render, denoise_seconds=denoise)] * 2
    return out


def test_build_time_model_projects_only_when_every_denoiser_was_timed_at_a_second_size():
    data = _Data(_frames(), [NOISY, "d", "e"], [1, 2, 4])
    timings = {
        "denoiser:d": {"width": 1024, "height": 1024, "seconds": _law(P1)},
        "denoiser:e": {"width": 1024, "height": 1024, "seconds": 0.01},  # all fixed cost
        "machine": {"cores": 2, "gpu": None},
    }
    model = tm.build_time_model(data, timings, (1920, 1080), (80, 80))
    assert model.projected and model.time_at == (1920, 1080) and model.extrapolated_pixels()
    assert model.render.offset0 == pytest.approx(0.3) and model.render.per_spp0 == pytest.approx(0.002)
    assert model.denoise_seconds("d", 1) == pytest.approx(_law(HD))
    assert model.denoise_seconds("e", 1) == pytest.approx(0.01)  # a fixed cost stays fixed
    assert model.total_seconds(NOISY, 4) == pytest.approx(0.3 + 0.002 * 4 * HD / P0)
    assert model.as_dict()["denoisers"]["d"]["fixed_s_per_call"] == pytest.approx(FIXED)
    # one denoiser without a second size: the axis stays at the dataset's size, and the report says so
    del timings["denoiser:e"]
    model = tm.build_time_model(data, timings, (1920, 1080), (80, 80))
    assert not model.projected and model.time_at == (80, 80)
    note = next(n for n in model.notes if "never scaled by pixel count" in n)
    assert "e" in note
    assert model.denoise_seconds("e", 2) == pytest.approx(0.01)
    from denoisebench.reports.formatting import time_axis_text

    assert (
        time_axis_text(SimpleNamespace(time_model=model)) == "Times are per frame at the dataset's 80×80, as measured."
    )


def test_upscaled_frame_tiles_every_buffer_and_the_samples():
    rng = np.random.default_rng(0)
    color = rng.random((5, 7, 3), dtype=np.float32)
    samples = {"color": rng.random((2, 5, 7, 3), dtype=np.float32)}
    frame = Frame({"color": color, "depth": color[..., :1].copy()}, spp=2, samples=samples)
    big = timing.upscaled_frame(frame, width=16, height=12)
    assert big.color.shape == (12, 16, 3) and big.buffers["depth"].shape == (12, 16, 1)
    assert big.samples["color"].shape == (2, 12, 16, 3) and big.reference is None
    assert np.array_equal(big.color[11, 15], color[11 % 5, 15 % 7])
    assert np.array_equal(big.samples["color"][1, 6, 9], samples["color"][1, 1, 2])


def test_timing_size_shrinks_to_the_budget_and_gives_up_below_four_frames():
    assert timing.timing_size(0.001, P0, (1024, 1024), 60.0) == (1024, 1024, "")
    width, height, note = timing.timing_size(1.0, P0, (1024, 1024), 60.0)  # 164 s proportional estimate
    assert width * height * 1.0 / P0 <= 60.0 and width * height >= 4 * P0 and "60 s" in note
    assert timing.timing_size(30.0, P0, (1024, 1024), 60.0) is None


def test_sizes_parse_and_bad_ones_are_one_line_errors(capsys):
    from denoisebench.cli import main

    assert tm.parse_size("1920x1080", "--time-at") == (1920, 1080)
    assert tm.parse_size("none", "--time-size") is None
    with pytest.raises(UserInputError):
        tm.parse_size("1920", "--time-at")
    assert main(["benchmark", "--data", "nowhere", "--time-at", "wide"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "--time-at" in err[0]


def test_timings_are_measured_once_per_run_and_kept_in_the_store(tmp_path):
    from denoisebench.benchmark.run import run_benchmark
    from denoisebench.benchmark.runner import BenchmarkConfig
    from denoisebench.dataset import open_dataset
    from denoisebench.dataset.synthetic import make_synthetic_dataset
    from denoisebench.results.store import ResultsStore

    dataset = open_dataset(make_synthetic_dataset(tmp_path / "ds", scenes=2, frames=2, height=16, width=16, spp=(1,)))
    with ResultsStore(tmp_path / "db.sqlite") as store:
        plan = run_benchmark(
            dataset,
            BenchmarkConfig(denoisers=["identity"], spp=[1], split="all", metrics=["relmse"]),
            store,
            progress=False,
        )
        instances = {d.label: d.instance for d in plan.denoisers}
        first = timing.measure_run_timings(store, dataset, plan, instances, (64, 48), progress=False)
        assert first["denoiser:identity"]["width"] == 64 and first["denoiser:identity"]["seconds"] > 0
        assert "error" in first["render_probe"]  # a synthetic dataset has no stage to render
        assert first["machine"]["cores"] >= 1
        again = timing.measure_run_timings(store, dataset, plan, instances, (64, 48), progress=False)
        assert again == first  # not measured twice
    with ResultsStore(tmp_path / "db.sqlite", readonly=True) as store:
        assert timings.read_timings(store, plan.run_id) == first
        assert timings.read_timings(store, "no-such-run") == {}
    with ResultsStore(tmp_path / "fresh.sqlite") as store:
        assert timings.read_timings(store, plan.run_id) == {}  # no table yet: nothing, not an error


def test_time_model_is_in_the_report(tmp_path):
    from denoisebench.cli import main
    from denoisebench.dataset.synthetic import make_synthetic_dataset

    data = make_synthetic_dataset(tmp_path / "ds", scenes=2, frames=2, height=16, width=16, spp=(1, 2))
    args = ["benchmark", "--data", str(data), "--db", str(tmp_path / "db.sqlite"), "--denoisers", "identity"]
    assert (
        main([*args, "--out", str(tmp_path / "r"), "--split", "all", "--time-size", "64x64", "--metrics", "relmse"])
        == 0
    )
    md = (tmp_path / "r" / "report.md").read_text()
    assert "Times are per frame at 1920×1080, projected from 16×16" in md and "GPU" in md


def _low_law(pixels: int) -> float:  # 1 spp: the filter estimates its own variance per pixel
    return 0.0031 + (0.006 - 0.0031) / P0 * pixels


def _high_law(pixels: int) -> float:  # 16 spp: less per-pixel work, less fixed cost
    return 0.0005 + (0.0025 - 0.0005) / P0 * pixels


def test_a_cost_that_shrinks_after_one_spp_is_projected_from_a_timing_at_each_end_of_the_ladder():
    """cross_bilateral's pattern: 6 ms per 1-spp frame, 2.5 ms at 2-16 spp (its own variance estimate at 1 spp).
    One line through the 1-spp timing puts its fixed cost above the 16-spp frame's whole time; the projection
    then charged 2-16 spp only that fixed cost. With a timing at 16 spp, both ends are their planted laws and
    the middle lies between them."""
    small = {1: _low_law(P0), 2: 0.0027, 16: _high_law(P0)}
    cost = tm.DenoiserCost(label="d", pixels0=P0, small=dict(small))
    cost.fixed = tm.line_through([(P0, _low_law(P0)), (P1, _low_law(P1))])[0]
    assert cost.fixed == pytest.approx(0.0031)
    # one line: the 1-spp line scaled whole by the small frames' ratio, never a small frame's time
    assert cost.seconds(HD, 16) == pytest.approx(_low_law(HD) * _high_law(P0) / _low_law(P0))
    fixed16 = tm.line_through([(P0, _high_law(P0)), (P1, _high_law(P1))])[0]
    cost.highest = tm.HighestSppTiming(spp=16, pixels=P1, seconds=_high_law(P1), fixed=fixed16)
    assert cost.seconds(HD, 1) == pytest.approx(_low_law(HD))
    assert cost.seconds(HD, 16) == pytest.approx(_high_law(HD))
    assert _high_law(HD) < cost.seconds(HD, 2) < _low_law(HD)
    assert cost.seconds(P0, 2) == pytest.approx(0.0027)  # the dataset's own size stays as measured


def test_one_large_timing_never_drops_the_per_pixel_part_at_another_spp():
    """kpcn's pattern on a loaded demo run: 86 ms per 64x64 frame at 1 spp, 43 ms at 2 spp (load, not work),
    one timing at 512x512 and 1 spp (2.35 s) putting the fixed cost at 50 ms, above the 2-spp time. At every
    spp the 1080p projection keeps the per-pixel part, scaled by the small frames' ratio; it was 43 ms."""
    p0, p1 = 64 * 64, 512 * 512
    small = {1: 0.0862, 2: 0.0434, 4: 0.0773, 16: 0.0805}
    cost = tm.DenoiserCost(label="kpcn", pixels0=p0, small=dict(small))
    fixed, slope = tm.line_through([(p0, small[1]), (p1, 2.345)])
    cost.fixed = min(fixed, small[1])
    assert cost.fixed > small[2]  # the planted trap: fixed above the 2-spp frame's whole time
    per_pixel_hd = (small[1] - cost.fixed) / p0 * HD
    assert per_pixel_hd == pytest.approx(slope * HD)
    for spp in (1, 2, 3, 4, 16):
        ratio = cost.small_at(spp) / small[1]
        assert cost.seconds(HD, spp) >= per_pixel_hd * ratio - 1e-12
        assert cost.seconds(HD, spp) == pytest.approx((cost.fixed + per_pixel_hd) * ratio)
        assert cost.seconds(HD, spp) > 100 * cost.small_at(spp)  # a 1080p frame, not a 64x64 one
    assert cost.seconds(p1, 1) == pytest.approx(2.345)  # the measured point itself
    assert cost.seconds(p0, 2) == pytest.approx(0.0434)  # the dataset's own size stays as measured


SPP_DEPENDENT = textwrap.dedent(
    """
    import time
    import numpy as np

    class SlowAtOneSpp:
        name = "slow_at_one_spp"
        needs = frozenset({"color"})
        temporal = False
        def reset(self):
            pass
        def denoise(self, frame):
            color = np.asarray(frame.buffers["color"], np.float32)
            time.sleep(2e-5 * color.shape[0] * color.shape[1] * (3 if frame.spp == 1 else 1))
            return color

    class Steady(SlowAtOneSpp):
        name = "steady"
        def denoise(self, frame):
            time.sleep(0.05)  # the same at every spp (and every size)
            return np.asarray(frame.buffers["color"], np.float32)
    """
)


def test_a_denoiser_whose_time_changes_with_spp_is_timed_at_the_highest_spp_too(tmp_path):
    from denoisebench.benchmark.run import run_benchmark
    from denoisebench.benchmark.runner import BenchmarkConfig
    from denoisebench.dataset import open_dataset
    from denoisebench.dataset.synthetic import make_synthetic_dataset
    from denoisebench.results.store import ResultsStore

    plugin = tmp_path / "slow.py"
    plugin.write_text(SPP_DEPENDENT)
    spec, steady = f"{plugin}:SlowAtOneSpp", f"{plugin}:Steady"
    dataset = open_dataset(make_synthetic_dataset(tmp_path / "ds", scenes=1, frames=2, height=16, width=16, spp=(1, 4)))
    config = BenchmarkConfig(denoisers=[spec, steady], spp=[1, 4], split="all", metrics=["relmse"], isolation="none")
    with ResultsStore(tmp_path / "db.sqlite") as store:
        plan = run_benchmark(dataset, config, store, progress=False)
        instances = {d.label: d.instance for d in plan.denoisers}
        records = timing.measure_run_timings(store, dataset, plan, instances, (64, 64), progress=False)
    slow, flat = records["denoiser:slow_at_one_spp"], records["denoiser:steady"]  # labelled by their names
    assert slow["spp"] == 1 and slow["highest"]["spp"] == 4 and slow["highest"]["width"] == 64
    assert slow["highest"]["seconds"] < slow["seconds"] / 2  # a third of the per-pixel sleep, plus call overhead
    assert "highest" not in flat  # the same time at every spp: one timing


def test_each_pays_its_own_line_with_each_point_the_least_of_the_renders_that_make_its_buffers():
    """Planted render lines (seconds per frame = 0.1 + slope · spp at every size): a denoiser reading albedo pays
    its own line; one reading albedo and normal pays its own set's line, whose points are the full feature set's
    where that was measured cheaper (a render of more buffers makes them too); rendering alone pays the
    colour-only line whatever a larger set measured."""
    colour, albedo = COLOUR_ONLY, (*COLOUR_ONLY, "albedo")
    pair, full = (*albedo, "normal"), (*albedo, "normal", "depth")

    def line(key, slope):
        points = [[1, 0.1 + slope], [4, 0.1 + 4 * slope]]
        return {"buffers": list(key), "points": points, "small_points": points, "spread": 1.1}

    probe = {"width": 160, "height": 160, "small_pixels": P0, "repeats": 3, "scene": "s"}
    probe["lines"] = [line(colour, 0.01), line(albedo, 0.02), line(pair, 0.05), line(full, 0.03)]
    frames = [
        SimpleNamespace(denoiser=label, spp=spp, render_seconds=0.5, denoise_seconds=0.01)
        for spp in (1, 4)
        for label in (NOISY, "a", "p")
    ]
    timings = {
        "render_probe": probe,
        "denoiser:a": {"width": 160, "height": 160, "seconds": 0.04, "buffers": list(albedo)},
        "denoiser:p": {"width": 160, "height": 160, "seconds": 0.04, "buffers": list(pair)},
    }
    model = tm.build_time_model(_Data(frames, [NOISY, "a", "p"], [1, 4]), timings, (80, 80), (80, 80))
    assert model.render.buffers == colour and model.render_seconds(4) == pytest.approx(0.1 + 4 * 0.01)
    assert model.render_line("a").buffers == albedo
    assert model.render_seconds(4, "a") == pytest.approx(0.1 + 4 * 0.02)
    assert model.render_line("p").buffers == pair and model.render_seconds(4, "p") == pytest.approx(0.1 + 4 * 0.03)
    assert model.total_seconds("p", 4) == pytest.approx(0.1 + 4 * 0.03 + 0.01)
    assert model.lines[pair].borrowed == 4 and model.lines[colour].borrowed == 0
    assert any("measured cheaper" in n for n in model.notes)
    paid = {tuple(r["buffers"]): r["paid_by"] for r in model.as_dict()["render_lines"]}
    assert paid == {colour: [NOISY], albedo: ["a"], pair: ["p"], full: []}


def test_a_larger_set_measured_cheaper_at_one_spp_lends_that_point_only():
    """Load noise: the colour+albedo render measured cheaper than colour alone at 4 spp, not at 1 spp. Rendering
    alone keeps its own line, taking only that point (least of the two): its slope moves with the measurement
    instead of its whole line switching to the other set's shape."""
    colour, albedo = COLOUR_ONLY, (*COLOUR_ONLY, "albedo")
    probe = {"width": 160, "height": 160, "small_pixels": P0, "repeats": 3, "scene": "s"}
    # all per-pixel: each small point is the large one over the pixel ratio 4
    own = {"buffers": list(colour), "points": [[1, 0.2], [4, 0.5]], "small_points": [[1, 0.05], [4, 0.125]]}
    larger = {"buffers": list(albedo), "points": [[1, 0.4], [4, 0.45]], "small_points": [[1, 0.1], [4, 0.1125]]}
    probe["lines"] = [own, larger]
    frames = [SimpleNamespace(denoiser=NOISY, spp=spp, render_seconds=0.5, denoise_seconds=None) for spp in (1, 4)]
    model = tm.build_time_model(_Data(frames, [NOISY], [1, 4]), {"render_probe": probe}, (160, 160), (80, 80))
    assert model.render.buffers == colour and model.lines[colour].borrowed == 2  # 4 spp at both sizes
    assert model.render_seconds(1) == pytest.approx(0.2) and model.render_seconds(4) == pytest.approx(0.45)
    assert model.lines[albedo].seconds(160 * 160, 1) == pytest.approx(0.4)  # its own points: nothing larger
