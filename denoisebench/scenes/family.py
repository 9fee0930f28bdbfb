"""A scene family: a seeded procedural generator of one kind of USD stage."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from denoisebench.scenes.authoring import SceneBuilder
from denoisebench.scenes.effects import validate_effects


@dataclass(frozen=True, kw_only=True)
class SceneFamily:
    """A seeded procedural generator of one kind of scene; every field is a keyword.

    Attributes:
        name: the CLI name.
        effects: the effects every stage of this family exercises, in vocabulary order.
        description: one line.
        up_axis: "Y" or "Z", the stage's upAxis.
        meters_per_unit: the stage's metersPerUnit (0.01 for a centimeter stage).
        camera_move: one line naming the camera's move over the sequence.
        build: ``build(builder, rng)`` authors the content into a :class:`SceneBuilder`.
    """

    name: str
    effects: tuple[str, ...]
    description: str
    up_axis: str
    meters_per_unit: float
    camera_move: str
    build: Callable[[SceneBuilder, np.random.Generator], None]

    def __post_init__(self) -> None:
        if tuple(self.effects) != validate_effects(self.effects):
            raise ValueError(f"{self.name}: effects must be vocabulary names in vocabulary order")

    def author(self, out_dir, seed: int = 0, frames: int = 8, width: int = 256, height: int = 256) -> Path:
        """Write ``out_dir/scene.usda`` (and ``out_dir/textures/*.png``); return the stage path.

        ``width``/``height`` only set the camera's aspect ratio (verticalAperture); the renderer
        chooses the resolution. The same family, seed, frames and aspect give byte-identical files.
        """
        if width <= 0 or height <= 0:
            raise ValueError(f"width and height must be positive, got {width}x{height}")
        builder = SceneBuilder(
            out_dir,
            family=self.name,
            seed=seed,
            frames=frames,
            effects=self.effects,
            up_axis=self.up_axis,
            meters_per_unit=self.meters_per_unit,
        )
        builder.aspect = width / height
        self.build(builder, np.random.default_rng(int(seed)))
        return builder.save()
