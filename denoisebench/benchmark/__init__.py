"""Running a benchmark: the plan of units (denoiser × scene × spp), measuring them locally or on Ray
(``runner``, ``run``, ``ray_executor``), live sampler pairs (``sampler_units``), timing at a larger
size (``timing``) and the hard-case stability table (``stability``). Writes to ``results``; never
imports ``analysis`` or ``reports``.
"""
