"""Where independent jobs run: in this process, in local worker processes, or on a Dask cluster.

``keyfill simulate`` (:mod:`keyfill.sim.runner`) and batch completion and
conversion (:mod:`keyfill.batch`) hand their jobs to one of three executors
with the same small interface:

* ``submit(fn, *args) -> future``: start ``fn(*args)`` (``fn`` must be a
  module-level function, so spawned processes and Dask workers can import it);
* ``wait(futures) -> set``: at least one finished future of ``futures``;
* ``close(cancel=False)``: stop; with ``cancel`` also the jobs in flight.

:func:`executor` picks one: a Dask cluster for ``scheduler``, spawned local
processes for ``workers > 1``, this process otherwise. Jobs must not depend on
where they run, so results are the same bytes on each.
"""

from __future__ import annotations

import concurrent.futures as cf
import multiprocessing
import os
import signal
import threading
import time

from keyfill.errors import UsageError
from keyfill.limits import CONNECT_SECONDS, MAX_CONNECT_SECONDS, MAX_WORKERS, check_count


def available_cpus() -> int:
    """CPU cores this process may use."""
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:  # not on Linux
        return os.cpu_count() or 1


#: input bytes of a batch for each local worker process started for it by default: a worker's start (Python,
#: numpy, keyfill and the method's model) costs about 0.4 s of CPU and cubic completion of BVH about 0.2 s per
#: MB, so a worker pays for itself from a few MB of work; below 8 MB each, the batch stays in this process
BYTES_PER_WORKER = 8 << 20


