"""The series HEV's point kernels and constants under their former name (the series HEV's
own compiled loop ``run_series`` / ``run_series_batch`` lived here until issue 24 item 2).

Every name now lives in :mod:`hevsim.architectures.series_kernel` (the architectures layer,
below :mod:`hevsim.sim`) and is re-exported here, so ``from hevsim.sim import kernel as K;
K.SUMMARY`` keeps working; the series HEV's forward run is the one compiled loop
:func:`hevsim.sim._loop.run_loop` with its plug-in :mod:`hevsim.sim._compiled_series`.
"""

from __future__ import annotations

from hevsim.architectures.series_kernel import *  # noqa: F403  (the former contents, by name)
