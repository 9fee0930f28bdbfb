"""Adaptive samplers: spend a frame's budget in rounds of per-pixel sample counts.

docs/architecture.md, "Sampler protocol", is the contract.

:mod:`.protocol` (the Sampler protocol and the budget), :mod:`.harness` (:func:`~.harness.run_sampler`, which
drives the rounds and enforces the budget), :mod:`.registry` (built-ins, entry points, ``module:attr``), the
built-ins :mod:`.uniform`, :mod:`.ci_stop`, :mod:`.dual_buffer`, :mod:`.hachisuka`, the synthetic frame of
known truth :mod:`.synthetic` and the convergence check :mod:`.checks`.
"""
