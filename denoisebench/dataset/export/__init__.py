"""Exports of a denoisebench dataset into the layouts other tools read.

* :mod:`.oidn`: Intel Open Image Denoise's training toolkit (``training/preprocess.py``,
  ``train.py``, ``infer.py`` in the OIDN repository): one single-layer EXR per feature.
* :mod:`.noisebase`: Noisebase's sample datasets (PyPI ``noisebase``): Zarr groups in zip stores,
  read by ``noisebase.loaders.torch.TrainingSampleLoader_v1`` / ``TestSampleLoader_v1``.

Both write the whole export into a hidden temporary folder beside ``OUT`` and rename it to ``OUT``
at the end (:mod:`.staging`), so an interrupted or refused export leaves nothing half-written.
"""
