"""Worker processes that end with the job: on Ctrl-C (SIGINT) or an error, every worker is
stopped and has exited before the call returns, so nothing writes on into an output that
the caller then removes.

The workers never act on SIGINT (a terminal sends it to the whole process group): they
start with it blocked and then ignore it. The main process notes it in a flag, checked
between short waits (an exception raised by the handler itself can land while the pool
starts a worker, where Python swallows it), then cancels the work not started,
terminates the workers, waits for them to exit and raises `KeyboardInterrupt`.
"""
from __future__ import annotations

import signal
import threading
from concurrent.futures import FIRST_COMPLETED, ProcessPoolExecutor, wait
from typing import Callable, Sequence, TypeVar

Item = TypeVar("Item")
Result = TypeVar("Result")

STOP_WAIT_S = 10.0  # a terminated worker that has not exited by then is killed


def _ignore_interrupts() -> None:
    """In each worker: Ctrl-C is the main process's to handle."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)


def _stop(pool: ProcessPoolExecutor) -> None:
    """Terminate the pool's workers and wait until they have exited."""
    processes = list((getattr(pool, "_processes", None) or {}).values())  # the executor's own record
    for process in processes:
        if process.is_alive():
            process.terminate()
    for process in processes:
        process.join(STOP_WAIT_S)
        if process.is_alive():
            process.kill()
            process.join()


def in_workers(work: Callable[[Item], Result], items: Sequence[Item], workers: int, context=None,
               on_result: Callable[[Result], None] | None = None) -> list[Result]:
    """`work(item)` for every item in up to `workers` processes (a `multiprocessing`
    `context`, default the platform's); results in completion order, each also passed to
    `on_result` as it arrives. Ctrl-C raises `KeyboardInterrupt` and an error in a worker
    propagates, both only once every worker has exited."""
    stopped: list[int] = []
    in_main = threading.current_thread() is threading.main_thread()  # where Python runs signal handlers
    if in_main:
        previous = signal.signal(signal.SIGINT, lambda signum, frame: stopped.append(signum))
    # while the workers start, SIGINT waits (blocked, not lost): they inherit the block and
    # keep it, so only this process sees a Ctrl-C, once it is unblocked below
    blocking = in_main and hasattr(signal, "pthread_sigmask")
    if blocking:
        signal.pthread_sigmask(signal.SIG_BLOCK, {signal.SIGINT})
    pool = ProcessPoolExecutor(max_workers=max(1, min(workers, len(items))), mp_context=context,
                               initializer=_ignore_interrupts)
    finished = False
    try:
        try:
            pending = {pool.submit(work, item) for item in items}  # starts the workers
        finally:
            if blocking:
                signal.pthread_sigmask(signal.SIG_UNBLOCK, {signal.SIGINT})
        results = []
        while pending and not stopped:
            done, pending = wait(pending, timeout=0.2, return_when=FIRST_COMPLETED)
            for future in done:
                results.append(future.result())
                if on_result is not None:
                    on_result(results[-1])
        if stopped:
            raise KeyboardInterrupt
        finished = True
        return results
    finally:
        if not finished:
            _stop(pool)
        pool.shutdown(wait=True, cancel_futures=True)
        if in_main:
            signal.signal(signal.SIGINT, previous)
