"""The worker thread behind the modal operator (addon/jobs.py): progress, cancel, errors."""

import threading

import pytest
from blender_helpers import bpy  # noqa: F401 (skips without bpy, like the other Blender tests)

pytestmark = pytest.mark.blender


def test_progress_and_result(addon):
    """The run function gets progress and cancel callables; progress is visible from outside."""
    seen = threading.Event()

    def run(progress, cancel):
        progress("form factors", 0.5)
        seen.set()
        assert cancel() is False

    worker = addon.jobs.BackgroundSolve(run).start()
    assert seen.wait(5) and worker.wait(5)
    assert (worker.stage, worker.fraction, worker.error) == ("form factors", 0.5, None)


def test_cancel_reaches_the_solver(addon):
    """cancel() makes the run's cancel callable true; what it raises is kept for the main thread."""
    started = threading.Event()

    class StoppedError(Exception):
        pass

    def run(progress, cancel):
        started.set()
        while not cancel():
            threading.Event().wait(0.01)
        raise StoppedError()

    worker = addon.jobs.BackgroundSolve(run).start()
    assert started.wait(5)
    assert not worker.done
    worker.cancel()
    assert worker.wait(5) and worker.cancelled and isinstance(worker.error, StoppedError)
