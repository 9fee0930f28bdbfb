"""What a reference's own noise adds to a score: the closed-form floors of the MSE family
(``closed_form``: from the reference's per-pixel variance) and the floors measured from the
reference's two independent halves (``half_reference``) for the scores without a closed form.

:mod:`denoisebench.metrics` re-exports the public names (``Floor``, ``mse_floor``, ``relmse_floor``);
this package re-exports nothing.
"""
