"""Step a Scenic simulation from outside, one time step per call.

Scenic 3.1 runs a whole simulation inside ``Simulation.__init__``. Here it runs
inside a greenlet: each time the simulation reaches ``step()`` it switches back
to the caller, which later switches in again with the agent's action. Single
threaded and deterministic; Scenic's signal-based timers keep working.

Scenic keeps the running simulation in module globals of
``scenic.syntax.veneer``. Several simulations may be suspended at once in one
process (vector envs), and a scenario may be compiled while one is suspended,
so the globals of the simulation that runs are installed lazily on each switch
in and set aside when another simulation (or a compilation) needs them.
"""

from __future__ import annotations

import signal
import threading
from contextlib import contextmanager
from dataclasses import dataclass
from typing import Any, Callable, Dict, Iterator, Optional

import greenlet
import scenic.syntax.veneer as veneer
from scenic.core.distributions import RejectionException
from scenic.core.dynamics import RejectSimulationException

from envs.errors import ResetNeededError
from scenario_bank.errors import DV2SError


__all__ = ["StepOutcome", "ExternalStepper", "installed_stepper", "release_veneer", "StepOvertime",
           "step_watchdog"]

_FIELDS = (
    "currentSimulation",
    "currentScenario",
    "runningScenarios",
    "inInitialScenario",
    "currentBehavior",
    "_globalParameters",
)

_installed: Optional["ExternalStepper"] = None


def installed_stepper() -> Optional["ExternalStepper"]:
    """The stepped simulation whose globals are installed now (``None``: none)."""
    return _installed


def release_veneer() -> None:
    """Set aside the globals of whichever stepped simulation holds them."""
    global _installed
    if _installed is not None:
        _installed._save_globals()
        _installed = None


@dataclass
class StepOutcome:
    """What a simulation did when it handed control back.

    ``status`` is ``"running"`` (waiting for the next action), ``"finished"``
    (the scenario terminated: ``reason`` says why) or ``"rejected"`` (a
    requirement was violated during the run: ``reason`` says which).
    """

    status: str
    reason: str = ""


class ExternalStepper:
    """Runs ``make_simulation()`` in a greenlet, pausing at every step.

    ``make_simulation`` must construct a Scenic ``Simulation`` whose ``step()``
    calls :meth:`handoff` first.
    """

    def __init__(self, make_simulation: Callable[["ExternalStepper"], Any]) -> None:
        self._make = make_simulation
        self._greenlet = greenlet.greenlet(self._run)
        self._saved: Optional[Dict[str, Any]] = None
        self._namespaces: Optional[Dict[str, Dict[str, Any]]] = None
        self.simulation = None
        self.done = False
        self.outcome: Optional[StepOutcome] = None

    # ---- inside the greenlet
    def _run(self) -> StepOutcome:
        global _installed
        release_veneer()
        _installed = self
        try:
            self.simulation = self._make(self)
            result = self.simulation.result
            reason = str(result.terminationReason) if result is not None else "ended"
            return StepOutcome("finished", reason)
        except (RejectSimulationException, RejectionException) as error:
            return StepOutcome("rejected", str(error))
        finally:
            if _installed is self:
                _installed = None

    def handoff(self) -> Any:
        """Called by the simulation's ``step()``: pause until the next action arrives."""
        try:
            action = self._greenlet.parent.switch(StepOutcome("running"))
        except greenlet.GreenletExit:
            self._install()
            raise
        self._install()
        return action

    # ---- veneer globals
    def _install(self) -> None:
        global _installed
        if _installed is self:
            return
        release_veneer()
        if self._saved is not None:
            for name, value in self._saved.items():
                setattr(veneer, name, value)
            for namespace, content in self._namespaces.values():
                namespace.clear()
                namespace.update(content)
        _installed = self

    def _save_globals(self) -> None:
        self._saved = {name: getattr(veneer, name) for name in _FIELDS}
        sim = veneer.currentSimulation
        self._namespaces = {}
        if sim is not None:
            for mod_name, (namespace, _sampled, original) in sim.scene.behaviorNamespaces.items():
                self._namespaces[mod_name] = (namespace, dict(namespace))
                namespace.clear()
                namespace.update(original)
        veneer.currentSimulation = None
        veneer.currentScenario = None
        veneer.runningScenarios = []
        veneer.currentBehavior = None
        veneer._globalParameters = {}

    # ---- outside
    def start(self) -> StepOutcome:
        """Set up the scene and run until the first step needs an action."""
        return self._switch()

    def advance(self, action: Any) -> StepOutcome:
        """Apply ``action`` and simulate one Scenic time step."""
        if self.done:
            raise ResetNeededError("the simulation has ended: call reset() to start a new episode")
        return self._switch(action)

    def _switch(self, *args) -> StepOutcome:
        outcome = self._greenlet.switch(*args)
        if self._greenlet.dead:
            self.done = True
            self.outcome = outcome
        return outcome

    def close(self) -> None:
        """Stop a simulation that is still running, letting Scenic clean up."""
        if not self._greenlet.dead and self._greenlet:
            self._greenlet.throw(greenlet.GreenletExit)
        self.done = True


class StepOvertime(DV2SError):
    """Raised inside a simulation step that ran past :func:`step_watchdog`'s limit."""

    expected = False

    def __init__(self, seconds: float) -> None:
        super().__init__(f"one simulation step used over {seconds:g} s of CPU time")
        self.seconds = seconds


@contextmanager
def step_watchdog(seconds: Optional[float]) -> Iterator[None]:
    """Interrupt the code running in the ``with`` block (a simulation step, whatever greenlet
    it runs in) with :class:`StepOvertime` once it has used ``seconds`` of CPU time.

    Scenic runs behaviours cooperatively: a behaviour that loops without taking an action
    (``while True: do B()`` with a ``B`` that returns at once) never hands the step back, and
    burns CPU. The timer is the process's profiling timer (``ITIMER_PROF``, ``SIGPROF``):
    Scenic itself uses ``SIGALRM`` for its stuck-behaviour warning, which would cancel a
    wall-clock timer. Only the main thread takes signals; elsewhere, or with ``seconds``
    None, nothing is watched. A timer already set by the caller is restored afterwards.
    """
    if not seconds or threading.current_thread() is not threading.main_thread():
        yield
        return

    def overtime(_signum, _frame):
        raise StepOvertime(float(seconds))

    previous = signal.signal(signal.SIGPROF, overtime)
    outer_delay, _ = signal.setitimer(signal.ITIMER_PROF, float(seconds))
    try:
        yield
    finally:
        signal.setitimer(signal.ITIMER_PROF, 0)
        signal.signal(signal.SIGPROF, previous)
        if outer_delay:
            signal.setitimer(signal.ITIMER_PROF, outer_delay)
