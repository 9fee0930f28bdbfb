"""Samplers on a dataset's own scenes, rendered live: a scene's stage and plan as progressive frames.

:class:`LiveScene` loads a scene file once as frame_jobs does (``scene.usda`` translated, or ``scene.xml``
loaded by Mitsuba) with a render plan, and
:meth:`LiveScene.open` gives a :class:`~denoisebench.generator.render.progressive.ProgressiveFrame`
of one frame, the handle :func:`~denoisebench.sampling.harness.run_sampler` drives.
:meth:`LiveScene.from_dataset` takes a dataset scene's own stage, plan, size and render seed from its
manifest, so that a sampler renders exactly what the stored inputs and the reference show.
:func:`run_live` is one sampler on one frame at one budget.

Notes
-----
* **Seeds.** The stored noisy inputs use the scene's ``render_seed`` (noisy stream), the reference
  the same seed's reference stream, adaptive references and independent rungs seeds hashed from it
  with their own tags. A live render uses :func:`live_seed`, a BLAKE2b hash of the render seed with
  the tag :data:`LIVE_STREAM` (never the render seed itself), on the noisy stream: its samples are
  none of the dataset's (another hash colliding has odds of 2⁻³²).
* **Common random numbers.** Every sampler of a run gets the same live seed, and the renderer's
  ``j``-th sample of a pixel is the same sample in every render with that seed: two samplers differ
  only in where they put samples, not in luck, which sharpens their comparison. ``repeat`` gives an
  independent draw.
* A moving scene (objects with their own motion) is rebuilt per frame, as the generator does.
"""

from __future__ import annotations

import hashlib
import struct
from pathlib import Path

from denoisebench.dataset import open_dataset
from denoisebench.errors import UserInputError
from denoisebench.generator.contract.render_plan import RenderPlan
from denoisebench.generator.dataset_scenes import load_scene_file
from denoisebench.generator.render.progressive import ProgressiveFrame
from denoisebench.generator.render.scene import build_mitsuba_scene
from denoisebench.sampling.harness import run_sampler

#: Stream tag of live sampler renders, hashed with the render seed.
LIVE_STREAM = 11


def live_seed(render_seed: int, repeat: int = 0) -> int:
    """The seed of live renders of a scene: BLAKE2b of its render seed, :data:`LIVE_STREAM` and ``repeat``."""
    data = struct.pack("<qqq", int(render_seed), LIVE_STREAM, int(repeat))
    seed = int.from_bytes(hashlib.blake2b(data, digest_size=4).digest(), "little")
    return seed if seed != int(render_seed) else seed ^ 1


class LiveScene:
    """A stage loaded for progressive rendering with ``plan`` at ``width``×``height`` (module docstring)."""

    def __init__(self, usd_path, plan, *, width: int, height: int, render_seed: int = 0, name: str = ""):

        self.usd_path = Path(usd_path)
        self.name = name or self.usd_path.parent.name
        self.plan = plan
        self.width, self.height = int(width), int(height)
        self.render_seed = int(render_seed)
        self.translated, loaded = load_scene_file(self.usd_path)  # scene.usda (USD) or scene.xml (Mitsuba XML)
        self._scene = loaded if loaded is not None else build_mitsuba_scene(self.translated)
        self._frame_scene: tuple = (0, self._scene)

    @classmethod
    def from_dataset(cls, dataset, scene: str) -> LiveScene:
        """Scene ``scene`` of ``dataset`` (a :class:`~denoisebench.dataset.reader.Dataset` or its folder) as it was rendered."""
        if not hasattr(dataset, "manifest"):
            dataset = open_dataset(dataset)
        record = dataset.scene(scene, renders=False).record
        try:
            plan = RenderPlan.from_dict(record["plan"])
            usd = dataset.path(record["usd"], "stage path")
            size = int(record["width"]), int(record["height"])
            seed = int(record["render_seed"])
        except (KeyError, TypeError, ValueError) as error:
            raise UserInputError(f"{dataset.root}: scene {scene!r} has no usable stage/plan record ({error})") from None
        return cls(usd, plan, width=size[0], height=size[1], render_seed=seed, name=scene)

    @property
    def frames(self) -> int:
        return int(self.translated.camera.frames)

    def _scene_at(self, frame: int):
        if not self.translated.moving:
            return self._scene

        if self._frame_scene[0] != frame:
            self._frame_scene = (frame, build_mitsuba_scene(self.translated, frame=frame))
        return self._frame_scene[1]

    def open(self, frame: int, *, seed: int | None = None, repeat: int = 0, keep_samples: bool = False):
        """A fresh ProgressiveFrame of ``frame`` (seed: :func:`live_seed` of the render seed unless given)."""
        if not 0 <= frame < self.frames:
            raise UserInputError(f"scene {self.name!r} has {self.frames} frame(s), not frame {frame}")
        return ProgressiveFrame(
            self._scene_at(frame),
            self.translated.camera,
            frame,
            self.plan,
            width=self.width,
            height=self.height,
            seed=live_seed(self.render_seed, repeat) if seed is None else int(seed),
            keep_samples=keep_samples,
        )


def run_live(sampler, scene: LiveScene, frame: int, budget, *, repeat: int = 0, keep_samples: bool = False):
    """``run_sampler`` on a fresh progressive frame of ``scene`` (common random numbers; module Notes)."""
    return run_sampler(sampler, scene.open(frame, repeat=repeat, keep_samples=keep_samples), budget)