def default_workers(jobs: int, work_bytes: int) -> int:
    """The local worker processes of a batch given no ``--workers``: one per idle core (the cores this process
    may use less the 1-minute load average, rounded), at most one per job and one per
    :data:`BYTES_PER_WORKER` of ``work_bytes`` (the inputs' size); 1 (everything in this process) when more
    would not pay. On a busy machine, workers only compete with the work for the same cores."""
    cpus = available_cpus()
    try:
        idle = round(cpus - os.getloadavg()[0])
    except (AttributeError, OSError):  # no load average on this system
        idle = cpus
    return max(1, min(cpus, idle, jobs, work_bytes // BYTES_PER_WORKER))


def input_bytes(paths) -> int:
    """The total size in bytes of the files ``paths`` (a file that cannot be read counts 0: its job says why)."""
    total = 0
    for path in paths:
        try:
            total += os.stat(path).st_size
        except OSError:
            pass
    return total


class Inline:
    """Runs each job in this process when submitted (``workers=1``)."""

    threads = 1

    def submit(self, fn, *args):
        fut: cf.Future = cf.Future()
        try:
            fut.set_result(fn(*args))
        except BaseException as e:  # delivered through the future, like a pool would
            if isinstance(e, KeyboardInterrupt):
                raise
            fut.set_exception(e)
        return fut

    def wait(self, futures):
        return set(futures)

    def close(self, cancel: bool = False):
        pass


def _worker_init() -> None:
    """Worker processes leave Ctrl-C to the parent, which stops them, and end when the parent dies
    (killed outright, it cannot stop them)."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    parent = os.getppid()

    def watch():
        while os.getppid() == parent:
            time.sleep(0.5)
        os._exit(1)

    threading.Thread(target=watch, daemon=True).start()


class Processes:
    """Local worker processes (spawned, so they never inherit the parent's threads or state)."""

    def __init__(self, workers: int):
        self.threads = workers
        self.pool = cf.ProcessPoolExecutor(
            max_workers=workers, mp_context=multiprocessing.get_context("spawn"), initializer=_worker_init
        )

    def submit(self, fn, *args):
        return self.pool.submit(fn, *args)

    def wait(self, futures):
        return cf.wait(futures, return_when=cf.FIRST_COMPLETED).done

    def close(self, cancel: bool = False):
        if cancel:
            for proc in list(getattr(self.pool, "_processes", {}).values()):
                proc.terminate()
        self.pool.shutdown(wait=True, cancel_futures=cancel)


#: address schemes that name a host and a port, which :func:`probe_scheduler` can try before a client starts
_HOST_PORT_SCHEMES = ("tcp", "tls", "ws", "wss")


def probe_scheduler(address: str, timeout: float) -> None:
    """Refuse, as one :class:`UsageError` naming ``scheduler`` (exit 2), a scheduler address that is malformed or
    that nobody answers at within ``timeout`` seconds, before any Dask client exists (a client whose start fails
    leaves a background loop and a noisy ``Client.__del__`` behind)."""
    import asyncio

    from distributed.comm import connect
    from distributed.comm.addressing import parse_address, parse_host_port

    try:
        scheme, location = parse_address(address)
        if scheme in _HOST_PORT_SCHEMES:
            host, _port = parse_host_port(location)
            if not host:
                raise ValueError(f"no host in {address!r}")
    except (ValueError, TypeError) as e:
        raise UsageError(f"scheduler {address!r} is not a scheduler address like tcp://host:8786 ({e})",
                         params="scheduler") from None
    if scheme not in _HOST_PORT_SCHEMES:
        return  # inproc://, ucx://: the client reaches them itself

    async def reach():
        comm = await connect(address, timeout=timeout)
        await comm.close()

    try:
        asyncio.run(asyncio.wait_for(reach(), timeout + 1.0))
    except (OSError, TimeoutError) as e:
        reason = " ".join(str(e).split()) or type(e).__name__
        raise UsageError(f"cannot reach the scheduler {address} within connect_timeout {timeout:g} s ({reason})",
                         params=("scheduler", "connect_timeout")) from None
    except ValueError as e:
        raise UsageError(f"scheduler {address!r} is not a scheduler address like tcp://host:8786 ({e})",
                         params="scheduler") from None


class DaskCluster:
    """A Dask distributed cluster."""

    def __init__(self, address: str, timeout: float):
        import logging

        # A refused connection is reported by our own message, not by distributed's retry warnings.
        log = logging.getLogger("distributed")
        level = log.level
        log.setLevel(logging.CRITICAL)
        try:
            probe_scheduler(address, timeout)
            from distributed import Client

            self.client = Client(address, timeout=f"{timeout}s", set_as_default=False)
        except (OSError, TimeoutError) as e:
            raise UsageError(f"cannot reach the scheduler {address} within connect_timeout {timeout:g} s ({e})",
                             params=("scheduler", "connect_timeout")) from None
        except ValueError as e:
            raise UsageError(f"scheduler {address!r} is not a scheduler address like tcp://host:8786 ({e})",
                             params="scheduler") from None
        finally:
            log.setLevel(level)
        from distributed import as_completed

        self.finished = as_completed(loop=self.client.loop)

    @property
    def threads(self) -> int:
        return max(1, sum(self.client.nthreads().values()))

    def submit(self, fn, *args):
        fut = self.client.submit(fn, *args, pure=False)
        self.finished.add(fut)
        return fut

    def wait(self, futures):
        return {next(self.finished)}

    def close(self, cancel: bool = False):
        self.client.close()


def check_options(workers: int | None, connect_timeout: float = CONNECT_SECONDS) -> None:
    """:class:`UsageError` (naming the parameter) for ``workers`` or ``connect_timeout`` no executor can use."""
    if workers is not None:
        check_count("workers", workers, MAX_WORKERS)
    if not 0 < connect_timeout <= MAX_CONNECT_SECONDS:
        raise UsageError(f"connect_timeout must be positive and at most {MAX_CONNECT_SECONDS:,.0f} s, "
                         f"got {connect_timeout}", params="connect_timeout")


def executor(workers: int | None = None, scheduler: str | None = None, connect_timeout: float = CONNECT_SECONDS):
    """The executor for ``--workers`` / ``--scheduler``: ``(executor, jobs to keep in flight)``.

    ``workers`` defaults to one process per available core (1 runs everything
    in this process; a batch passes :func:`default_workers`); with ``scheduler`` it is the number of jobs
    kept in flight on the cluster (default: its thread count).
    """
    if scheduler:
        ex = DaskCluster(scheduler, connect_timeout)
        return ex, workers or ex.threads
    workers = workers or available_cpus()
    return (Processes(workers) if workers > 1 else Inline()), workers
