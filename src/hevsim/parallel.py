"""Former home of the parallel HEV; it lives in :mod:`hevsim.architectures.parallel` now.

Kept so that ``from hevsim.parallel import ParallelHEV, build_parallel_hev, ...`` still works.
"""

from hevsim.architectures.parallel import (
    ARCHITECTURE,
    ParallelHEV,
    ParallelHEVConfig,
    build_parallel_hev,
    load_parallel_config,
    parallel_from_dict,
)

__all__ = ["ARCHITECTURE", "ParallelHEV", "ParallelHEVConfig", "build_parallel_hev", "load_parallel_config",
           "parallel_from_dict"]  # fmt: skip
