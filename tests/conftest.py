"""Test tree root.

The tests mirror the packages (``tests/alloc``, ``tests/alloc/ams``, ``tests/sim``,
``tests/service``, ``tests/benchmarks``); project-wide checks (layering, README, docs) stay
here.  Shared helpers (``hostile``, ``service_backends``, ``vehicle_documents``) live in this
directory, which pytest puts on ``sys.path`` because this conftest sits in it (rootdir-style
imports, no ``__init__.py`` anywhere under ``tests``).
"""
