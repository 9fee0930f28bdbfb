"""The test suite mirrors the package: ``tests/<package>/test_<module or topic>.py`` tests ``denoisebench/<package>/``.

``tests/generator/render/`` tests ``denoisebench/generator/render/`` and so on; ``tests/test_architecture.py``
holds the rules over the whole package. Helpers shared by several test modules live in ``tests/support/``
(stages written by hand, hostile plugin parts, motion peers, paths), fixtures in ``tests/conftest.py``; a test
module never imports another test module. ``tests/data/`` holds the pinned inputs with their provenance.

``make test`` runs the suite in two pytest-xdist workers, each taking whole modules (``--dist loadfile``), so a
module's fixtures are built once, in one process. Pitfall: two modules may run at the same time in two
processes; a test that starts a shared service starts its own (Ray: ``ray.init(address="local", ...)``, not a
cluster another worker started), and a test writes only under its ``tmp_path``.
"""
