"""Defects found and not yet fixed, pinned as expected failures (reported XPASS once fixed).

Not strict: an alignment-dependent rounding shows or hides with where the allocator's arrays
happen to sit, which the tests before it in one process change.  Each names the hostile-suite
seed that found it.
"""

from __future__ import annotations

import copy

import numpy as np
import pytest

import alloc


@pytest.mark.xfail(strict=False, reason="answers depend on array alignment: the facet methods' numpy paths "
                                       "(flat sets, rate-limited calls: `@` through OpenBLAS) round "
                                       "differently when a copy's arrays sit at another offset; hostile seed "
                                       "30000408")
def test_da_table_deepcopy_answers_bit_for_bit_on_a_flat_set():
    B = [[-2.005300279472917, -1.2441694943889845, 1.752706010801285],
         [-2.5568999761759126, -1.9995305738226383, 2.2351792790739173],
         [-1.980911506057848, -1.3408990484891268, 1.731485422915185],
         [1.2842195245986237, 1.6150645662880676, -1.1231579256306097]]  # k = 4 > m = 3: a flat AMS
    umin = [-1.3562687775164036e48, -1.2103896882114235e47, -1.1041135561204125e47]
    umax = [1.493372969772889e48, 6.9068285472364255e47, 4.960878082633313e47]
    v = np.array([-3.252012546471413e48, -4.198935484037509e48, -3.226646326946874e48, 2.186397103164009e48])
    original = alloc.make_allocator(alloc.Problem(B, umin, umax), "da_table")
    twin = copy.deepcopy(original)
    assert original(v).u.tobytes() == twin(v).u.tobytes()
