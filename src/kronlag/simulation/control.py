"""Stopping a run and keeping its work: Ctrl-C (SIGINT) and an exception raised by a callback (a
time-varying parameter, ``progress``) end the integration at the last accepted step with
:attr:`Result.INTERRUPTED` or :attr:`Result.RAISED`; :func:`kronlag.simulate` then raises with the
partial :class:`~.trajectory.Trajectory` as the exception's attribute ``trajectory``: a
:class:`KeyboardInterrupt` (a plain one, so that a program that does not catch it ends as on any
Ctrl-C, by SIGINT) or the callback's exception.

Python runs its signal handlers only between bytecodes of the main thread, never while a compiled
driver runs.  A :class:`RunControl` therefore replaces the default SIGINT handler (``KeyboardInterrupt``)
for the run by one that only records the interrupt, and the drivers call back into Python, through
``progress``, after every step when ``progress`` is given and else at least every
:data:`POLL_INTERVAL` seconds: the handler runs there, the callback returns the code to stop with.
"""

from __future__ import annotations

import signal
import threading
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from typing import TYPE_CHECKING

from .interface import Progress
from .trajectory import Result

if TYPE_CHECKING:
    from .trajectory import Trajectory

__all__ = ["RunControl", "POLL_INTERVAL"]


#: Seconds between the compiled drivers' calls into Python when no ``progress`` is given: the
#: delay between Ctrl-C and the end of a compiled run.
POLL_INTERVAL = 0.05


class RunControl:
    """What ends one run early: Ctrl-C (:meth:`catching_sigint`) and exceptions raised by callbacks
    (:meth:`record`); read by the Python stepping loop (:meth:`report`) and the compiled drivers
    (:meth:`c_progress`) after every accepted step."""

    def __init__(self) -> None:
        self.interrupted = False
        self.error: BaseException | None = None

    def record(self, error: BaseException) -> None:
        """Note ``error``, raised during the run (a :class:`KeyboardInterrupt`: an interrupt)."""
        if isinstance(error, KeyboardInterrupt):
            self.interrupted = True
        elif self.error is None:
            self.error = error

    def stop(self) -> Result | None:
        """The result to end the run with now, or None to go on."""
        if self.interrupted:
            return Result.INTERRUPTED
        return Result.RAISED if self.error is not None else None

    def report(self, progress: Callable[[float], object] | None, t: float) -> Result | None:
        """Call ``progress(t)`` after an accepted step (recording what it raises); then :meth:`stop`."""
        if progress is not None:
            try:
                progress(t)
            except (Exception, KeyboardInterrupt) as error:  # noqa: BLE001 - the run ends, simulate raises it
                self.record(error)
        return self.stop()

    def c_progress(self, progress: Callable[[float], object] | None) -> tuple[Progress, float]:
        """The ``progress`` callback of a compiled driver and its interval (0: every step)."""

        def callback(t: float) -> int:
            stop = self.report(progress, t)
            return 0 if stop is None else stop.code

        return Progress(callback), 0.0 if progress is not None else POLL_INTERVAL

    @contextmanager
    def catching_sigint(self) -> Iterator[RunControl]:
        """Within the block, SIGINT (Ctrl-C) sets :attr:`interrupted` instead of raising, when this is
        the main thread and SIGINT has Python's default handler (another handler is left alone); a
        second SIGINT raises :class:`KeyboardInterrupt` at once.  The handler is restored after."""
        if (threading.current_thread() is not threading.main_thread()
                or signal.getsignal(signal.SIGINT) is not signal.default_int_handler):
            yield self
            return
        previous = signal.signal(signal.SIGINT, self._on_sigint)
        try:
            yield self
        finally:
            signal.signal(signal.SIGINT, previous)

    def _on_sigint(self, signum: int, frame) -> None:
        if self.interrupted:
            raise KeyboardInterrupt
        self.interrupted = True

    def raise_if_stopped(self, trajectory: Trajectory) -> None:
        """After an interrupt raise :class:`KeyboardInterrupt`, after a callback's exception raise it
        again: either with ``trajectory`` as its attribute ``trajectory`` (and a note saying so)."""
        if self.interrupted:
            error: BaseException = KeyboardInterrupt(f"simulation interrupted at {_reached(trajectory)}")
        elif self.error is not None:
            error, self.error = self.error, None
        else:
            return
        error.trajectory = trajectory
        error.add_note(f"kronlag.simulate: the partial trajectory (to {_reached(trajectory)}) is this "
                       "exception's .trajectory")
        raise error


def _reached(trajectory: Trajectory) -> str:
    return f"t = {trajectory.t[-1]:.6g}" if len(trajectory.t) else "its start"
