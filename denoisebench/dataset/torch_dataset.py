"""torch ``Dataset``s of random crops (and K-frame crop sequences) for training.

The only module of ``denoisebench.dataset`` that imports torch; ``denoisebench.dataset`` loads it
lazily. Items are dicts of float32 tensors:

* :class:`CropDataset`: each buffer C×h×w, plus ``reference`` (3×h×w, the reference color) and
  ``reference_<name>`` for other reference layers asked for in ``targets`` (e.g. diffuse).
* :class:`SequenceCropDataset`: the same with a leading K: K×C×h×w, K consecutive frames with one
  crop window and one augmentation for the whole window.

Items enumerate (scene, spp, frame or window start, crop number) over the split's scenes, so
``len()`` is finite and a sampler can shuffle them. Crop positions and augmentations are drawn
from ``numpy.random.default_rng([seed, epoch, index])``: the same item gives the same crop within
an epoch, a new one after :meth:`set_epoch`. Augmentation (:mod:`.augment`) flips and rotates all
buffers consistently, motion vectors included. Frames are read with the dataset reader (only the
buffers needed, no per-sample data) and kept in a small per-worker LRU cache.
"""

from __future__ import annotations

from collections import OrderedDict
from collections.abc import Iterable

import numpy as np
import torch

from denoisebench.dataset.augment import IDENTITY, random_transform, transform_buffers
from denoisebench.dataset.errors import DatasetError
from denoisebench.dataset.reader import Dataset, open_dataset

DEFAULT_BUFFERS = ("color", "color_var", "albedo", "normal", "depth")


def _as_dataset(dataset) -> Dataset:
    return dataset if isinstance(dataset, Dataset) else open_dataset(dataset)


def _scene_list(ds: Dataset, split) -> list[str]:
    if isinstance(split, str):
        scenes = ds.split(split)
        if not scenes:
            raise DatasetError(f"{ds.root}: split {split!r} has no scenes")
        return scenes
    scenes = list(split)
    for name in scenes:
        ds.scene(name)  # raises on unknown names
    if not scenes:
        raise DatasetError("no scenes given")
    return scenes


class _CropBase(torch.utils.data.Dataset):
    def __init__(
        self,
        dataset,
        split,
        spp,
        crop: int | None,
        buffers: Iterable[str],
        targets: Iterable[str],
        augment: bool,
        seed: int,
        cache_size: int,
    ):
        self.dataset = _as_dataset(dataset)
        self.scenes = _scene_list(self.dataset, split)
        self.spp = [int(spp)] if isinstance(spp, (int, np.integer)) else [int(s) for s in spp]
        self.buffers = tuple(buffers)
        self.targets = tuple(targets)
        self.augment = bool(augment)
        self.seed = int(seed)
        self.epoch = 0
        self.crop = None if crop is None else int(crop)
        self._cache: OrderedDict = OrderedDict()
        self._cache_size = max(1, int(cache_size))
        if "color" not in self.buffers:
            self.buffers = ("color",) + self.buffers
        for name in self.scenes:
            info = self.dataset.scene(name, renders=False)  # the header record: no frame records loaded
            missing_spp = [s for s in self.spp if s not in info.spp]
            if missing_spp:
                raise DatasetError(f"scene {name!r} was rendered at spp {info.spp}, not {missing_spp}")
            if self.targets and not info.has_reference:
                raise DatasetError(f"scene {name!r} has no reference frames; training needs them")
            if self.crop is not None and (self.crop < 1 or self.crop > min(info.height, info.width)):
                raise DatasetError(f"crop {self.crop} does not fit scene {name!r} ({info.height}×{info.width})")

    def set_epoch(self, epoch: int) -> None:
        """Draw new crops and augmentations (call once per epoch)."""
        self.epoch = int(epoch)

    def _load(self, scene: str, spp: int, index: int) -> dict[str, np.ndarray]:
        key = (scene, spp, index)
        if key in self._cache:
            self._cache.move_to_end(key)
            return self._cache[key]
        frame = self.dataset.frame(scene, spp, index, reference=bool(self.targets), samples=False, buffers=self.buffers)
        arrays = {name: frame.buffers[name] for name in self.buffers}
        if self.targets:
            ref = frame.meta["reference_buffers"]
            for name in self.targets:
                if name not in ref:
                    raise DatasetError(
                        f"scene {scene!r} frame {index} reference file {frame.meta['reference_file']} has no {name!r} layer"
                    )
                arrays["reference" if name == "color" else f"reference_{name}"] = ref[name]
        self._cache[key] = arrays
        while len(self._cache) > self._cache_size:
            self._cache.popitem(last=False)
        return arrays

    def _window(self, rng: np.random.Generator, height: int, width: int) -> tuple[slice, slice]:
        if self.crop is None:
            return slice(0, height), slice(0, width)
        y0 = int(rng.integers(0, height - self.crop + 1))
        x0 = int(rng.integers(0, width - self.crop + 1))
        return slice(y0, y0 + self.crop), slice(x0, x0 + self.crop)

    def _rng(self, index: int) -> np.random.Generator:
        return np.random.default_rng([self.seed, self.epoch, int(index)])


