"""Analysis of a run's typed rows, pure functions (no SQL, nothing run): per-scene values
(``run_index``), aggregation over scenes with intervals and reference-noise corrections
(``aggregate``), the summary and per-effect table (``summary``), accuracy against time and its
readings (``accuracy``), the time model (``time_model``), equal-time and equal-quality tables (``equal_tables``) and the ranking
across runs (``ranking``). Imports ``results`` (and ``metrics``, ``dataset`` for reference files);
``reports`` builds on it.
"""
