"""Where the heavy stages run: in this process, or on a Dask cluster (``--dask``).

``--dask local`` starts a ``LocalCluster`` sized to this machine (one single-threaded worker
process per core, the memory shared out among them); ``--dask tcp://HOST:8786`` connects to a
scheduler that is already running (``dask scheduler`` on one machine, ``dask worker
tcp://HOST:8786`` on each of the others). Without the flag a stage runs in-process. The
stages build task graphs over the field store and give the same results either way; Dask
retries a task whose worker died, and the stages write their outputs only once every task
has finished, so a lost worker never leaves a partial file.
"""

from __future__ import annotations

import contextlib
import os
import sys
import time
from collections.abc import Iterator, Sequence
from typing import Any

from core.errors import ClusterError, InputError
from core.memory_budget import available_memory, format_size
from core.progress import progress_bar

__all__ = [
    "ADDRESS_SCHEMES",
    "CONNECT_TIMEOUT_S",
    "check_dask_spec",
    "compute_each",
    "dask_client",
    "worker_memory",
]

#: Seconds to wait for an existing scheduler to answer before giving up.
CONNECT_TIMEOUT_S = 10.0

#: Schemes of a scheduler address that another process can reach: Dask's network transports.
#: (``inproc://`` lives inside one process, ``ucx://`` needs a library this project lacks.)
ADDRESS_SCHEMES = ("tcp", "tls", "ws", "wss")

#: What ``--dask`` accepts, as every refusal says it.
ACCEPTED = (
    "give 'local' (a cluster on this machine) or a scheduler's address SCHEME://HOST:PORT "
    f"with SCHEME one of {', '.join(ADDRESS_SCHEMES)} (e.g. tcp://host:8786)"
)


def check_dask_spec(spec: str) -> str:
    """``spec`` when it is ``local`` or a scheduler address Dask can dial; refused otherwise.

    Checked before any work (the command line checks it as it is parsed): distributed's own
    answer to ``bogus://x`` or ``tcp://host`` is a ValueError from deep in its registry.

    Parameters
    ----------
    spec : str, ``local`` or ``SCHEME://HOST:PORT`` (:data:`ADDRESS_SCHEMES`; an IPv6 host in
        brackets, ``tcp://[::1]:8786``)

    Returns
    -------
    str
        ``spec`` unchanged.

    Raises
    ------
    InputError
        Anything else, naming the value and the accepted forms.
    """
    if spec == "local":
        return spec
    scheme, separator, location = spec.partition("://")
    if not separator:
        raise InputError(f"--dask {spec!r}: {ACCEPTED}")
    if scheme not in ADDRESS_SCHEMES:
        raise InputError(f"--dask {spec!r}: unknown scheme {scheme + '://'!r}; {ACCEPTED}")
    host, colon, port = location.rpartition(":")
    bracketed = host.startswith("[") and host.endswith("]")
    if not colon or not host or not port.isdigit() or not 1 <= int(port) <= 65535:
        raise InputError(f"--dask {spec!r}: no port 1..65535 after the host; {ACCEPTED}")
    if any(c.isspace() or c in "/?#@" for c in host) or (":" in host and not bracketed):
        raise InputError(f"--dask {spec!r}: {host!r} is not a host name or address; {ACCEPTED}")
    return spec


