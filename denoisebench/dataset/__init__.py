"""Dataset I/O: Frame/Sequence types, EXR + manifest read/write, torch datasets (loaded lazily).

Torch-free on import: ``CropDataset`` and ``SequenceCropDataset`` import torch only when asked for.
"""

from __future__ import annotations

from denoisebench.dataset.errors import DatasetError
from denoisebench.dataset.exr_io import read_exr, read_samples_exr, write_exr
from denoisebench.dataset.frame import Frame, Sequence
from denoisebench.dataset.manifest import assign_splits, config_hash, manifest_without_timings, reference_quality
from denoisebench.dataset.reader import Dataset, SceneInfo, open_dataset
from denoisebench.dataset.writer import DatasetWriter

# Lazy imports: the torch datasets (torch: 1 s) only when CropDataset or SequenceCropDataset is asked for.

__all__ = [
    "CropDataset",
    "Dataset",
    "DatasetError",
    "DatasetWriter",
    "Frame",
    "SceneInfo",
    "Sequence",
    "SequenceCropDataset",
    "assign_splits",
    "config_hash",
    "manifest_without_timings",
    "open_dataset",
    "read_exr",
    "read_samples_exr",
    "reference_quality",
    "write_exr",
]


def __getattr__(name: str):
    if name in ("CropDataset", "SequenceCropDataset"):
        from denoisebench.dataset import torch_dataset

        return getattr(torch_dataset, name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
