"""Learned reference denoisers (torch; CPU or CUDA for training): DPCN and KPCN after Bako et al.
2017, the recurrent denoising autoencoder after Chaitanya et al. 2017, the MLP-driven
cross-bilateral filter (LBF) after Kalantari et al. 2015; their training, checkpoints and shipped weights.

Modules: :mod:`.features` (buffers → network inputs: exposure, firefly clamp, demodulation, log,
gradients, variances), :mod:`.pcn`, :mod:`.rae`, :mod:`.lbf`, :mod:`.losses`, :mod:`.catalog` (models by name
and configuration), :mod:`.checkpoint` (safe load), :mod:`.training` (``denoisebench train``),
:mod:`.card` (model cards), :mod:`.denoisers` (built-ins ``dpcn``, ``kpcn``, ``rae``, ``lbf``) and
``weights/`` (the small configurations' weights with a model card each). Importing this package
does not import torch.
"""
