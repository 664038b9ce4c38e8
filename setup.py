"""Build steps that pyproject.toml cannot declare: the one C extension, ``alloc._engine._fastcall`` (the
allocator's call path; see alloc/_engine/_fastcall.c), and the numba kernels compiled into the build tree.

The extension is optional: where it cannot be built, ``alloc`` runs the same call path in Python
(``alloc.api.has_c_call_path()``).  The kernels: after the build, :func:`alloc._engine._jit_warm.warm` runs on
the built tree, so a wheel (and ``pip install .``) carries every kernel compiled for the build
machine's CPU, numba and Python in the packages' ``__pycache__``; the first allocation after the
install loads them instead of compiling for about a minute.  ``ALLOC_BUILD_KERNELS=0`` skips it
(the kernels then compile on first use, with a message).  Editable installs do not run it
(``make install`` warms the clone).
"""

import os
import subprocess
import sys

from setuptools import Extension, setup
from setuptools.command.build import build

try:
    import numpy
except ImportError:  # pragma: no cover - numpy is a build requirement
    ext_modules = []
else:
    ext_modules = [Extension("alloc._engine._fastcall", ["alloc/_engine/_fastcall.c"], include_dirs=[numpy.get_include()],
                             extra_compile_args=["-O2"], optional=True)]


class BuildWithKernels(build):
    """``build``, then the numba kernels compiled into the build tree (see the module docstring)."""

    def run(self) -> None:
        super().run()
        if os.environ.get("ALLOC_BUILD_KERNELS", "1") == "0":
            return
        build_lib = os.path.abspath(self.build_lib)
        # the built tree first (not the source tree, not an installed copy of the package), then
        # what this process sees: pip's isolated build environment holds numba and scipy
        path = [build_lib, *(p for p in sys.path if p and os.path.abspath(p) != os.path.abspath("."))]
        env = {**os.environ, "PYTHONPATH": os.pathsep.join(path), "PYTHONNOUSERSITE": "1"}
        env.pop("NUMBA_CACHE_DIR", None)
        command = [sys.executable, "-m", "alloc._engine._jit_warm", "warm"]
        print(f"compiling the numba kernels into {build_lib} (about a minute per method family)", flush=True)
        done = subprocess.run(command, cwd=build_lib, env=env)
        if done.returncode != 0:  # the package still works: the kernels compile on first use
            print(f"warning: {' '.join(command)} exited {done.returncode}; the kernels will compile on first use",
                  file=sys.stderr)


setup(ext_modules=ext_modules, cmdclass={"build": BuildWithKernels})
