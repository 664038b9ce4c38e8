"""The active-set solver's packed state: which row of which stacked array holds what
(:func:`alloc._engine._active_set.pack` builds it; the solver and its factorisation cache,
:mod:`alloc._engine._lsq_factor`, index it), and the cache's budget."""

# --- packed solver: a few stacked arrays per allocator ---------------------------------
#
# numba unboxes every array argument on each call (~0.05 us each), every np.empty in a call
# is an allocation, and every reshape of a flat buffer costs a helper call; the solver's
# data and state are therefore five stacked arrays built once (:func:`pack`), each piece a
# plain index into them (no views on the hot path: a view costs two atomic reference
# counts): ``mats`` (matrices, top-left corners of one (R, C) stack), ``vecs`` (vectors
# and work rows), ``ivecs`` (header, index data, working sets, then from row ``_TABLE`` the
# cache's hash table: column 0 the slot, then the key words) and the factorisation cache
# ``bankL``, ``bank`` (slot 0 is scratch).
#
# The solver's inner functions (``_jacobi``, ``_factor``, ``_level``, ``_run``) allocate
# nothing, so they are compiled without numba's reference counting (``_nrt=False``): with
# it, every call of ``_level`` and every cache lookup took and dropped an atomic reference
# on each array argument, a quarter of the solver's time in a perf profile (NRT_incref /
# NRT_decref).  Without it: 11-22 % less per allocation on ICE and the hexacopter, answers
# bit for bit the same (benchmarks/bench_alloc.py; tests/alloc/test_fastcall.py).  The caller
# (``lexico_call``, ``lexico_batch_finished``) owns the arrays for the whole call.

#: int header fields (``ivecs[0]``); ``_WARM``: the single call keeps its working set (the
#: ``warm_start`` option), ``_WVALID``: a kept one is there (rows ``_UW``, ``_WSIDE`` of ``vecs``)
_N, _M, _K, _NLEV, _FINAL, _DIAG, _MAXIT, _WORDS, _DYN, _NCW, _NLW, _WARM, _WVALID = range(13)
#: ``mats`` rows
_A, _T, _WU, _B, _P0, _KV, _KU = range(7)
#: ``ivecs[_MISC]`` columns: the next free cache slot, factorisations computed
_NEXT_SLOT, _FACTORED = range(2)
#: ``vecs`` rows
(_UP, _UMIN, _UMAX, _RMIN, _RMAX, _GAM, _U, _LO, _HI, _UPC, _BV, _R, _E, _LAM,
 _G, _H, _Y, _TMP, _SCALE, _CONST, _UW, _WSIDE) = range(22)
#: the factorisation cache's overflow: bank slots ``0 .. OVERFLOW_SLOTS - 1``, direct-mapped by
#: the free set's hash, hold what the hash table has no room left for, so the free sets of the
#: last few calls stay cached once it is full (a long smooth flight at m = 192 met more free
#: sets than the table keeps, and then refactorised each call's sets twice: level 0 and the
#: final level share one); the table's slots follow
OVERFLOW_SLOTS = 8
#: ``ivecs`` rows; from ``_OVER``, one row per overflow slot (column 0: 1 when it holds a key,
#: then the key's words), then the hash table from ``_TABLE``
_HEAD, _PERM, _STARTS, _FREE, _PINNED, _TABU, _FIDX, _KEY, _MISC, _OVER = range(10)
_TABLE = _OVER + OVERFLOW_SLOTS
#: cache budget per allocator, floats (2 MiB), and entry cap (free sets beyond are computed, not
#: kept); sized so an allocator stays small enough for the service to cache (a 32 MiB budget made
#: every inline qp request rebuild a 14 MiB allocator: 4 ms a build, 300 req/s overloaded it)
#: A slot holds only the blocks its levels use (:func:`_slot`): 69 floats on ICE, 140 on the 6 x 12
#: hexacopter (372 when every slot had five square blocks).  A long-lived ICE allocator meets
#: about 700 free sets, the hexacopter about 2,000 in 10,000 random demands and 2,950 in 100,000:
#: it keeps 1,871 (it kept 703, and recomputed almost every second call's factorisation).
CACHE_FLOATS = 1 << 18
CACHE_ENTRIES = 1 << 11
