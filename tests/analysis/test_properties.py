"""Analysis that cannot crash on finite numbers: Hypothesis drives the functions from scene values to the
report's verdicts with random finite inputs (flat, rising, noisy and single-rung curves, empty cells,
ties, values from 1e-300 to 1e300). Each returns a finite answer or a stated "no answer" (None) and
never raises.

The example counts are modest (the suite's time budget); ``derandomize`` keeps every run the same.
"""

from __future__ import annotations

import math

from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from denoisebench.analysis import aggregate as agg
from denoisebench.analysis import equal_tables as et
from denoisebench.analysis import lead
from denoisebench.analysis.accuracy import AccuracyTime, NoisyFit, Point, readings
from denoisebench.analysis.run_index import RunIndex
from denoisebench.analysis.summary import Cell, SummaryRow, metric_cell
from denoisebench.analysis.time_model import DenoiserCost, RenderCost, TimeModel
from denoisebench.results.names import NOISY
from denoisebench.results.records import FrameRow, UnitRow

PROPERTY = settings(max_examples=60, deadline=None, derandomize=True, suppress_health_check=[HealthCheck.too_slow])

#: Any finite float up to 1e300 in size (negative, zero and subnormal included): sums of a few stay finite.
finite = st.floats(min_value=-1e300, max_value=1e300, allow_nan=False, allow_infinity=False)
#: A positive finite score (errors, seconds).
positive = st.floats(min_value=1e-300, max_value=1e300, allow_nan=False, allow_infinity=False)
#: A per-scene value: finite, missing (None), or not finite (what the store may hand back).
cell_value = st.one_of(finite, st.none(), st.just(math.nan), st.just(math.inf))
scenes = st.lists(st.sampled_from(["a", "b", "c", "d", "e", "f", "g"]), unique=True, max_size=7)
RUNG_CHOICES = [1, 2, 4, 8, 16, 32, 64]
#: A measured curve {spp: error}: any length from empty to seven rungs, any shape (flat, rising, noisy).
curves = st.dictionaries(st.sampled_from(RUNG_CHOICES), st.one_of(positive, st.just(0.0), finite), max_size=7)


def _per_scene(draw_values):
    return st.builds(lambda names, values: dict(zip(names, values)), scenes, st.lists(draw_values, max_size=7))


def _finite_or_none(x) -> bool:
    return x is None or (isinstance(x, (int, float)) and math.isfinite(x))


# --------------------------------------------------------------------------- aggregation


@PROPERTY
@given(_per_scene(cell_value), _per_scene(cell_value), _per_scene(st.one_of(positive, st.none())))
def test_every_rule_aggregates_any_finite_scene_values(mine, noisy, ses):
    for rule in ("mean", "geomean", "relative_to_input"):
        value, low, high, count = agg.aggregate(rule, mine, noisy, ses)
        assert all(_finite_or_none(x) for x in (value, low, high))
        assert count >= 0
    corrected, raised = agg.corrected_values(mine, noisy, ses)
    assert set(corrected) == set(mine) and set(raised) <= set(mine)


@PROPERTY
@given(_per_scene(cell_value), _per_scene(cell_value))
def test_the_lead_aggregate_is_finite_or_no_answer(mine, anchors):
    value, low, high, count = lead.lead_aggregate(mine, anchors)
    assert all(_finite_or_none(x) for x in (value, low, high))
    assert (value is None) == (count == 0)
    if value is not None and low is not None:
        assert low <= high
    assert _finite_or_none(lead.arithmetic_mean(mine))
    decided = lead.deciding_scenes(mine)
    assert len(decided) <= 1 and all(share > lead.DECIDING_SHARE for _, share in decided)
    factor = lead.drop_one_factor(mine, anchors)
    assert factor is None or (math.isfinite(factor) and factor >= 1.0)


@PROPERTY
@given(
    st.lists(st.floats(min_value=-1e6, max_value=1e6, allow_nan=False), max_size=8),
    st.lists(st.floats(min_value=0, max_value=1e6, allow_nan=False), max_size=8),
)
def test_the_bootstrap_interval_is_ordered_or_absent(terms, ses):
    ses = (ses + [0.0] * len(terms))[: len(terms)]
    low, high = agg.bootstrap_mean(terms, ses)
    assert (low is None) == (high is None)
    if low is not None:
        assert math.isfinite(low) and math.isfinite(high) and low <= high


# --------------------------------------------------------------------------- equal tables


@PROPERTY
@given(curves, finite)
def test_reading_a_curve_never_raises(curve, x):
    spp = abs(x) if x else 1.0
    for found in (et.error_at(curve, spp), et.spp_for(curve, x)):
        assert found is None or (
            math.isfinite(found.value) and found.how in ("measured", "interpolated", "at_most", "extrapolated")
        )
    found = et.spp_for(curve, x)
    if found is not None and found.how == "extrapolated":
        top = max(s for s, e in curve.items() if e is not None and e > 0)
        assert found.value <= et.EXTRAPOLATION_LIMIT * top


class _Model:
    """A time model from drawn costs: render offset + per-spp seconds, denoise seconds per label."""

    time_at, projected = (64, 64), False

    def __init__(self, offset, per_spp, denoise):
        self.offset, self.per_spp, self.denoise = offset, per_spp, denoise

    def render_seconds(self, spp):
        return self.offset + self.per_spp * spp

    def total_seconds(self, label, spp):
        extra = 0.0 if label == NOISY else self.denoise.get(label)
        return None if extra is None else self.render_seconds(spp) + extra


