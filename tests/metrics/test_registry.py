"""Registry by name, compute_metrics on frames and sequences (non-finite reporting), cost helpers."""

from __future__ import annotations

import math
import time

import numpy as np
import pytest

from denoisebench import metrics as M

ALL = [
    "mse",
    "relmse",
    "smape",
    "l1",
    "psnr",
    "ssim",
    "flip",
    "deltae2000",
    "grad_l1",
    "hfen",
    "temporal_l1",
    "temporal_l1_warped",
    "temporal_relmse",
    "tpsnr",
]


@pytest.fixture
def frames():
    rng = np.random.default_rng(0)
    ref = rng.uniform(0.1, 2.0, (3, 16, 20, 3))
    pred = ref + rng.normal(0, 0.05, ref.shape)
    motion = np.zeros((3, 16, 20, 2))
    return pred, ref, motion


# --------------------------------------------------------------------------- registry


def test_every_metric_is_registered_with_its_properties():
    assert M.metric_names()[: len(ALL)] == ALL  # the core set first; optional metrics (msssim, cvvdp, ...) follow
    higher = {n for n in ALL if M.get_metric(n).higher_is_better}
    assert higher == {"psnr", "ssim", "tpsnr"}
    assert {n for n in ALL if M.get_metric(n).domain == "tonemapped"} == {"psnr", "ssim", "tpsnr"}
    assert M.get_metric("deltae2000").domain == "reinhard"
    assert M.metric_names("temporal")[:4] == ["temporal_l1", "temporal_l1_warped", "temporal_relmse", "tpsnr"]
    assert M.metric_names("gradient")[:2] == ["grad_l1", "hfen"]
    assert M.get_metric("relmse").fn is M.relmse and M.get_metric("relmse").map_fn is M.relmse_map
    assert M.get_metric("temporal_l1_warped").requires == ("motion",)
    for n in ALL:
        m = M.get_metric(n)
        assert m.better(m.perfect, m.worst), n


def test_entries_are_declared_once_beside_their_functions():
    """The registry holds exactly the modules' METRICS entries, in order; each WORST comes from them."""
    from denoisebench.metrics import registry

    declared = [m for module in registry.BUILTIN_MODULES for m in module.METRICS]
    assert [m.name for m in declared] == M.metric_names()
    for module in registry.BUILTIN_MODULES:
        assert module.WORST == {m.name: m.worst for m in module.METRICS}, module.__name__
        for m in module.METRICS:
            assert M.get_metric(m.name) is m
            assert m.fn.__module__ == module.__name__, m.name
    with pytest.raises(TypeError):
        M.Metric("x", M.mse, False, "linear", "spatial", math.inf, 0.0)  # every field is a keyword


def test_every_metric_states_its_aggregation_and_linear_scores_are_never_plain_means():
    # scale-dependent scores of linear radiance: an arithmetic mean over scenes would let the
    # brightest scene decide (temporal_l1 ranked the noisy input above oidn)
    scale_dependent = {"mse", "l1", "grad_l1", "hfen", "temporal_l1", "temporal_l1_warped"}
    for n in ALL:
        m = M.get_metric(n)
        assert m.aggregate in ("mean", "geomean", "relative_to_input"), n
        assert (m.aggregate != "mean") == (n in scale_dependent), n
    for n in M.metric_names():  # every registered metric, optional ones included, states a valid rule
        assert M.get_metric(n).aggregate in ("mean", "geomean", "relative_to_input"), n
    assert {n for n in ALL if M.get_metric(n).floor_fn is not None} == {"mse", "relmse", "temporal_relmse"}
    with pytest.raises(ValueError, match="aggregate"):
        M.Metric(
            name="x",
            fn=M.mse,
            higher_is_better=False,
            domain="linear",
            kind="spatial",
            worst=math.inf,
            perfect=0.0,
            aggregate="median",
        )


