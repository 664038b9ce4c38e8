"""The engine under the public concepts: compiled kernels and the numerics they share.

Nothing here is public API; the modules of :mod:`alloc` and :mod:`alloc.methods` (and the C
export, which transcribes them) import them.  ``_active_set`` (with its packed-state layout and
the free sets' factorisation ``_lsq_factor``) solves ``qp``, ``wls`` and ``dynamic``; ``_kernels``
and ``_inverse_kernels`` hold the closed forms, the finish and the fast call paths; ``_simplex``
and ``_ray_simplex`` the LP and ``da``'s ray simplex; ``_linalg`` the guarded linear algebra;
``_threads`` the batch threads; ``_warm`` when a warm start may be used; ``_kernel_cache``,
``_jit_cache`` and ``_jit_warm`` where the compiled kernels are cached and how they are warmed;
``_fastcall.c`` the C entry of the one-call path.
"""
