"""Run a campaign's runs on Dask: a LocalCluster of processes on this machine (one per core,
on 127.0.0.1, no dashboard), or an existing scheduler by address. Rows stream back as runs
finish; Ctrl-C cancels what is left and keeps what finished. A worker that dies costs only
the runs it had: the scheduler gives them to another worker."""

from __future__ import annotations

import atexit
import contextlib
import logging
import os
import signal
import threading
import time
import uuid
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass, field
from typing import Any

from lowerbase.campaign.execute import run_one
from lowerbase.campaign.plan import RunSpec, plan_run
from lowerbase.campaign.progress import CampaignProgress
from lowerbase.campaign.spec import Campaign
from lowerbase.errors import CampaignError

#: retries of a run whose worker raised (a run's own exceptions are rows, not raised)
RETRIES = 2
#: the longest a Ctrl-C'd campaign waits for the scheduler to cancel what is left [s]
CANCEL_WAIT = 10.0
log = logging.getLogger(__name__)

#: a LocalCluster's Dask settings where a campaign needs less than Dask's defaults: with them
#: a worker's own event loop took ~9 % of its process' CPU beside the runs, without them ~3 %
#: (docs/campaigns.md). The statistical profiler samples every 10 ms for a dashboard that a
#: LocalCluster of ours does not serve; the event loop's health check runs every 20 ms, the
#: system and memory monitors every 0.5 s and 0.1 s.
LOCAL_CLUSTER_CONFIG: dict[str, Any] = {
    "distributed.worker.profile.enabled": False,
    "distributed.admin.tick.interval": "1s",
    "distributed.admin.system-monitor.interval": "2s",
    "distributed.worker.memory.monitor-interval": "1s",
}
#: where the system has a forkserver (Linux, macOS), a LocalCluster's workers are forked from
#: one that imported these first: the warm-up's imports and kernel loads are done once for all
#: workers instead of once in each (docs/campaigns.md), and a worker is up in a fraction of the
#: time a fresh interpreter takes
FORKSERVER_PRELOAD = ("distributed", "lowerbase.campaign.prewarm")
_NOISY = ("distributed", "tornado", "bokeh")


@dataclass
class Outcome:
    """What came back: rows by run index, and whether Ctrl-C cut the campaign short."""

    rows: dict[int, dict[str, Any]] = field(default_factory=dict)
    interrupted: bool = False
    workers: int = 0


@contextlib.contextmanager
def quiet_dask(debug: bool = False) -> Iterator[None]:
    """Dask's own log lines (a worker lost, a nanny restarting it) only with ``debug``."""
    import distributed  # noqa: F401  (its loggers exist once it is imported)

    names = [n for n in list(logging.root.manager.loggerDict) if n.split(".")[0] in _NOISY]
    saved = {n: logging.getLogger(n).level for n in {*names, *_NOISY}}
    for n in saved:
        logging.getLogger(n).setLevel(logging.DEBUG if debug else logging.CRITICAL)
    try:
        yield
    finally:
        for n, level in saved.items():
            logging.getLogger(n).setLevel(level)


