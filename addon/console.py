"""Progress of a solve on a console: a bar redrawn in place on a terminal, plain lines elsewhere.

The core reports `progress(stage, fraction)` with each stage's own fraction, and some stages run
more than once (form factors and visibility are refined in passes). Every line names its stage,
and a stage seen again is labelled as a new pass ("visibility (pass 2)"), so a log never shows a
bar that seems to restart at 0 %. On a terminal the current stage's bar is redrawn with `\\r`
and ends with a newline when the next stage starts; on anything else (a pipe, a log file) only
whole lines are written: one when a stage starts, one each time it passes another `step` of its
own progress, and one when it completes.
"""

import sys


class ConsoleProgress:
    """A `progress(stage, fraction)` callback printing to `stream`.

    Parameters
    ----------
    stream : file-like, optional
        Default `sys.stdout` (looked up at each call, so redirections are honoured).
    terminal : bool or None
        Draw in place; None: if the stream is a TTY.
    step : float
        Plain-line mode: print a stage again each time its fraction grows by this much.
    width : int
        Bar width in characters (terminal mode).
    """

    def __init__(self, stream=None, terminal=None, step=0.25, width=30):
        self._stream = stream
        self._terminal = terminal
        self.step = float(step)
        self.width = int(width)
        self._passes = {}  # stage name -> passes seen
        self._current = None  # label of the stage being shown
        self._printed = -1.0  # plain mode: fraction printed last for the current stage
        self._open = False  # terminal mode: a bar line without its newline
        self._last = 0.0  # the fraction of the previous call
        self._shown = ""  # terminal mode: the bar drawn last

    @property
    def stream(self):
        return self._stream if self._stream is not None else sys.stdout

    @property
    def terminal(self):
        if self._terminal is not None:
            return self._terminal
        isatty = getattr(self.stream, "isatty", None)
        return bool(isatty and isatty())

    def __call__(self, stage, fraction):
        fraction = min(max(float(fraction), 0.0), 1.0)
        label = self._label(stage, fraction)
        self._last = fraction
        if self.terminal:
            self._draw(label, fraction)
        else:
            self._line(label, fraction)

    def _label(self, stage, fraction):
        """The stage's label: its name, with the pass number from the second pass on (a stage
        starts a new pass when another stage came between, or when its fraction goes back)."""
        name = str(stage)
        current_name = self._current[0] if self._current else None
        if name != current_name or fraction < self._last:
            self._passes[name] = self._passes.get(name, 0) + 1
            count = self._passes[name]
            self._current = (name, name if count == 1 else f"{name} (pass {count})")
            self._printed = -1.0
            if self._open:
                self.stream.write("\n")
                self._open = False
        return self._current[1]

    def _draw(self, label, fraction):
        filled = int(round(self.width * fraction))
        bar = "#" * filled + "." * (self.width - filled)
        text = f"\r  {label:<26} [{bar}] {100 * fraction:5.1f}%"
        if self._open and text == self._shown:
            return  # many small blocks: redraw only what changes
        self._shown = text
        self.stream.write(text)
        self._open = fraction < 1.0
        if not self._open:
            self.stream.write("\n")
        self.stream.flush()

    def _line(self, label, fraction):
        first = self._printed < 0.0
        if first or fraction >= 1.0 > self._printed or fraction >= self._printed + self.step:
            self.stream.write(f"  {label:<26} {100 * fraction:5.1f}%\n")
            self.stream.flush()
            self._printed = fraction

    def close(self):
        """End an open bar line (terminal mode)."""
        if self._open:
            self.stream.write("\n")
            self.stream.flush()
            self._open = False