@contextlib.contextmanager
def dask_client(
    spec: str | None,
    *,
    workers: int | None = None,
    memory_limit: int | None = None,
    dashboard: bool = True,
) -> Iterator[Any]:
    """A ``distributed.Client`` for ``spec``, or None to run in-process; closed on exit.

    Parameters
    ----------
    spec : None, ``"local"`` or a scheduler address (``tcp://host:port``; see
        :func:`check_dask_spec`)
    workers : int, optional; worker processes of a local cluster (default: the cores)
    memory_limit : int, optional; bytes per local worker (default: the available memory
        shared among them); Dask pauses, then restarts, a worker that goes over it
    dashboard : bool, serve a local cluster's dashboard (its address is printed)

    Raises
    ------
    InputError
        ``spec`` is neither ``local`` nor an address (:func:`check_dask_spec`).
    ClusterError
        The scheduler at the address did not answer, or its transport could not be set up.
    """
    if spec is None:
        yield None
        return
    from distributed import Client, LocalCluster

    if spec == "local":
        count = workers or os.cpu_count() or 1
        limit = memory_limit or max(available_memory() // count, 256 << 20)
        with (
            LocalCluster(
                n_workers=count,
                threads_per_worker=1,
                processes=True,
                memory_limit=limit,
                # A free port either way: the scheduler's HTTP server (health, metrics) starts
                # even without the dashboard, and 8787 may be another cluster's.
                dashboard_address=":0",
                scheduler_kwargs={"dashboard": dashboard},
                silence_logs=40,
            ) as cluster,
            Client(cluster) as client,
        ):
            workers_text = f"{count} worker{'s' if count != 1 else ''}"
            _announce(client, f"a local Dask cluster of {workers_text}, "
                      f"{format_size(limit)} each", dashboard)  # fmt: skip
            yield client
        return
    check_dask_spec(spec)
    try:
        client = Client(spec, timeout=CONNECT_TIMEOUT_S)
    except (OSError, TimeoutError) as error:
        raise ClusterError(
            f"the Dask scheduler at {spec} did not answer within {CONNECT_TIMEOUT_S:.0f} s "
            f"({error}); start it (dask scheduler, then dask worker {spec} on each machine) or "
            "use --dask local"
        ) from error
    except (TypeError, ValueError) as error:
        # What the address's transport wants and lacks: tls:// without Dask's TLS settings
        # (distributed.comm.tls.*) is a TypeError about an ssl_context.
        raise ClusterError(
            f"cannot connect to the Dask scheduler at {spec}: {error}; for tls:// set Dask's "
            "TLS configuration (distributed.comm.tls), or use tcp:// or --dask local"
        ) from error
    with client:
        workers_seen = len(client.scheduler_info().get("workers", {}))
        _announce(client, f"the Dask scheduler at {spec} ({workers_seen} workers)", dashboard)
        yield client


def _announce(client: Any, what: str, dashboard: bool) -> None:
    link = getattr(client, "dashboard_link", None) if dashboard else None
    where = f"; dashboard {link}" if link else ""
    print(f"running on {what}{where}", file=sys.stderr)


def compute_each(
    client: Any, tasks: Sequence[Any], *, what: str = "tasks"
) -> Iterator[tuple[int, Any]]:
    """Compute Dask delayed ``tasks`` on ``client``; yield (index, value) as each finishes.

    The caller keeps each value as it comes and drops it, so the client never holds every
    task's result at once (a fit's blocks, a build's cameras). A progress bar counts the
    finished tasks; a task's error is raised here, the others are cancelled. Make the tasks
    with ``delayed(..., pure=False)`` (and scatter with ``hash=False``): keys of their own, so
    a computation repeated right after another never meets keys the scheduler is still
    releasing (it would cancel the task for "lost dependencies").
    """
    from distributed import as_completed

    futures = client.compute(list(tasks))
    index = {id(future): i for i, future in enumerate(futures)}
    bar = progress_bar(total=len(futures), desc=what, unit="task")
    try:
        for future in as_completed(futures):
            value = future.result()
            bar.update()
            yield index[id(future)], value
            future.release()
    except BaseException:
        client.cancel(futures)
        # A cancelled task that already runs goes on to its end (Dask cannot interrupt it):
        # wait for it, so the caller's clean-up (removing a partial store) comes after its
        # last write, not before.
        _wait_for_running(client, {future.key for future in futures})
        raise
    finally:
        bar.close()


#: Seconds to wait, after a failure, for cancelled tasks still running to end.
SETTLE_TIMEOUT_S = 600.0


def _running_keys(dask_worker: Any) -> list[Any]:
    """The keys of the tasks a worker is running (called on each worker by ``client.run``)."""
    # all_running_tasks: executing ones, cancelled ones included (they hold a thread).
    return [task.key for task in dask_worker.state.all_running_tasks]


def _wait_for_running(client: Any, keys: set[Any]) -> None:
    deadline = time.monotonic() + SETTLE_TIMEOUT_S
    while time.monotonic() < deadline:
        try:
            running = client.run(_running_keys)
        except Exception:  # a worker lost, the cluster closing: nothing more to wait for
            return
        if not keys.intersection(key for found in running.values() for key in found):
            return
        time.sleep(0.1)


def worker_memory(client: Any) -> int | None:
    """The smallest memory limit (bytes) among the cluster's workers, None when none is set."""
    limits = [
        int(info.get("memory_limit") or 0)
        for info in client.scheduler_info().get("workers", {}).values()
    ]
    limits = [limit for limit in limits if limit > 0]
    return min(limits) if limits else None
