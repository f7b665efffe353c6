"""Lockstep with several clients driving the clock: ``STEP {Count n} {Sync true}``.

A plain ``STEP`` advances the world ``n`` steps whoever else steps it: with one ``skeye pilot``
per robot, each pilot's steps add up, and with N pilots sim time ran N times each pilot's pace,
each robot's control ticking once every N of its periods. A connection with a robot that steps
with ``Sync`` joins the barrier instead: its ``STEP`` asks for the world to reach its own next
boundary (now + ``n`` steps), and the world advances, to the nearest such boundary, only once
every member has asked; each member's answer goes out when the world reaches its boundary. With
one member this is a plain ``STEP``, step for step. A member that stops asking holds the
others, as PX4 instances hold Gazebo's lockstep world; a member leaves when its connection
ends (or it goes away during its ``STEP``), and a STEP not answered within the server's limit
is withdrawn. Plain ``STEP``s of other connections still advance the world; a member whose
boundary they pass is answered then.

Everything here runs on the engine thread (``SimulationRunner`` tasks), so it needs no lock.
"""

from __future__ import annotations

from collections.abc import Callable
from concurrent.futures import Future
from dataclasses import dataclass
from functools import partial

from skeye.sim.engine import Simulation


@dataclass
class _Ask:
    """A member's STEP not yet answered."""

    target: int  # the world's step count it waits for
    answer: Callable[[Simulation], None]  # sends its RES (engine thread)
    gone: Callable[[], bool]  # its client went away: stop stepping for it
    future: Future[None]  # done once answered, or once the member has left


class ClockBarrier:
    """The members of one simulator's lockstep barrier and their STEPs."""

    def __init__(self) -> None:
        self._members: dict[int, _Ask | None] = {}  # connection id -> its STEP, if it waits

    @property
    def members(self) -> int:
        """How many connections drive the clock in step."""
        return len(self._members)

    @property
    def waiting(self) -> int:
        """How many of them wait for the others (a STEP asked, not yet answered)."""
        return sum(ask is not None for ask in list(self._members.values()))

    def step(self, sim: Simulation, conn_id: int, count: int, answer: Callable[[Simulation], None],
             gone: Callable[[], bool], future: Future[None]) -> None:
        """Member ``conn_id`` asks for ``count`` more steps (joining at its first); the world
        advances as far as every member has asked."""
        self._members[conn_id] = _Ask(sim.steps + count, answer, gone, future)
        self.advance(sim)

    def leave(self, sim: Simulation, conn_id: int) -> None:
        """``conn_id`` no longer drives the clock: its STEP, if one waits, ends unanswered; the
        others go on without it."""
        ask = self._members.pop(conn_id, None)
        if ask is not None:
            _end(ask.future)
        self.advance(sim)

    def advance(self, sim: Simulation) -> None:
        """Answer every STEP the world has reached; step on while every member waits."""
        while True:
            for conn_id, ask in list(self._members.items()):
                if ask is not None and ask.gone():
                    del self._members[conn_id]
                    _end(ask.future)
                elif ask is not None and sim.steps >= ask.target:
                    self._members[conn_id] = None
                    if ask.future.set_running_or_notify_cancel():  # not given up by its reader
                        try:
                            ask.answer(sim)
                        finally:
                            ask.future.set_result(None)
            asks = [ask for ask in self._members.values() if ask is not None]
            if not asks or len(asks) < len(self._members):
                return
            sim.step(min(ask.target for ask in asks) - sim.steps, partial(_any_gone, asks))

    def withdraw(self, sim: Simulation, conn_id: int, future: Future[None]) -> None:
        """The STEP of ``future`` was given up by its reader (the members did not all ask in
        time): it no longer waits, and the world will not step to its boundary."""
        ask = self._members.get(conn_id)
        if ask is not None and ask.future is future:
            self._members[conn_id] = None

    def fail(self, exc: BaseException) -> None:
        """The engine died: every waiting STEP ends with its error (one whose own task failed
        has it already)."""
        for ask in self._members.values():
            if ask is not None:
                fail_step(ask.future, exc)
        self._members.clear()


def _any_gone(asks: list[_Ask]) -> bool:
    return any(ask.gone() for ask in asks)


def fail_step(future: Future[None], exc: BaseException) -> None:
    """End a STEP's future with ``exc``, unless it has ended already (answered, failed, or
    given up by its reader)."""
    if not future.done() and future.set_running_or_notify_cancel():
        future.set_exception(exc)


def _end(future: Future[None]) -> None:
    """End a STEP that will not be answered (its member left)."""
    if future.set_running_or_notify_cancel():
        future.set_result(None)