def test_compute_metrics_reports_floors_with_the_reference_variance(frames):
    pred, ref, motion = frames
    var = np.full_like(ref, 1e-4)
    out = M.compute_metrics(pred, ref, ["mse", "relmse", "temporal_relmse", "ssim"], motion=motion, ref_var=var)
    assert out["mse"].floor == pytest.approx(1e-4) and out["mse"].corrected == out["mse"].value - 1e-4
    assert out["ssim"].floor is None and out["ssim"].corrected is None
    assert out["temporal_relmse"].floor > 0 and out["temporal_relmse"].ref_se > 0
    assert M.compute_metrics(pred, ref, ["mse"])["mse"].floor is None  # no variance, no floor


def test_names_are_case_insensitive_with_aliases():
    assert M.get_metric("RelMSE").name == "relmse"
    assert M.get_metric("delta_e").name == "deltae2000"
    assert M.get_metric("HDR_FLIP").name == "flip"
    with pytest.raises(ValueError, match="unknown metric 'nope'.*relmse"):
        M.get_metric("nope")


def test_plugins_register_and_are_computed(frames):
    pred, ref, _ = frames

    def max_abs(p, r):
        return float(np.max(np.abs(np.asarray(p, float) - r)))

    entry = dict(higher_is_better=False, domain="linear", kind="spatial", worst=math.inf, perfect=0.0)
    metric = M.Metric(name="max_abs", fn=max_abs, **entry)
    M.register_metric(metric)
    try:
        with pytest.raises(ValueError, match="already registered"):
            M.register_metric(metric)
        res = M.compute_metrics(pred[0], ref[0], ["max_abs", "l1"])
        assert list(res) == ["max_abs", "l1"]
        assert res["max_abs"].value == pytest.approx(np.max(np.abs(pred[0] - ref[0])))
        bad = pred[0].copy()
        bad[0, 0, 0] = np.nan
        assert M.compute_metrics(bad, ref[0], ["max_abs"])["max_abs"].value == math.inf  # policy enforced
    finally:
        M.unregister_metric("max_abs")
    assert "max_abs" not in M.metric_names()
    with pytest.raises(ValueError):
        M.Metric(name="Bad Name", fn=max_abs, **entry)
    with pytest.raises(ValueError, match="alias"):
        M.register_metric(M.Metric(name="delta_e", fn=max_abs, **entry))


# --------------------------------------------------------------------------- compute_metrics


def test_compute_on_a_frame_matches_the_functions(frames):
    pred, ref, _ = frames
    res = M.compute_metrics(pred[0], ref[0], maps=True)
    assert [n for n in res if n in ALL] == [n for n in ALL if M.get_metric(n).kind != "temporal"]
    for name, r in res.items():
        assert r.value == pytest.approx(M.get_metric(name).fn(pred[0], ref[0]), rel=1e-12)
        assert r.nonfinite_count == 0 and not r.worst_value_used and r.per_frame is None
        assert r.seconds >= 0
        if M.get_metric(name).map_fn is not None:
            assert r.map.shape == (16, 20)
    assert res["psnr"].map is None
    d = res["relmse"].as_dict()
    assert d["name"] == "relmse" and d["higher_is_better"] is False and "map" not in d


def test_compute_on_a_sequence(frames):
    pred, ref, motion = frames
    res = M.compute_metrics(pred, ref, motion=motion)
    assert [n for n in res if n in ALL] == ALL  # optional metrics (msssim, cvvdp, ...) may follow
    assert res["ssim"].per_frame == tuple(M.ssim(p, r) for p, r in zip(pred, ref))
    assert res["ssim"].value == pytest.approx(np.mean(res["ssim"].per_frame))
    assert res["temporal_l1"].value == pytest.approx(M.temporal_l1(pred, ref))
    assert res["temporal_l1_warped"].value == pytest.approx(M.temporal_l1_warped(pred, ref, motion))
    without_motion = M.compute_metrics(list(pred), list(ref))
    assert "temporal_l1_warped" not in without_motion and "tpsnr" in without_motion
    maps = M.compute_metrics(pred, ref, ["l1", "temporal_l1"], maps=True)
    assert maps["l1"].map.shape == (3, 16, 20) and maps["temporal_l1"].map.shape == (2, 16, 20)


