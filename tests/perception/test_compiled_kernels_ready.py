"""prepare_compiled_kernels: what it says on stderr is what it compiled in that call."""

from __future__ import annotations

import io

from pedsafe_sumo.compiled_kernels import prepare_compiled_kernels
from pedsafe_sumo.perception.raycast_kernels import _nmax


def test_a_kernel_compiled_earlier_in_the_process_is_not_announced_as_compiled_now():
    prepare_compiled_kernels(io.StringIO())  # the cache filled (the suite's conftest does it too)
    # A compilation earlier in this process, for argument types of its own (a unit test of one kernel
    # does that): numba counts it as a cache miss of that kernel.
    earlier = ("float32", "float32")
    _nmax.stats.cache_misses[earlier] += 1
    try:
        stream = io.StringIO()
        assert prepare_compiled_kernels(stream) is None  # nothing compiled by this call
        assert stream.getvalue() == ""
    finally:
        _nmax.stats.cache_misses[earlier] -= 1