@contextlib.contextmanager
def _children_ignore_sigint() -> Iterator[None]:
    """Worker processes started meanwhile ignore SIGINT: Ctrl-C reaches the whole process
    group, and the campaign (this process) is what stops them, quietly."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    saved = signal.signal(signal.SIGINT, signal.SIG_IGN)
    try:
        yield
    finally:
        signal.signal(signal.SIGINT, saved)


@contextlib.contextmanager
def open_client(scheduler: str | None = None, workers: int | None = None, *,
                warm: bool = False, meanwhile: Callable[[], None] | None = None
                ) -> Iterator[Any]:
    """A Dask client: of ``scheduler`` (``tcp://HOST:8786``), or of a LocalCluster with
    ``workers`` single-threaded processes (default: one per core) listening on 127.0.0.1.
    ``warm``: a LocalCluster's workers are warmed as they start (their plugin, before they
    take runs), a scheduler's by :func:`warm_workers`. ``meanwhile`` runs in this thread while
    the LocalCluster starts and warms in another (the campaign is planned then)."""
    method = start_forkserver() if scheduler is None else {}
    try:
        from distributed import Client, LocalCluster
    except ImportError as e:  # pragma: no cover - a dependency
        raise CampaignError(f"campaigns need Dask: pip install 'dask[distributed]' ({e})"
                            ) from None
    if scheduler is not None:
        _check_scheduler(scheduler)
        try:
            client = Client(scheduler, timeout=10)
        except OSError as e:
            raise CampaignError(f"--scheduler {scheduler}: cannot connect ({e}); start one "
                                "with `dask scheduler` and workers with `dask worker "
                                f"{scheduler}`") from None
        try:
            if meanwhile is not None:
                meanwhile()
            if warm:
                warm_workers(client)
            yield client
        finally:
            client.close()
        return
    n = workers or os.cpu_count() or 1
    started: list[Any] = []

    def start() -> None:
        import dask

        from lowerbase.campaign.warmup import WarmPlugin

        # the nannies take the settings along to the workers they start (and restart)
        with dask.config.set(LOCAL_CLUSTER_CONFIG), dask.config.set(method):
            started.append(LocalCluster(
                n_workers=n, threads_per_worker=1, processes=True, host="127.0.0.1",
                dashboard_address=None, silence_logs=logging.CRITICAL,
                # the scheduler's HTTP routes (health, metrics; no dashboard) on a free
                # loopback port: on Dask's 8787 a second campaign beside the first warned
                scheduler_kwargs={"dashboard_address": "127.0.0.1:0"},
                plugins={WarmPlugin()} if warm else set()))

    with _children_ignore_sigint():  # (SIGINT waits meanwhile: Ctrl-C after the start)
        if meanwhile is None:
            start()
        else:
            box: list[BaseException] = []

            def guarded() -> None:
                try:
                    start()
                except BaseException as e:
                    box.append(e)

            starter = threading.Thread(target=guarded, name="lowerbase-cluster-start")
            starter.start()
            try:
                meanwhile()
            finally:
                starter.join()
                if box and started:  # pragma: no cover - the start raised after starting
                    started[0].close()
            if box:
                raise box[0]
    cluster = started[0]
    try:
        with Client(cluster) as client:
            yield client
    finally:
        cluster.close()


def _check_scheduler(address: str) -> None:
    """One line at once for an address Dask cannot take, or a TCP port nobody listens on
    (Dask's Client would retry it for its whole timeout)."""
    import socket

    from distributed.comm.addressing import get_address_host_port, parse_address

    hint = "give the scheduler's address, e.g. tcp://127.0.0.1:8786"
    try:
        scheme, _ = parse_address(address, strict=True)
        host, port = get_address_host_port(address)
        if scheme in ("tcp", "tls") and not 0 < port < 65536:
            raise ValueError(f"port {port} is out of range")
    except (ValueError, TypeError) as e:
        raise CampaignError(f"--scheduler {address}: {e}; {hint}") from None
    if scheme != "tcp":
        return
    try:
        socket.create_connection((host, port), timeout=2).close()
    except ConnectionRefusedError:
        raise CampaignError(f"--scheduler {address}: nothing listens there (connection "
                            "refused); start one with `dask scheduler` and workers with "
                            f"`dask worker {address}`") from None
    except socket.gaierror as e:
        raise CampaignError(f"--scheduler {address}: unknown host {host!r} ({e.strerror}); "
                            f"{hint}") from None
    except OSError:
        pass  # unreachable or slow to answer: the Client's own timeout says so


def start_forkserver() -> dict[str, str]:
    """Start the forkserver a LocalCluster's workers are forked from, preloading
    :data:`FORKSERVER_PRELOAD`, and return Dask's setting that makes the nannies use it (else,
    where there is none, ``{}``: Dask's default, spawn). :func:`open_client` calls it; call it
    first, before this process imports Dask, and the warm-up runs beside that. It is started once
    per process and kept (already running, it keeps what it preloaded: the workers then warm
    by their plugin); it ignores SIGINT, as do the workers it forks."""
    import multiprocessing
    import multiprocessing.forkserver

    if "forkserver" not in multiprocessing.get_all_start_methods():  # pragma: no cover
        return {}
    # (Dask sets a preload list of its own on its first use: the server is running by then)
    multiprocessing.get_context("forkserver").set_forkserver_preload(list(FORKSERVER_PRELOAD))
    with _children_ignore_sigint():
        multiprocessing.forkserver.ensure_running()
    atexit.unregister(stop_forkserver)  # once, however often it is started
    atexit.register(stop_forkserver)
    return {"distributed.worker.multiprocessing-method": "forkserver"}


def stop_forkserver(timeout: float = 20.0) -> None:
    """Stop this process' forkserver and wait until it has gone (run at exit once
    :func:`start_forkserver` ran). Left alone, it goes only once it notices its parent has,
    which on a busy host is seconds later: until then it holds this process' stdout and
    stderr open, and a pipe reading them (``| tee``, a test) does not end with the CLI. One
    that has not gone after ``timeout`` [s] (stuck in a preload) is killed."""
    import multiprocessing.forkserver

    server = getattr(multiprocessing.forkserver, "_forkserver", None)
    stop = getattr(server, "_stop", None)  # CPython's own (3.7-3.13), for its tests
    pid = getattr(server, "_forkserver_pid", None)
    if stop is None or pid is None:
        return

    def run() -> None:
        with contextlib.suppress(OSError):  # already gone (reaped, its socket file removed)
            stop()

    waiter = threading.Thread(target=run, name="forkserver-stop", daemon=True)
    waiter.start()
    waiter.join(timeout)
    if waiter.is_alive():
        log.warning("the campaign's forkserver (pid %d) did not stop in %g s; killed",
                    pid, timeout)
        with contextlib.suppress(OSError):
            os.kill(pid, signal.SIGKILL)
        waiter.join(timeout)


def warm_workers(client: Any) -> None:
    """Warm every worker of ``client`` now, and each that joins later (a restarted one),
    before its runs: :class:`lowerbase.campaign.warmup.WarmPlugin`."""
    from lowerbase.campaign.warmup import WarmPlugin

    client.register_plugin(WarmPlugin(), name=WarmPlugin.name)


def _cancels(client: Any) -> int:
    """How many cancels the scheduler has acted on for ``client`` (its event log)."""
    return sum(1 for _, event in client.get_events(client.id)
               if isinstance(event, dict) and event.get("action") == "cancel")


def cancel_and_wait(client: Any, futures: Sequence[Any], timeout: float = CANCEL_WAIT
                    ) -> bool:
    """Cancel ``futures`` and wait until the scheduler has acted on it (its events for this
    client show the cancel), at most ``timeout`` [s]; False (and a warning) if it had not.
    Dask sends a cancel down the client's stream with no answer: a client closed at once
    after it (a Ctrl-C's campaign) left the scheduler to report the cancelled runs to a closed
    connection, and a LocalCluster's scheduler, in this process, printed a traceback for it.
    A second Ctrl-C ends the wait."""
    if not futures:
        return True
    try:
        before = _cancels(client)
        client.cancel(list(futures))
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            if _cancels(client) > before:
                return True
            time.sleep(0.02)
    except KeyboardInterrupt:
        return False
    except Exception as e:  # the scheduler gone: nothing is left to report to
        log.debug("cancel: %s", e)
        return False
    log.warning("the scheduler had not cancelled the %d unfinished run(s) after %g s; "
                "closing anyway", len(futures), timeout)
    return False


def plan_runs(campaign: Campaign, indices: Sequence[int] | None = None
              ) -> dict[int, RunSpec]:
    """The run specs of every run (or ``indices``), by index."""
    wanted = list(range(campaign.total)) if indices is None else list(indices)
    return {i: plan_run(campaign, i) for i in wanted}


def _failed_row(index: int, scenario: str, values: dict[str, Any], error: str
                ) -> dict[str, Any]:
    return {"run": index, "scenario": scenario, "passed": False, "error": error, **values}


def run_campaign(campaign: Campaign, client: Any, *,
                 indices: Sequence[int] | None = None,
                 on_row: Callable[[dict[str, Any]], None] | None = None,
                 progress: CampaignProgress | None = None, warm: bool = True,
                 specs: dict[int, RunSpec] | None = None) -> Outcome:
    """Submit every run (or ``indices``; or the planned ``specs``) to ``client``; call
    ``on_row`` with each row as it arrives. Ctrl-C cancels the runs not finished and returns
    what finished. ``warm``: warm the workers first (:func:`warm_workers`; not needed when
    :func:`open_client` warmed them)."""
    from distributed import as_completed

    if warm:
        warm_workers(client)
    token = uuid.uuid4().hex[:8]
    if specs is None:
        specs = plan_runs(campaign, indices)
    futures = {client.submit(run_one, spec, key=f"lowerbase-run-{i}-{token}", pure=False,
                             retries=RETRIES): i for i, spec in specs.items()}
    info = client.scheduler_info().get("workers", {})
    out = Outcome(workers=len(info))
    w_threads = {w: int(i.get("nthreads", 1)) for w, i in info.items()}
    passed = failed = 0
    seen = [-1.0, 0.0]  # when the scheduler was last asked, what it said

    def running() -> int:
        now = time.monotonic()
        if now - seen[0] >= 0.25:  # at most 4 questions a second
            seen[0] = now
            # the scheduler busy or gone: the line shows the last count
            with contextlib.suppress(Exception):
                # a worker holds a few runs ahead; only its threads' worth are running
                seen[1] = sum(min(len(keys), w_threads.get(w, 1))
                              for w, keys in client.processing().items())
        return int(seen[1])

    try:
        for future in as_completed(list(futures)):
            i = futures[future]
            if future.status == "finished":
                row = future.result()
            else:  # exhausted its retries, or its workers kept dying (KilledWorker)
                exc = future.exception()
                row = _failed_row(i, specs[i].scenario, specs[i].values,
                                  f"{type(exc).__name__}: {exc}".splitlines()[0][:300])
            out.rows[i] = row
            passed, failed = passed + bool(row["passed"]), failed + (not row["passed"])
            if on_row is not None:
                on_row(row)
            if progress is not None:
                progress.update(done=passed, failed=failed,
                                running=running() if len(out.rows) < len(futures) else 0)
    except KeyboardInterrupt:
        out.interrupted = True
        cancel_and_wait(client, [f for f, i in futures.items() if i not in out.rows])
    finally:
        if progress is not None:
            progress.update(done=passed, failed=failed, running=0, force=True)
            progress.close()
    return out
