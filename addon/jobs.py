"""Run `pipeline.run` in a worker thread, with progress and cancel for a modal operator (no bpy).

The worker touches only numpy data (the core solver); the modal operator polls `stage`,
`fraction` and `done` from timer events and writes results on the main thread when finished.
"""

import threading


class BackgroundSolve:
    """A solve running in a daemon thread.

    Attributes
    ----------
    stage : str
        The core's current stage name.
    fraction : float
        Progress of that stage in [0, 1].
    error : BaseException or None
        What the solve raised (core.Cancelled after `cancel`).
    """

    def __init__(self, run):
        """`run(progress, cancel)` is called in the thread."""
        self._run = run
        self._cancel = threading.Event()
        self._thread = threading.Thread(target=self._main, daemon=True)
        self.stage = "starting"
        self.fraction = 0.0
        self.error = None

    def start(self):
        self._thread.start()
        return self

    def cancel(self):
        """Ask the solver to stop at its next check."""
        self._cancel.set()

    @property
    def cancelled(self):
        return self._cancel.is_set()

    @property
    def done(self):
        return not self._thread.is_alive()

    def wait(self, timeout=None):
        self._thread.join(timeout)
        return self.done

    def _progress(self, stage, fraction):
        self.stage, self.fraction = stage, float(fraction)

    def _main(self):
        try:
            self._run(self._progress, self._cancel.is_set)
        except BaseException as error:  # handed to the main thread, which reports it
            self.error = error
