"""The optimizer's GMA, built on a worker thread (:class:`GMABuild`): the lap OCP, the model's optimum, the
privileged directions and GMA (disk-cached where possible), then GMA's NLPs.

They take seconds (10-14 s when nothing is cached): on a worker thread, the optimizer node's services and status
answer from the first second. Once GMA exists (its first experiment needs no NLP) :attr:`GMABuild.ready` is set and
the node starts flying while the worker creates GMA's NLPs, which the first iteration's end needs (``GMA.prepare``;
a thread that needs them earlier waits).
"""
from __future__ import annotations

import threading
import time

from ..gma import GMA
from ..kite.params import ParameterError
from ..rto.builder import gma_directions, lap_problem, make_gma, model_only_optimum

__all__ = ["GMABuild"]


class GMABuild(threading.Thread):
    """Builds GMA for ``settings`` (a :class:`~kite_rto.rto.settings.KiteRTOSettings`), resumed from ``history``
    (None: a new run); ``logger`` has ``info`` and ``error``; ``make`` makes GMA from ``(settings, history=)``.

    Attributes:
        phase: what it does (``starting: ...``; the node's status meanwhile).
        built: once :attr:`ready`: the :class:`~kite_rto.gma.GMA`, a :class:`ParameterError` (settings it cannot
            build GMA for) or the exception the build raised; None when cancelled before.
        ready: set once :attr:`built` holds the result, or the build stopped on :meth:`cancel`.
        cancelled: set by :meth:`cancel`; the worker stops at its next step.
    """

    def __init__(self, settings, history, logger, make=make_gma):
        super().__init__(name="optimizer-build", daemon=True)
        self.settings, self.history, self.log, self._make = settings, history, logger, make
        self.phase = "starting"
        self.built = None
        self.ready = threading.Event()
        self.cancelled = threading.Event()

    def run(self) -> None:
        s = self.settings
        try:
            for what, step in (("building the lap OCP", lambda: lap_problem(s)),
                               ("solving for the model's optimum", lambda: model_only_optimum(s)),
                               ("computing the privileged directions", lambda: s.gradient != "directional" or
                                gma_directions(s))):
                if self.cancelled.is_set():
                    return self.ready.set()
                self.phase = f"starting: {what}"
                step()
            if self.history is not None:
                self.phase = "starting: resuming GMA from the database"
            self.built = self._make(s, history=self.history)
        except ValueError as err:       # e.g. more privileged directions than setpoints free to move on this box
            self.built = ParameterError(f"parameters gradient = {s.gradient!r}, n_directions = {s.n_directions}: "
                                        f"{err}")
        except Exception as err:  # noqa: BLE001 - reported and turned into a clean exit by the node
            self.built = err
        self.ready.set()
        if isinstance(self.built, GMA) and not self.cancelled.is_set():
            try:
                t0 = time.perf_counter()
                self.built.prepare()
                self.log.info(f"GMA's NLPs built in {time.perf_counter() - t0:.1f} s")
            except Exception as err:  # noqa: BLE001 - the executor meets it again where it needs the NLPs
                self.log.error(f"building GMA's NLPs failed: {err!r}")

    def cancel(self, wait: bool = True) -> None:
        """Stop at the next step; with ``wait``, wait for it (up to 120 s: CasADi must not run on two threads)."""
        self.cancelled.set()
        if wait:
            self.join(120.0)
