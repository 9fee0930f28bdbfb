"""denoisebench: paired noisy/reference data from procedural USD scenes, and a benchmark for denoisers."""

__version__ = "0.1.0"