def _chw(array: np.ndarray) -> torch.Tensor:
    """...×H×W×C numpy → ...×C×H×W float32 tensor (contiguous)."""
    moved = np.moveaxis(array, -1, -3)
    return torch.from_numpy(np.ascontiguousarray(moved, dtype=np.float32))


class CropDataset(_CropBase):
    """Random crops of single frames: ``{buffer: C×h×w, "reference": 3×h×w, ..., "spp": 1×1×1}``.

    ``spp`` is the crop's sample count, batched to N×1×1×1 as the models read it (KPCN's
    partly-covered rule needs it to read the variance buffers; models/features.py FRAME_SCALARS).

    ``dataset``: a :class:`~denoisebench.dataset.reader.Dataset` or its path; ``split``: a split name
    or a list of scene names; ``spp``: one sample count or several (each is its own item);
    ``crop``: side of the square crop (None: whole frames); ``buffers``: noisy buffers returned
    (``color`` always); ``targets``: reference layers (``"color"`` → ``reference``); ``augment``:
    random flips/rotations; ``crops_per_frame``: items per frame per epoch.
    """

    def __init__(
        self,
        dataset,
        split="train",
        spp=4,
        crop: int | None = 64,
        buffers: Iterable[str] = DEFAULT_BUFFERS,
        targets: Iterable[str] = ("color",),
        augment: bool = True,
        seed: int = 0,
        crops_per_frame: int = 1,
        cache_size: int = 8,
    ):
        super().__init__(dataset, split, spp, crop, buffers, targets, augment, seed, cache_size)
        self.items = [
            (scene, s, index, k)
            for scene in self.scenes
            for s in self.spp
            for index in range(self.dataset.scene(scene, renders=False).frame_count)
            for k in range(max(1, int(crops_per_frame)))
        ]

    def __len__(self) -> int:
        return len(self.items)

    def __getitem__(self, index: int) -> dict[str, torch.Tensor]:
        scene, spp, frame, _ = self.items[index]
        arrays = self._load(scene, spp, frame)
        rng = self._rng(index)
        rows, cols = self._window(rng, *arrays["color"].shape[:2])
        transform = random_transform(rng) if self.augment else IDENTITY
        cropped = transform_buffers({name: a[rows, cols] for name, a in arrays.items()}, transform)
        return {**{name: _chw(a) for name, a in cropped.items()}, "spp": torch.full((1, 1, 1), float(spp))}


class SequenceCropDataset(_CropBase):
    """Windows of ``frames`` (K) consecutive frames with one crop and one augmentation: K×C×h×w.

    ``play_backward``: each window is played in reverse with probability 1/2 (drawn from the
    item's generator), as Chaitanya et al. train. A reversed window's ``motion`` buffer still
    points to the frame *before* in render order, so it is not valid for reversed play (the
    recurrent autoencoder does not read it).

    Windows start every ``stride`` frames; a scene with fewer than K frames gives none (an error
    when no scene has enough). Other arguments as :class:`CropDataset`.
    """

    def __init__(
        self,
        dataset,
        split="train",
        spp=4,
        frames: int = 4,
        crop: int | None = 64,
        buffers: Iterable[str] = DEFAULT_BUFFERS + ("motion",),
        targets: Iterable[str] = ("color",),
        augment: bool = True,
        seed: int = 0,
        stride: int = 1,
        cache_size: int | None = None,
        play_backward: bool = False,
    ):
        self.frames = int(frames)
        self.play_backward = bool(play_backward)
        if self.frames < 1:
            raise ValueError(f"frames must be >= 1 (got {frames})")
        super().__init__(dataset, split, spp, crop, buffers, targets, augment, seed, cache_size or 2 * self.frames)
        stride = max(1, int(stride))
        self.items = [
            (scene, s, start)
            for scene in self.scenes
            for s in self.spp
            for start in range(0, self.dataset.scene(scene, renders=False).frame_count - self.frames + 1, stride)
        ]
        if not self.items:
            longest = max(self.dataset.scene(s, renders=False).frame_count for s in self.scenes)
            raise DatasetError(f"no scene has {self.frames} frames (the longest has {longest})")

    def __len__(self) -> int:
        return len(self.items)

    def __getitem__(self, index: int) -> dict[str, torch.Tensor]:
        scene, spp, start = self.items[index]
        window = [self._load(scene, spp, start + k) for k in range(self.frames)]
        rng = self._rng(index)
        rows, cols = self._window(rng, *window[0]["color"].shape[:2])
        transform = random_transform(rng) if self.augment else IDENTITY
        stacked = {name: np.stack([f[name][rows, cols] for f in window]) for name in window[0]}
        items = transform_buffers(stacked, transform)
        # drawn after the crop and augmentation, so forward-only runs keep their crops
        if self.play_backward and rng.random() < 0.5:
            items = {name: a[::-1] for name, a in items.items()}
        return {name: _chw(a) for name, a in items.items()}
