"""The results store: a run's records in SQLite (schema, migrations, typed rows), the only package that
speaks SQL, plus the names and value rules every reader of a run shares.

``store`` (ResultsStore), ``schema`` (its tables, versions and migrations), ``records`` (what the
runner writes, the typed rows read back, read by attribute), ``timings``
(the run's timing records), ``sampler_maps`` (live samplers' per-frame spp maps), ``crops`` (which
crops of a run's images are kept), ``names`` (labels and metric groups), ``finite`` (which values count).
Imports: ``dataset`` and ``metrics`` only; ``benchmark`` writes here, ``analysis`` and ``reports`` read.
"""
