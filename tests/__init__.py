"""The test suite mirrors the package: ``tests/<package>/test_<module or topic>.py`` tests ``denoisebench/<package>/``.

``tests/generator/render/`` tests ``denoisebench/generator/render/`` and so on; ``tests/test_architecture.py``
holds the rules over the whole package. Helpers shared by several test modules live in ``tests/support/``
(stages written by hand, hostile plugin parts, motion peers, paths), fixtures in ``tests/conftest.py``; a test
module never imports another test module. ``tests/data/`` holds the pinned inputs with their provenance.
"""
