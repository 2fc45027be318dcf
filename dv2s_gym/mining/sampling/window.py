"""The sliding-window schedule of an adaptive sampler: which scene is drawn when, whatever the timing.

With a window of ``W`` scenes, scene ``j`` is drawn exactly when the outcomes of scenes
``0 .. j-W`` have been fed back, in index order: ``W`` draws before any outcome, then one
more draw after each outcome fed. Outcomes may finish in any order; each is fed as soon
as every earlier one has been. So every draw, and every record, is a function of the
run's seed and ``W`` only -- not of how many workers ran the episodes, nor of when they
finished -- while the workers always have up to ``W`` scenes to run.

The draws do not depend on the budget either (the schedule keeps drawing past it; those
scenes are never run), so a run resumed with a larger budget continues exactly as an
uninterrupted run with that budget would have.

:class:`WindowSchedule` holds the sampler, the scenes drawn and not yet fed, and the
clusters seen by the ``novelty`` feedback; :meth:`WindowSchedule.dumps` is the run's
checkpoint (``sampler.pkl``). A run killed at any point is rebuilt from the checkpoint
(or from scratch) by :meth:`WindowSchedule.advance` with the recorded outcomes: it replays
the same draws and feeds in the same order.
"""

from __future__ import annotations

import io
from typing import Any, Callable, Dict, List, Optional, Tuple

from dv2s_gym.mining.errors import MiningError
from dv2s_gym.mining.sampling.checkpoint_mac import seal, unseal
from dv2s_gym.mining.sampling.samplers import UNSEALED, SceneSampler

__all__ = ["WindowSchedule", "SCHEDULES"]

SCHEDULES = ("window", "chunks")
"""``window``: this module (adaptive samplers); ``chunks``: draw ``batch`` scenes, feed them all, draw again
(non-adaptive samplers, whose draws do not depend on outcomes)."""

Feedback = Callable[[Dict[str, Any], set], float]


class WindowSchedule:
    """An adaptive sampler driven by the sliding-window schedule (module docstring).

    Args:
        sampler: a fresh sampler (nothing drawn or fed yet).
        window: ``W``, scenes drawn ahead of the last outcome fed (the run's ``batch``).
    """

    def __init__(self, sampler: SceneSampler, window: int) -> None:
        if int(window) < 1:
            raise MiningError(f"--batch must be at least 1, not {window}")
        self.sampler = sampler
        self.window = int(window)
        self.drawn = 0
        """Scenes drawn so far (indices ``0 .. drawn-1``)."""
        self.pending: Dict[int, Tuple[Any, Any]] = {}
        """``index -> (point, info)`` of the scenes drawn and not fed yet."""
        self.seen: set = set()
        """Failure clusters of the episodes fed so far (for the ``novelty`` feedback)."""

    @property
    def fed(self) -> int:
        """Outcomes fed so far (scenes ``0 .. fed-1``)."""
        return self.sampler.fed

    def advance(self, done: Dict[int, Dict[str, Any]], budget: int, feedback: Feedback,
                check: Optional[Callable[[int, Any, Dict[str, Any]], None]] = None) -> List[int]:
        """Feed every outcome that can be fed (index order, ``index < budget``) and make every draw the
        schedule allows; the indices drawn by this call.

        ``done``: finished records by index. ``feedback(record, seen)``: the value fed for a record.
        ``check(index, point, record)``: called before a record is fed (e.g. to verify that the
        recorded scene is this draw).
        """
        new: List[int] = []
        while True:
            while self.drawn < self.fed + self.window:
                (pair,) = self.sampler.draw(1)
                self.pending[self.drawn] = pair
                new.append(self.drawn)
                self.drawn += 1
            index = self.fed
            if index >= budget or index not in done:
                return new
            point, info = self.pending[index]
            if check is not None:
                check(index, point, done[index])
            self.sampler.feed(point, info, feedback(done[index], self.seen))
            del self.pending[index]

    def outstanding(self, done: Dict[int, Dict[str, Any]], budget: int) -> List[int]:
        """Drawn scenes below ``budget`` without a record yet, in index order."""
        return sorted(i for i in self.pending if i < budget and i not in done)

    def dumps(self) -> bytes:
        """The whole state (sampler, generators, pending draws) as bytes (:meth:`loads` restores it)."""
        import dill

        buffer = io.BytesIO()
        dill.dump({"schedule": "window", "state": self}, buffer)
        return seal(buffer.getvalue())

    @staticmethod
    def loads(data: bytes) -> "WindowSchedule":
        """Inverse of :meth:`dumps`; :class:`MiningError` if ``data`` holds something else."""
        import dill

        sealed = unseal(data)
        if sealed is None:
            raise MiningError(UNSEALED)
        try:
            payload = dill.loads(sealed)
        except Exception as error:
            raise MiningError(f"the sampler checkpoint cannot be read ({type(error).__name__}); delete sampler.pkl "
                              "to rebuild it from episodes.jsonl") from None
        state = payload.get("state") if isinstance(payload, dict) and payload.get("schedule") == "window" else None
        if not isinstance(state, WindowSchedule):
            raise MiningError("the sampler checkpoint holds no window schedule; delete sampler.pkl to rebuild it "
                              "from episodes.jsonl")
        return state
