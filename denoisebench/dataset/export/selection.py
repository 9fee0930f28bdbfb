"""``--scenes``: export some of a dataset's scenes (a view of the opened dataset, nothing copied)."""

from __future__ import annotations

import copy

from denoisebench.dataset.reader import Dataset
from denoisebench.errors import UserInputError


def select_scenes(dataset: Dataset, text: str | None) -> Dataset:
    """``dataset`` restricted to the comma-separated scene names in ``text`` (all when None or empty).

    Notes
    -----
    The view shares the dataset's files and frame index; only its manifest header lists fewer
    scenes, and each split keeps its selected scenes. An unknown name is a UserInputError.
    """
    names = [name.strip() for name in (text or "").split(",") if name.strip()]
    if not names:
        return dataset
    unknown = [name for name in names if name not in dataset.manifest["scenes"]]
    if unknown:
        raise UserInputError(
            f"--scenes: no scene {', '.join(unknown)} in {dataset.root} (scenes: {', '.join(dataset.scenes)})"
        )
    view = copy.copy(dataset)
    keep = set(names)
    manifest = dict(dataset.manifest)
    manifest["scenes"] = {name: record for name, record in dataset.manifest["scenes"].items() if name in keep}
    manifest["splits"] = {
        split: [s for s in scenes if s in keep] for split, scenes in dataset.manifest["splits"].items()
    }
    view.manifest = manifest
    return view