def test_compute_reports_nonfinite_counts(frames):
    pred, ref, motion = frames
    pred = pred.copy()
    pred[1, 2, 3, :] = np.nan
    pred[2, 0, 0, 1] = np.inf
    res = M.compute_metrics(pred, ref, motion=motion)
    for name, r in res.items():
        assert r.nonfinite_count == 4, name
        assert r.worst_value_used and r.value == M.get_metric(name).worst, name
    assert res["l1"].per_frame[0] == pytest.approx(M.l1(pred[0], ref[0]))  # frame 0 is fine
    assert res["l1"].per_frame[1] == math.inf
    single = M.compute_metrics(pred[1], ref[1], ["ssim", "smape"])
    assert single["ssim"].value == -1.0 and single["smape"].value == 1.0
    assert single["ssim"].nonfinite_count == 3


def test_compute_errors(frames):
    pred, ref, motion = frames
    with pytest.raises(ValueError, match="temporal"):
        M.compute_metrics(pred[0], ref[0], ["tpsnr"])
    with pytest.raises(ValueError, match="needs motion"):
        M.compute_metrics(pred, ref, ["temporal_l1_warped"])
    with pytest.raises(ValueError, match=r"\(3, 16, 20, 3\).*\(3, 16, 19, 3\)"):
        M.compute_metrics(pred, ref[..., :19, :])
    with pytest.raises(ValueError, match="unknown metric"):
        M.compute_metrics(pred[0], ref[0], ["relmse", "bogus"])
    with pytest.raises(ValueError, match="H×W×3"):
        M.compute_metrics(np.ones((4, 4)), np.ones((4, 4)))


def test_metrics_import_nothing_of_the_project():
    """docs/architecture.md: metrics imports nothing of the project but its own modules."""
    import ast
    from pathlib import Path

    package = Path(M.__file__).parent
    for path in package.glob("*.py"):
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.ImportFrom):
                module = node.module or ""
                assert node.level == 0, f"{path.name}: the package's own modules are imported absolutely"
                inside = module == "denoisebench.metrics" or module.startswith("denoisebench.metrics.")
                assert inside or not module.startswith("denoisebench"), path.name
            elif isinstance(node, ast.Import):
                names = [a.name for a in node.names if a.name.startswith("denoisebench")]
                assert all(n.startswith("denoisebench.metrics") for n in names), path.name


# --------------------------------------------------------------------------- cost


def test_measure_call_times_and_traces_memory():
    def work(n):
        a = np.ones(n)  # n float64 = 8·n bytes
        time.sleep(0.02)
        return float(a.sum())

    cost = M.measure_call(work, 1_000_000)
    assert cost.result == 1_000_000.0
    assert cost.seconds >= 0.02
    assert 8_000_000 <= cost.peak_bytes < 9_000_000
    assert M.measure_call(work, 10, trace_memory=False).peak_bytes == 0
    with pytest.raises(ZeroDivisionError):
        M.measure_call(lambda: 1 / 0)
    import tracemalloc

    assert not tracemalloc.is_tracing()


def test_per_megapixel_and_totals():
    assert M.megapixels((1000, 2000, 3)) == 2.0
    assert M.seconds_per_megapixel(3.0, (1000, 2000)) == 1.5
    assert M.seconds_per_megapixel(1.0, 250_000) == 4.0
    assert M.total_seconds(0.5, 16, 2.0) == 10.0
    with pytest.raises(ValueError):
        M.megapixels((0, 10))
    with pytest.raises(ValueError):
        M.total_seconds(-1, 4, 0)
    costs = [M.CallCost(1.0, 10), M.CallCost(3.0, 30)]
    s = M.summarize_costs(costs, (500, 1000))
    assert (s.frames, s.seconds_per_frame, s.seconds_per_megapixel, s.peak_bytes) == (2, 2.0, 4.0, 30)
