"""Imported once by the forkserver a LocalCluster's workers are forked from (never by
lowerbase itself): it runs :func:`lowerbase.campaign.execute.warm` there, so each worker
starts with the runners imported and the numba kernels loaded instead of loading them itself
(~2.5 s of CPU a worker). See ``engine.FORKSERVER_PRELOAD``."""

from __future__ import annotations

import contextlib

from lowerbase.campaign.execute import warm

# a warm-up that raises here is not lost: the workers' WarmPlugin runs it again, and raises
# where Dask reports it (a forkserver that raised on import would take every worker with it)
with contextlib.suppress(Exception):
    warm()
