"""One solve's progress, cancellation, threads and statistics (`Run`), shared by its stages.

Work in a stage is cut into blocks (`Run.blocks`): each block reports progress and checks the
`cancel` callback when it ends, and blocks run in threads (numpy releases the GIL in its loops).
"""

import os
import threading
import time
from concurrent.futures import ThreadPoolExecutor, as_completed

import numpy as np

from . import checks

BLOCKS = 16  # work per stage is cut into about this many blocks (progress, cancel, threads)
MAX_THREADS = 256  # worker threads a solve accepts


class Cancelled(Exception):  # noqa: N818 (public name the add-on catches)
    """Raised by `Scene.solve` when its `cancel` callback returns True."""


class Run:
    """Progress, cancellation, threads and statistics of one solve."""

    def __init__(self, progress, cancel, threads):
        self._progress = progress
        self._cancel = cancel
        if threads is None:
            threads = min(2, os.cpu_count() or 1)
        self.threads = checks.count(threads, "threads", limit=MAX_THREADS)
        self.stats = dict(times={}, evaluations=0, rays=0, ray_tests=0, threads=self.threads)
        self._stage = None
        self._lock = threading.Lock()

    def progress(self, stage, fraction):
        if self._progress is not None:
            self._progress(stage, float(fraction))

    def check(self):
        if self._cancel is not None and self._cancel():
            raise Cancelled("radiosity solve cancelled")

    def stage(self, name):
        return _Stage(self, name)

    def count(self, **counts):
        with self._lock:
            for k, v in counts.items():
                self.stats[k] = self.stats.get(k, 0) + v

    def blocks(self, name, work, items, min_block=64):
        """Run work(chunk) over `items` cut into blocks (of at least `min_block` items where
        there are enough), in threads, with progress and cancel."""
        self.check()
        if len(items) == 0:
            return []
        count = min(max(1, len(items) // min_block), max(BLOCKS, 4 * self.threads))
        blocks = np.array_split(items, count)
        results = [None] * len(blocks)
        done = 0
        if self.threads == 1:
            for k, block in enumerate(blocks):
                results[k] = work(block)
                done += 1
                self.progress(name, done / len(blocks))
                self.check()
            return results
        with ThreadPoolExecutor(self.threads) as pool:
            futures = {pool.submit(work, block): k for k, block in enumerate(blocks)}
            try:
                for future in as_completed(futures):
                    results[futures[future]] = future.result()
                    done += 1
                    self.progress(name, done / len(blocks))
                    self.check()
            except BaseException:
                for future in futures:
                    future.cancel()
                raise
        return results


class _Stage:
    def __init__(self, run, name):
        self.run, self.name = run, name

    def __enter__(self):
        self.run.check()
        self.run.progress(self.name, 0.0)
        self.start = time.perf_counter()
        return self

    def __exit__(self, *exc):
        times = self.run.stats["times"]
        times[self.name] = times.get(self.name, 0.0) + time.perf_counter() - self.start
        return False