def _rows(table):
    rows = []
    for label, curve in table.items():
        for spp, value in curve.items():
            cell = Cell(value=value, low=None, high=None, scenes=3)
            rows.append(
                SummaryRow(
                    denoiser=label,
                    spp=spp,
                    metrics={"relmse": cell},
                    denoise_seconds=None,
                    total_seconds=None,
                    render_seconds=None,
                    frames=3,
                    failed_units=0,
                )
            )
    return rows


labels = st.sampled_from([NOISY, "a", "b"])


@PROPERTY
@given(
    st.dictionaries(labels, curves, max_size=3),
    st.floats(min_value=0, max_value=1e6, allow_nan=False),
    st.floats(min_value=1e-9, max_value=1e6, allow_nan=False),
    st.dictionaries(labels, st.floats(min_value=0, max_value=1e6, allow_nan=False), max_size=3),
)
def test_equal_tables_and_their_verdicts_never_raise(table, offset, per_spp, denoise):
    model = _Model(offset, per_spp, denoise)
    tables = et.build_tables(_rows(table), model, RUNG_CHOICES, "relmse")
    for sentence in et.verdicts(tables):
        assert isinstance(sentence, str) and "nan" not in sentence and "inf" not in sentence
    et.as_dict(tables)


# --------------------------------------------------------------------------- readings (accuracy against time)


@PROPERTY
@given(
    st.lists(st.tuples(labels, st.sampled_from(RUNG_CHOICES), positive, positive), max_size=8),
    st.floats(min_value=-5, max_value=-1e-6),
    st.floats(min_value=-50, max_value=50),
    positive,
)
def test_readings_never_raise(points, slope, intercept, per_spp):
    pts = [Point(denoiser=label, spp=spp, seconds=seconds, error=error) for label, spp, seconds, error in points]
    fit = NoisyFit(intercept=intercept, slope=slope, seconds_per_spp=per_spp, measured_spp=[1], assumed_slope=False)
    at = AccuracyTime(metric="relmse", points=pts, fit=fit, reference_seconds=None, reference_spp=None, hidden=[])
    for sentence in readings(at):
        assert isinstance(sentence, str)
    for x in (fit.spp_for(1e-300), fit.error_at(1e300)):
        assert math.isfinite(x)


# --------------------------------------------------------------------------- time model


@PROPERTY
@given(
    st.floats(min_value=0, max_value=1e6, allow_nan=False),
    st.floats(min_value=0, max_value=1e6, allow_nan=False),
    st.dictionaries(st.sampled_from(RUNG_CHOICES), st.floats(min_value=0, max_value=1e6, allow_nan=False), max_size=4),
    st.one_of(st.none(), st.floats(min_value=0, max_value=1e6, allow_nan=False)),
    st.floats(min_value=0, max_value=1e6, allow_nan=False),
)
def test_the_time_model_gives_finite_seconds(offset, per_spp, small, fixed, spp):
    render = RenderCost(pixels0=4096, offset0=offset, per_spp0=per_spp, measured_spp=[1, 4])
    cost = DenoiserCost(
        label="a", pixels0=4096, small=small, fixed=fixed, large_pixels=None if fixed is None else 65536
    )
    model = TimeModel(
        time_at=(1920, 1080), pixels0=4096, dataset_size=(64, 64), render=render, denoisers={"a": cost}, projected=True
    )
    for x in (model.render_seconds(spp), model.total_seconds("a", spp), model.total_seconds(NOISY, spp)):
        assert _finite_or_none(x)
    bounds = model.ratio_bounds("a", spp, max(spp, 1.0))
    assert bounds is None or all(math.isfinite(b) for b in bounds)
    model.as_dict()


# --------------------------------------------------------------------------- cells over planted runs


class _Run(RunIndex):
    """A run of planted per-scene values: one frame per unit (its value is the scene's)."""

    def __init__(self, planted: dict):
        units, frames = [], []
        for (label, spp, scene), value in planted.items():
            units.append(
                UnitRow(
                    denoiser=label,
                    scene=scene,
                    spp=spp,
                    status="ok",
                    error=None,
                    frames=1,
                    frames_ok=1,
                    denoise_seconds=0.0,
                    render_seconds=1.0,
                )
            )
            frames.append(
                FrameRow(
                    denoiser=label,
                    scene=scene,
                    spp=spp,
                    frame=0,
                    status="ok",
                    error=None,
                    render_seconds=1.0,
                    denoise_seconds=0.0,
                    total_seconds=1.0,
                    sanitized=0,
                    metrics={"relmse_robust": value, "grad_l1": value},
                    floors={},
                    ref_se={},
                )
            )
        super().__init__(units, frames, [])
        self.labels = sorted({label for label, _, _ in planted})


planted_runs = st.dictionaries(
    st.tuples(labels, st.sampled_from([1, 4, 16]), st.sampled_from(["s1", "s2", "s3", "s4", "s5"])),
    st.one_of(finite, st.just(math.nan)),
    max_size=30,
)


@PROPERTY
@given(planted_runs)
def test_every_cell_of_a_planted_run_is_finite_or_no_answer(planted):
    data = _Run(planted)
    for label in data.labels:
        for spp in data.spp:
            for metric in ("relmse_robust", "grad_l1"):
                cell = metric_cell(data, label, spp, metric=metric, scenes=None)
                for x in (cell.value, cell.low, cell.high, cell.arithmetic, cell.drop_one):
                    assert _finite_or_none(x)
                assert len(cell.deciding_scenes) <= 1
