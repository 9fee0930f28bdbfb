"""The training data of ``denoisebench train``: which buffers and sample counts the train split has,
its crop datasets, and the order of their batches.

Crops come from :class:`~denoisebench.dataset.torch_dataset.CropDataset` (DPCN, KPCN) or
:class:`~denoisebench.dataset.torch_dataset.SequenceCropDataset` (the recurrent autoencoder, K-frame
windows), read through a torch ``DataLoader`` as ``(epoch, index)`` items (:class:`EpochItems`).
Batch *b* of epoch *e* is a fixed slice of a permutation drawn from ``(seed, e)`` (:func:`batches`) and
each item's crop comes from the dataset's ``(seed, e, item)`` generator, so a resumed run continues
with the batches the uninterrupted one had (:func:`batch_plan`), on any device and worker count.

Pitfall: the ragged tail of an epoch is dropped, so every step sees a full batch (unless the dataset
is smaller than one).
"""

from __future__ import annotations

import torch

from denoisebench.dataset.reader import Dataset
from denoisebench.dataset.torch_dataset import CropDataset, SequenceCropDataset
from denoisebench.errors import UserInputError
from denoisebench.models.training_options import recipe_value


def available_buffers(ds: Dataset, scene: str, spp: int, wanted: tuple[str, ...], targets: tuple[str, ...]):
    frame = ds.frame(scene, spp, 0, reference=True, samples=False)
    buffers = tuple(name for name in wanted if name in frame.buffers)
    ref_layers = frame.meta.get("reference_buffers", {})
    have_targets = tuple(t for t in targets if t == "color" or t in ref_layers)
    return buffers, have_targets


def train_spp(ds: Dataset, scenes: list[str], spp: list[int] | None) -> list[int]:
    common = set.intersection(*(set(ds.scene(s).spp) for s in scenes))
    if spp is None:
        if not common:
            raise UserInputError("the train scenes share no noisy sample count")
        return sorted(common)
    missing = sorted(set(spp) - common)
    if missing:
        raise UserInputError(f"--spp {missing} not rendered for every train scene (have {sorted(common)})")
    return sorted(set(spp))


def batches(length: int, batch_size: int, seed: int, epoch: int) -> list[list[int]]:
    generator = torch.Generator().manual_seed(seed * 1_000_003 + epoch)
    order = torch.randperm(length, generator=generator).tolist()
    # Drop the ragged tail so every step sees a full batch (unless the dataset is smaller than one).
    count = max(1, length // batch_size)
    return [order[i * batch_size : (i + 1) * batch_size] for i in range(count)]


class EpochItems(torch.utils.data.Dataset):
    """A crop dataset addressed by ``(epoch, index)``: the epoch is set where the item is read
    (in a loader worker too), so crops do not depend on the worker count."""

    def __init__(self, base):
        self.base = base

    def __len__(self) -> int:
        return len(self.base)

    def __getitem__(self, key):
        epoch, index = key
        if self.base.epoch != epoch:
            self.base.set_epoch(epoch)
        return self.base[index]


def batch_plan(
    length: int, batch_size: int, seed: int, per_epoch: int, start: int, total: int
) -> list[list[tuple[int, int]]]:
    """Batches of ``(epoch, index)`` for steps ``start`` to ``total``: batch *b* of epoch *e* is
    :func:`batches`'s, so a resumed run continues with the batches the uninterrupted one had."""
    plan = []
    step = start
    while step < total:
        epoch, offset = divmod(step, per_epoch)
        for batch in batches(length, batch_size, seed, epoch)[offset:]:
            plan.append([(epoch, int(i)) for i in batch])
            step += 1
            if step >= total:
                break
    return plan


def make_dataset(spec, ds, scenes, spp, options, buffers, targets):
    smallest = min(min(ds.scene(s).height, ds.scene(s).width) for s in scenes)
    # "where the data allows": a recipe's 128 px crop shrinks to the smallest train scene
    crop = min(int(recipe_value(spec, options.config, "crop", options.crop, 32)), smallest)
    if spec.temporal:
        frames = min(options.sequence_length, min(ds.scene(s).frame_count for s in scenes))
        backward = bool(recipe_value(spec, options.config, "play_backward", options.play_backward, False))
        dataset = SequenceCropDataset(
            ds,
            scenes,
            spp,
            frames=frames,
            crop=crop,
            buffers=buffers,
            targets=targets,
            seed=options.seed,
            play_backward=backward,
        )
        return dataset, crop, frames
    return CropDataset(ds, scenes, spp, crop=crop, buffers=buffers, targets=targets, seed=options.seed), crop, 1


def to_device(batch: dict[str, torch.Tensor], device: torch.device) -> dict[str, torch.Tensor]:
    if device.type == "cpu":
        return batch
    return {name: value.to(device, non_blocking=True) for name, value in batch.items()}
