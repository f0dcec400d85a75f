"""SIGINT and SIGTERM as a stop request (standard library only, so it can be installed before anything heavy loads).

rclpy's own handler shuts the context down the moment the signal arrives, while a callback may still be publishing:
"publisher's context is invalid" tracebacks, or a RuntimeError out of ``spin_once``. And a signal that arrives
while Python is still importing numpy or CasADi raises KeyboardInterrupt inside an extension module's import.
:data:`STOP` instead only records the first signal; :func:`kite_rto.nodes.spin.run_node` checks it between
callbacks and stops cleanly (exit code 0). A second signal while stopping raises KeyboardInterrupt (exit 130).
"""
from __future__ import annotations

import signal

__all__ = ["StopSignals", "STOP"]


class StopSignals:
    """Records the first SIGINT/SIGTERM (:attr:`signum`); a second one raises KeyboardInterrupt."""

    def __init__(self):
        self.signum: int | None = None
        self._previous: dict = {}

    @property
    def installed(self) -> bool:
        return bool(self._previous)

    def install(self) -> None:
        """Handle SIGINT and SIGTERM (idempotent; a signal already recorded is kept)."""
        if self.installed:
            return
        for sig in (signal.SIGINT, signal.SIGTERM):
            self._previous[sig] = signal.signal(sig, self._handle)

    def restore(self) -> None:
        """Put the previous handlers back (the record of a received signal is kept)."""
        for sig, handler in self._previous.items():
            signal.signal(sig, handler)
        self._previous = {}

    @property
    def name(self) -> str:
        """The received signal's name (``SIGINT``), or ``""``."""
        return signal.Signals(self.signum).name if self.signum is not None else ""

    def _handle(self, signum, frame) -> None:
        if self.signum is not None:
            raise KeyboardInterrupt
        self.signum = signum


STOP = StopSignals()
"""The process's stop request."""
