"""Build of the one C extension, ``alloc._fastcall`` (the allocator's call path; see
alloc/_fastcall.c).  Everything else is in pyproject.toml.  The extension is optional: where
it cannot be built, ``alloc`` runs the same call path in Python (``alloc.api.FAST_CALL``)."""

from setuptools import Extension, setup

try:
    import numpy
except ImportError:  # pragma: no cover - numpy is a build requirement
    ext_modules = []
else:
    ext_modules = [Extension("alloc._fastcall", ["alloc/_fastcall.c"], include_dirs=[numpy.get_include()],
                             extra_compile_args=["-O2"], optional=True)]

setup(ext_modules=ext_modules)
