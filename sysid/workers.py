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
from concurrent.futures import FIRST_COMPLETED, Future, ProcessPoolExecutor, wait
from typing import Callable, Hashable, Sequence, TypeVar

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


class Overlap:
    """Work handed to up to `workers` processes while something else (Ray's trials) keeps
    the cores busy: items queue with `add` and start only as `allow` frees slots for them
    (a count that only grows), so the work fills cores the other job leaves idle instead
    of competing with it. Results are kept by key (`results`); `on_result(key, result)`
    may `add` follow-up items. Everything runs in the caller's thread: `poll` collects
    finished work and starts queued work, `finish` lets every slot work and waits for all.

    Used as a context manager: leaving it by an error or Ctrl-C stops every worker and
    waits until they have exited (as `in_workers`); work queued and not started never starts.
    """

    def __init__(self, work: Callable, workers: int, context=None,
                 on_result: Callable[[Hashable, object], None] | None = None):
        self.work, self.workers, self.context, self.on_result = work, max(1, workers), context, on_result
        self.allowed = 0
        self.queued: list[tuple[Hashable, object, bool]] = []  # (key, item, queued first)
        self.running: dict[Future, Hashable] = {}
        self.results: dict[Hashable, object] = {}
        self._pool: ProcessPoolExecutor | None = None

    def __enter__(self) -> "Overlap":
        return self

    def __exit__(self, kind, value, traceback) -> None:
        if self._pool is not None:
            if kind is not None:
                _stop(self._pool)
            self._pool.shutdown(wait=True, cancel_futures=True)
            self._pool = None

    def add(self, key: Hashable, item, first: bool = False) -> None:
        """Queue `work(item)`, its result kept under `key` (it starts when a slot is allowed and
        free); `first`: ahead of the items queued without it (long work first, so the last
        items to run are short ones)."""
        if first:
            ahead = sum(1 for _, _, f in self.queued if f)
            self.queued.insert(ahead, (key, item, True))
        else:
            self.queued.append((key, item, False))
        self.poll()

    def allow(self, slots: int) -> None:
        """Let up to `slots` items work at once from now on (never fewer than before)."""
        self.allowed = max(self.allowed, min(slots, self.workers))
        self.poll()

    def poll(self) -> None:
        """Collect finished work (an error in it propagates) and start queued work."""
        finished = [(f, self.running.pop(f)) for f in list(self.running) if f.done()]
        for future, key in finished:  # taken out first: `on_result` may `add`, which polls again
            self.results[key] = future.result()
            if self.on_result is not None:
                self.on_result(key, self.results[key])
        while self.queued and len(self.running) < self.allowed:
            key, item, _ = self.queued.pop(0)
            self.running[self._submit(item)] = key

    def _submit(self, item) -> Future:
        in_main = threading.current_thread() is threading.main_thread()
        blocking = in_main and hasattr(signal, "pthread_sigmask") and self._pool is None
        if blocking:  # the workers start with SIGINT blocked, then ignore it (as `in_workers`)
            signal.pthread_sigmask(signal.SIG_BLOCK, {signal.SIGINT})
        try:
            if self._pool is None:
                self._pool = ProcessPoolExecutor(max_workers=self.workers, mp_context=self.context,
                                                 initializer=_ignore_interrupts)
            return self._pool.submit(self.work, item)
        finally:
            if blocking:
                signal.pthread_sigmask(signal.SIG_UNBLOCK, {signal.SIGINT})

    def finish(self) -> dict:
        """Every slot allowed; wait for all work, queued and added on the way: `results`."""
        self.allow(self.workers)
        while self.running or self.queued:
            wait(list(self.running), timeout=0.2, return_when=FIRST_COMPLETED)
            self.poll()
        return self.results
