"""Progress of a long command on stderr: a rich bar with an ETA in a terminal, plain lines in a log.

One :class:`StageProgress` serves every command that counts finished units in stages (objects posed,
shards written, rollouts by object): ``update(stage, done, total)`` after each unit. In a terminal
each stage is a bar with its count, elapsed time and ETA; when stderr is not a terminal (a log file, a
pipe) each update is one line ``COMMAND: STAGE DONE/TOTAL [UNIT] (ELAPSED s[, DETAIL])``, so a log shows
every finished unit and when. :meth:`StageProgress.note` prints a line either way, above the bars.
"""

from __future__ import annotations

import sys
import time
from typing import TextIO

__all__ = ["StageProgress"]


class StageProgress:
    """A context manager: a bar per stage in a terminal, one line per finished unit otherwise.

    ``command`` starts every plain line; ``stream`` (default ``sys.stderr``) receives them, and the bars
    when it is a terminal; ``tty`` overrides that test.
    """

    def __init__(self, command: str, *, stream: TextIO | None = None, tty: bool | None = None) -> None:
        self.command = command
        self.stream = stream if stream is not None else sys.stderr
        self.tty = tty
        self.tasks: dict[str, int] = {}
        self.t0 = time.perf_counter()

    def __enter__(self) -> StageProgress:
        from rich.console import Console
        from rich.progress import BarColumn, Progress, TextColumn, TimeElapsedColumn, TimeRemainingColumn

        self.console = Console(file=self.stream, force_terminal=self.tty)
        if self.tty is None:
            self.tty = self.console.is_terminal
        self.bar = Progress(
            TextColumn("{task.description}"),
            BarColumn(),
            TextColumn("{task.completed}/{task.total}"),
            TimeElapsedColumn(),
            TimeRemainingColumn(),
            console=self.console,
            transient=True,
            disable=not self.tty,
        )
        self.bar.__enter__()
        self.t0 = time.perf_counter()
        return self

    def __exit__(self, *exc):
        return self.bar.__exit__(*exc)

    def update(
        self, stage: str, done: int, total: int, *, unit: str = "", detail: str = "", log: bool = True
    ) -> None:
        """Record that ``done`` of ``total`` units of ``stage`` have finished.

        ``unit`` names the last one, ``detail`` adds a figure (e.g. a rate) to the line; ``log=False``
        moves the bar only, with no plain line (units too many and short to log one by one).
        """
        if stage not in self.tasks:
            self.tasks[stage] = self.bar.add_task(stage, total=total)
        label = f"{stage} {detail}" if detail else stage
        self.bar.update(self.tasks[stage], completed=done, total=total, description=label)
        if log and not self.tty:
            extra = f", {detail}" if detail else ""
            name = f" {unit}" if unit else ""
            self.line(f"{stage} {done}/{total}{name} ({time.perf_counter() - self.t0:.0f} s{extra})")

    def note(self, text: str) -> None:
        """One line on the stream whatever it is (in a terminal above the bars): ``COMMAND: text``."""
        if self.tty:
            self.console.print(f"{self.command}: {text}", markup=False, highlight=False)
        else:
            self.line(text)

    def line(self, text: str) -> None:
        """``COMMAND: text`` as one plain line, flushed."""
        print(f"{self.command}: {text}", file=self.stream, flush=True)

    def __call__(self, stage: str, done: int, total: int) -> None:
        """:meth:`update` as the ``progress(stage, done, total)`` callback the library takes."""
        self.update(stage, done, total)
