"""Names every part of the benchmark side shares: the noisy input's label and the metric groups.

The runner stores rows under these names and the analyses and reports read them back by the same
names, so they live here, below all of them, rather than in any one of them.
"""

from __future__ import annotations

#: The label of the noisy input itself (the "just render more samples" point of a run).
NOISY = "noisy"

#: Metrics the report leads with; always computed (temporal ones on sequences of ≥ 2 frames).
REQUIRED_METRICS = ("relmse_robust", "relmse", "flip", "temporal_relmse_robust", "temporal_relmse", "tpsnr")

#: Per-frame flicker: these temporal metrics of frames (t−1, t), stored as frame metrics
#: ``flicker.<name>`` of frame t (scale-free ones: the flicker figure averages them over scenes).
#: Older runs stored temporal_l1 as ``flicker``.
FLICKER_METRICS = ("temporal_relmse_robust", "temporal_relmse", "tpsnr")
FLICKER_PREFIX = "flicker."

#: A score with a closed-form floor also has its floor measured from the reference's two halves
#: (metrics.half_reference), kept beside it as the frame "metric" ``floor_measured.<name>`` (its value
#: the measured floor, its ref_se the floor's se); for a per-pair flicker score the name is
#: ``floor_measured.flicker.<metric>``. These are no metrics: the analyses read them as floors.
MEASURED_FLOOR_PREFIX = "floor_measured."

#: The error metrics of the accuracy-against-time figure, in panel order (the first leads:
#: :mod:`denoisebench.metrics.ours.robust`).
ERROR_METRICS = ("relmse_robust", "relmse", "flip")

#: A sampler × denoiser pair is labelled ``SAMPLER+DENOISER`` (the sampler alone: ``SAMPLER``).
PAIR_LABEL_SEPARATOR = "+"
#: A pair's ``spec`` in the store: ``sampler SAMPLER_SPEC`` then, with a denoiser, `` + DENOISER_SPEC``.
SAMPLER_SPEC_PREFIX = "sampler "
PAIR_SPEC_SEPARATOR = " + "

#: Scores whose worst frame each unit keeps an image of (beside its last frame), so that a report can
#: show the frame that decides a lead score at every spp; the first one measured of each pair leads.
DECIDING_SCORES = (("relmse_robust", "relmse"), ("flip",))
