"""Physics core: batched numerics compiled with numba (see the modules' docstrings)."""

from wsp_env.physics.jit_cache import refresh as _refresh_kernel_cache

_refresh_kernel_cache()
