"""Our own scores: spatial (``spatial``: relMSE, MSE, SMAPE, L1, PSNR, SSIM, FLIP, ΔE2000), gradient
(``gradient``: grad-L1, HFEN), temporal (``temporal``: flicker against the reference's change, warped
by motion) and the robust, outlier-bounded ones the report leads with (``robust``).

Import a score from :mod:`denoisebench.metrics` (the one place the public names are re-exported) or
from its module here; this package re-exports nothing.
"""
