"""The demo's dataset: scenes chosen so that its per-effect table separates the effects it shows."""

from __future__ import annotations

from pxr import Usd

from denoisebench.commands.demo import DEMO_DATASET_FAMILIES, DEMO_DATASET_SEED, DEMO_FRAMES, DEMO_SIZE
from denoisebench.generator.dataset_scenes import family_scene_names
from denoisebench.scenes import METADATA_KEY, get_family, list_families
from denoisebench.scenes.families import cluttered


def _demo_scene_effects(root) -> dict[str, set[str]]:
    """{scene name: effects its stage declares}, authored as the demo's dataset stage authors them."""
    out = {}
    for family, seed, name in family_scene_names(list(DEMO_DATASET_FAMILIES), 1, DEMO_DATASET_SEED):
        path = get_family(family).author(root / name, seed=seed, frames=DEMO_FRAMES, width=DEMO_SIZE, height=DEMO_SIZE)
        stage = Usd.Stage.Open(str(path))
        out[name] = set(stage.GetRootLayer().customLayerData[METADATA_KEY]["effects"])
    return out


def _inseparable(effects: set[str]) -> bool:
    """True when no family's stages can show some of ``effects`` without the others.

    A fixed family declares the same effects at every seed; the cluttered family always has
    :data:`cluttered.ALWAYS` and draws the rest per seed, so those can be had apart."""
    for family in list_families():
        always = set(cluttered.ALWAYS) if family.name == "cluttered" else set(family.effects)
        optional = set(family.effects) - always
        if optional & effects or (always & effects and not effects <= always):
            return False
    return True


def test_every_demo_effect_has_two_scenes_and_a_scene_set_of_its_own(tmp_path):
    """the per-effect table (geometric mean over the scenes with the effect) of one scene per
    effect confounds effects; two effects over the same scenes give the same column."""
    scene_effects = _demo_scene_effects(tmp_path)
    assert any(name.startswith("cluttered_") for name in scene_effects)
    scenes_of: dict[str, frozenset[str]] = {}
    for name, effects in scene_effects.items():
        for effect in effects:
            scenes_of[effect] = scenes_of.get(effect, frozenset()) | {name}
    assert len(scenes_of) >= 7, scenes_of
    thin = {e: sorted(s) for e, s in scenes_of.items() if len(s) < 2}
    assert not thin, thin
    # an effect on every scene would repeat the table's "overall" column
    assert all(s != frozenset(scene_effects) for s in scenes_of.values()), scenes_of
    groups: dict[frozenset[str], set[str]] = {}
    for effect, scenes in scenes_of.items():
        groups.setdefault(scenes, set()).add(effect)
    shared = [effects for effects in groups.values() if len(effects) > 1]
    # only effects no family shows apart (every stage with a glass has a mirror, and the reverse) may share
    assert all(_inseparable(effects) for effects in shared), shared


def test_inseparable_tells_fixed_pairs_from_pairs_a_seed_can_split():
    assert _inseparable({"specular", "transmission"})
    assert not _inseparable({"depth_of_field", "motion_blur"})  # cluttered draws them apart
    assert not _inseparable({"environment", "motion_blur"})  # glass_env has the environment alone
    assert not _inseparable({"area_lights", "indirect"})  # glossy_fireflies: area lights, no indirect


def test_the_demo_scores_what_the_report_leads_with_and_leaves_out_only_what_it_names():
    """The demo's metric selection keeps every metric the report's curves, tables, verdicts and flicker figure
    read, and drops only the default metrics it names; its denoisers are every available one but the skips,
    each of which is a denoiser that exists (a renamed one would otherwise slip back in unnoticed)."""
    from denoisebench.commands.demo import DEMO_METRIC_SKIPS, DEMO_SKIPS, demo_denoisers, demo_metrics
    from denoisebench.denoisers.registry import available_denoisers
    from denoisebench.metrics.registry import default_metric_names
    from denoisebench.results.names import ERROR_METRICS, FLICKER_METRICS, REQUIRED_METRICS
    from tests.support.paths import REPO

    metrics = set(demo_metrics())
    assert set(REQUIRED_METRICS) | set(ERROR_METRICS) | set(FLICKER_METRICS) <= metrics
    assert metrics | set(DEMO_METRIC_SKIPS) == set(default_metric_names())
    assert set(DEMO_SKIPS) <= set(available_denoisers())
    assert set(demo_denoisers()) == set(available_denoisers()) - set(DEMO_SKIPS)
    page = (REPO / "docs" / "demo.md").read_text()
    assert all(f"`{name}`" in page for name in (*DEMO_SKIPS, *DEMO_METRIC_SKIPS))
