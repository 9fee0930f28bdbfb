"""The field's own scores, computed as their authors' code computes them: Noisebase's (``noisebase``),
OIDN's comparison (``oidn_compare``), ColorVideoVDP (``colorvideovdp``) and MS-SSIM (``msssim``).

They register under their own names in :mod:`denoisebench.metrics.registry` (opt-in sets such as
``noisebase``); this package re-exports nothing.
"""
