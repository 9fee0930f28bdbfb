"""The learned models by name: how to build each, its configurations, what it reads and trains on.

``dpcn`` and ``kpcn`` (:mod:`.pcn`) and ``lbf`` (:mod:`.lbf`, the MLP-driven cross-bilateral
filter) are spatial and train on single-frame crops; ``rae`` (:mod:`.rae`) is temporal and trains
on K-frame crop sequences. ``recipes`` holds each configuration's training defaults (what
``denoisebench train`` uses for an option not given on the command line).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field

from torch import nn

from denoisebench.models import lbf, pcn, rae
from denoisebench.models.features import OPTIONAL_BUFFERS
from denoisebench.models.names import MODEL_NAMES


@dataclass(frozen=True)
class ModelSpec:
    name: str
    build: Callable[..., nn.Module]
    configs: dict[str, dict]
    temporal: bool
    #: Reference layers trained against ("color" → "reference", others → "reference_<name>").
    targets: tuple[str, ...]
    #: Buffers a training item carries when the dataset has them (features.py fills the rest with zeros).
    buffers: tuple[str, ...]
    #: Training defaults per configuration name (``loss``, ``crop``, ...); see training_options.TrainOptions.
    recipes: dict[str, dict] = field(default_factory=dict)


def _pcn_spec(name: str, build: Callable[..., nn.Module], configs: dict[str, dict]) -> ModelSpec:
    """DPCN's or KPCN's spec: the same targets, buffers and recipe, another builder and configurations.

    Notes
    -----
    The paper's recipe: each branch trained on its own lobe with L1, no combined-colour loss.
    """
    targets = ("color", "diffuse", "specular")
    return ModelSpec(name, build, configs, False, targets, OPTIONAL_BUFFERS, recipes={"paper": {"loss": "lobes"}})


MODELS: dict[str, ModelSpec] = {
    "dpcn": _pcn_spec("dpcn", pcn.make_dpcn, pcn.DPCN_CONFIGS),
    "kpcn": _pcn_spec("kpcn", pcn.make_kpcn, pcn.KPCN_CONFIGS),
    # The paper's recipe: 128 px crops (where the scenes are that large), windows played both ways
    # (the small configuration plays both ways too).
    "rae": ModelSpec(
        "rae",
        rae.make_rae,
        rae.CONFIGS,
        True,
        ("color",),
        ("albedo", "normal", "depth", "roughness", "position"),
        recipes={"paper": {"crop": 128, "play_backward": True}, "small": {"play_backward": True}},
    ),
    # The paper's loss, relative MSE of the filtered image, in every configuration.
    "lbf": ModelSpec(
        "lbf",
        lbf.make_lbf,
        lbf.CONFIGS,
        False,
        ("color",),
        ("color_var", "albedo", "normal", "depth"),
        recipes={"small": {"loss": "relmse"}, "paper": {"loss": "relmse"}},
    ),
}


if tuple(MODELS) != MODEL_NAMES:  # the one list of names (models/names.py: importable without torch)
    raise ImportError(f"models/names.py lists {MODEL_NAMES}, the catalog builds {tuple(MODELS)}")


def get_spec(name: str) -> ModelSpec:
    try:
        return MODELS[name]
    except KeyError:
        raise KeyError(f"unknown model {name!r}; models: {', '.join(MODELS)}") from None


def model_config(name: str, config: str | dict) -> dict:
    """The keyword arguments of a named configuration (``small``/``paper``) or a dict given as is."""
    spec = get_spec(name)
    if isinstance(config, dict):
        return dict(config)
    try:
        return dict(spec.configs[config])
    except KeyError:
        raise KeyError(f"model {name!r} has configurations {', '.join(spec.configs)}, not {config!r}") from None


def build_model(name: str, config: str | dict = "small") -> nn.Module:
    """A freshly initialised model (weights from torch's global RNG: seed it first)."""
    return get_spec(name).build(**model_config(name, config))


def parameter_count(model: nn.Module) -> int:
    return sum(p.numel() for p in model.parameters())
