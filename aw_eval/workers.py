"""Worker processes that never outlive the command that started them.

A scoring worker watches its parent: when the parent is gone (killed with SIGKILL, or ended
without stopping its pool) the worker exits within :data:`WATCH_SECONDS`, rather than scoring
on for minutes with nobody to receive the result. A worker ignores SIGINT and SIGHUP, which a
terminal sends to the whole process group: the parent acts on them (:mod:`aw.interrupts`).
:func:`stop_pool` ends a pool's workers at once (Ctrl-C, SIGTERM, a failure), where ``shutdown``
would wait for the running tasks.
"""

from __future__ import annotations

import os
import threading
import time
from concurrent.futures import ProcessPoolExecutor

from aw import interrupts

__all__ = ["WATCH_SECONDS", "watch_parent", "worker_init", "stop_pool"]

WATCH_SECONDS = 0.5


def watch_parent(parent: int) -> None:
    """Start a daemon thread that ends this process when its parent, the process ``parent``, is
    gone (a pool ``initializer``, with ``initargs=(os.getpid(),)``: the parent may be gone
    before the worker has even started)."""

    def watch() -> None:
        while os.getppid() == parent:  # an orphan is re-parented (to init or a subreaper)
            time.sleep(WATCH_SECONDS)
        os._exit(1)

    threading.Thread(target=watch, name="aw-watch-parent", daemon=True).start()


def worker_init(parent: int) -> None:
    """A pool ``initializer`` (``initargs=(os.getpid(),)``): signals left to the parent, and an
    end with it."""
    interrupts.ignore_in_worker()
    watch_parent(parent)


def stop_pool(pool: ProcessPoolExecutor, grace: float = 2.0) -> None:
    """Cancel what has not started and terminate the workers now (then wait ``grace`` seconds
    for them to go, killing any that linger)."""
    processes = list((getattr(pool, "_processes", None) or {}).values())  # no public handle before Python 3.14
    pool.shutdown(wait=False, cancel_futures=True)
    for p in processes:
        if p.is_alive():
            p.terminate()
    deadline = time.monotonic() + grace
    for p in processes:
        p.join(max(0.0, deadline - time.monotonic()))
        if p.is_alive():
            p.kill()
            p.join(1.0)
