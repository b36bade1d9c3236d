"""Work split over forked worker processes (the one place for it), and the BLAS threads a computation may use
(:func:`blas_threads`).

:func:`fork_map` runs ``func(*args)`` for each ``args`` in its own process, forked from this one (so
the workers share what is loaded, with nothing pickled on the way in), and returns the results in
order. An exception in a worker is raised here, the first in argument order (the error of the
earliest part of a file, as a serial run would give); the other workers are then stopped. Ctrl-C and
SIGTERM reach the parent, which stops the workers. Where ``fork`` is not available (Windows, macOS'
default) :func:`workers` is 1 and callers run serially.
"""
from __future__ import annotations

import multiprocessing
import os
import signal
import sys

__all__ = ["workers", "fork_map", "WorkerDied", "blas_threads"]


class WorkerDied(OSError):
    """A worker process ended without a result (killed, e.g. by the kernel's out-of-memory killer): a
    failure of the system, reported like one (``aacmm``: the message, exit 2, nothing written)."""


_CONTROLLERS: dict = {}


def blas_threads(n: int | None = 1):
    """A context limiting the BLAS threads (threadpoolctl) to ``n`` (None: unchanged). Small or thin
    products gain nothing from several threads, and on a busy machine the idle ones spin-wait (10-15 x
    slower). threadpoolctl's controller (finding the loaded BLAS libraries takes 0.4 ms: more than many of the
    computations it wraps) is made once for numpy's BLAS alone and once more when scipy's is loaded too."""
    import contextlib
    if n is None:
        return contextlib.nullcontext()
    key = "scipy.linalg" in sys.modules
    if key not in _CONTROLLERS:
        from threadpoolctl import ThreadpoolController
        _CONTROLLERS[key] = ThreadpoolController()
    return _CONTROLLERS[key].limit(limits=n, user_api="blas")


def cores() -> int:
    """The cores this process may run on (at least 1)."""
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except (AttributeError, OSError):
        return os.cpu_count() or 1


def workers(limit: int = 2) -> int:
    """How many worker processes to use: the cores this process may run on, at most ``limit``; 1
    where forking is not safe."""
    if not sys.platform.startswith("linux"):
        return 1
    return max(1, min(limit, cores()))


def _child(conn, func, args) -> None:
    signal.signal(signal.SIGINT, signal.SIG_IGN)      # the parent handles Ctrl-C and stops us
    signal.signal(signal.SIGTERM, signal.SIG_DFL)
    try:
        result = ("ok", func(*args))
    except BaseException as exc:                     # noqa: BLE001 - handed to the parent
        result = ("error", exc)
    try:
        conn.send(result)
    except Exception as exc:                         # noqa: BLE001 - an unpicklable result
        conn.send(("error", RuntimeError(f"a worker's result could not be returned: {exc}")))
    conn.close()


def fork_map(func, arg_lists) -> list:
    """``[func(*args) for args in arg_lists]``, each in a forked process (see the module doc)."""
    ctx = multiprocessing.get_context("fork")
    procs, done = [], False
    try:
        for args in arg_lists:
            recv, send = ctx.Pipe(duplex=False)
            proc = ctx.Process(target=_child, args=(send, func, tuple(args)), daemon=True)
            proc.start()
            send.close()
            procs.append((proc, recv))
        out = []
        for proc, recv in procs:
            try:
                kind, value = recv.recv()
            except EOFError:
                proc.join()
                raise WorkerDied(f"a worker process ended without a result (exit code {proc.exitcode})") from None
            if kind == "error":
                raise value
            out.append(value)
        done = True
        return out
    finally:
        for proc, recv in procs:
            if not done and proc.is_alive():
                proc.terminate()
            proc.join()
            recv.close()
