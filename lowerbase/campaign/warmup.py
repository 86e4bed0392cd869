"""The worker plugin that warms a Dask worker before its runs (a module of its own: Dask is
imported here, and a LocalCluster's worker processes unpickle the plugin from it)."""

from __future__ import annotations

from typing import Any

from distributed.diagnostics.plugin import WorkerPlugin

from lowerbase.campaign.execute import warm


class WarmPlugin(WorkerPlugin):
    """Its setup runs :func:`lowerbase.campaign.execute.warm`: given to a LocalCluster's
    workers it runs as each starts, before it registers (so before its first run, in the
    cluster's start); registered with a scheduler's workers, on each now and on each that
    joins later (a restarted one)."""

    name = "lowerbase-warm"
    idempotent = True

    def setup(self, worker: Any) -> None:
        warm()
