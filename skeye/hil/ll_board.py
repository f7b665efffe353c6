"""The AscTec low-level board as the simulator plays it, sans-IO.

How this works: what the LL board answers on its serial line (the structures, CTRL_INPUT in
attitude / height / GPS mode, the motor start/stop gesture, the single waypoint and ``>*>wl``
``we`` ``wg`` ``wh``) is what the pilot already emulates towards ground control
(:class:`skeye.pilot.boards.OnboardBoards`). ``LLBoard`` wraps one, over the simulated robot
(an ``Airframe``), so both speak with one implementation, and keeps to what the real board
does on its line:

- AscTec commands and polls only. Every intact command is acknowledged (``>a PD a<``), also
  when the board's state makes it ignore it (sticks before the motors run, a waypoint while
  landing) or a field is out of its range (a stick beyond +-2047: its checksum holds, it is
  not flown): the real board acknowledges what it received, and LL_STATUS tells what it did. The
  skeye RESULT the pilot would answer instead is counted in ``ignored`` (with the reason).
- A command with a bad checksum is counted (LL_STATUS ``chksum_error``), never answered; an
  unreadable frame and unknown ``>*>`` letters are not answered either (counted with the
  line's garbage, which the board's server says at most every 5 s; not in ``chksum_error``).
- skeye commands (``>*>s`` frames) are answered RESULT code 3, "the LL board takes AscTec
  commands only", except CLOCK: in lockstep it grants sim time (the I/O side advances the
  simulator and answers once the time is reached, see :mod:`skeye.hil.ll_server`). So is an
  intact skeye frame the board cannot read (its CRC holds: an unknown PD, whatever its value,
  a field out of range); a CLOCK of the wrong length is answered RESULT code 2, as the pilot
  answers it.
- The serial timeout: a line with no valid packet for ``serial_timeout_s`` while the vehicle
  flies starts AscTec's emergency procedure "wait and land" (the AscTec emergency-mode
  documentation: the vehicle waits 5 s at its position and height, then descends; the R/C, which
  would otherwise take over, is not simulated): the boards' link-loss failsafe with these
  times, counted as the pilot counts them on a simulator: the silence must last that long on
  the wall clock and in sim time, the vehicle's own time (in lockstep a client that grants no
  time leaves the world standing, and at ``--lockstep-rate 0.1`` 0.5 s of sim time is 5 s of
  wall time). A valid CTRL_INPUT after it ends the procedure (the boards go back to holding, then
  fly the sticks), as AscTec's does when the connection comes back.
- The R/C's serial-interface switch (channel 5 of the transmitter, ``RC_DATA`` channel[4]):
  on by default; :meth:`LLBoard.set_serial_switch` turns it off as a safety pilot would: the
  board then ignores serial sticks and holds its position (GPS mode, sticks centred), and
  RC_DATA shows the switch off.

Time is an argument (the simulator's time, so a lockstep run is reproducible); the board owns
no socket or thread.
"""

from __future__ import annotations

import logging
from collections import Counter
from dataclasses import dataclass, replace

from skeye.errors import ConfigError
from skeye.pilot.airframe import Airframe
from skeye.pilot.boards import BoardSettings, OnboardBoards, event_pd
from skeye.pilot.envelope import FlightEnvelope
from skeye.wire.packets import (
    PD,
    Ack,
    Clock,
    ComeHome,
    CommandError,
    CommandEvent,
    CtrlInput,
    EndFlight,
    FrameError,
    Hold,
    Launch,
    Message,
    NavState,
    Poll,
    RcData,
    Result,
    ResultCode,
    Waypoint,
    WaypointGoto,
)

log = logging.getLogger(__name__)

ASCTEC_COMMANDS = (CtrlInput, Waypoint, WaypointGoto, Launch, EndFlight, ComeHome)
WAIT_BEFORE_LANDING_S = 5.0
"""AscTec's emergency procedure "wait and land": seconds held before the descent."""
SERIAL_TIMEOUT_S = 0.5
"""A line silent this long (10 of the pilot's 20 Hz command cycles) starts the emergency
procedure. AscTec does not publish its figure; this is skeye's (docs/onboard.md)."""
SKEYE_REFUSAL = "the LL board takes AscTec commands only (and CLOCK in lockstep)"
SWITCH_CHANNEL = 4  # RC_DATA channel[4]: the serial interface switch (> 2048 enabled)
# The LL board keeps no flight envelope (that is the onboard computer's): limits this wide
# never act.
NO_ENVELOPE = FlightEnvelope(ceiling_m=100_000.0, max_radius_m=10_000_000.0)


@dataclass(frozen=True)
class LLSettings:
    """The emulated board's own figures."""

    serial_timeout_s: float = SERIAL_TIMEOUT_S
    wait_before_landing_s: float = WAIT_BEFORE_LANDING_S
    max_speed_m_s: float = 3.0  # full stick in GPS mode (the robot file's MaxSpeed)
    max_climb_m_s: float = 1.5  # full thrust stick in height / GPS mode (MaxClimb)

    def __post_init__(self) -> None:
        for name in ("serial_timeout_s", "wait_before_landing_s", "max_speed_m_s",
                     "max_climb_m_s"):
            value = getattr(self, name)
            if not (isinstance(value, (int, float)) and 0 < value < 1e6):
                raise ConfigError(f"LL board: {name} must be a positive number, got {value!r}")


class LLBoard:
    """The low-level board's answers on its serial line, over one ``Airframe``."""

    def __init__(self, airframe: Airframe, settings: LLSettings | None = None,
                 now_s: float = 0.0) -> None:
        self.settings = settings or LLSettings()
        s = self.settings
        self.boards = OnboardBoards(
            airframe,
            BoardSettings(link_timeout_s=s.serial_timeout_s,
                          land_timeout_s=s.wait_before_landing_s,
                          max_speed_m_s=s.max_speed_m_s, max_climb_m_s=s.max_climb_m_s,
                          default_speed_m_s=min(1.0, s.max_speed_m_s), envelope=NO_ENVELOPE),
            now_s=now_s,
        )
        self.serial_switch = True
        self.ignored: Counter[str] = Counter()  # commands acknowledged but not acted on, by why
        self.refused_skeye = 0
        self.emergencies = 0  # emergency procedures started by the serial timeout
        self._emergency_landing = False

    @property
    def airframe(self) -> Airframe:
        return self.boards.airframe

    @property
    def in_emergency(self) -> bool:
        """The serial timeout's procedure (hold, then land) is under way."""
        return self.boards.state is NavState.FAILSAFE or (
            self.boards.state is NavState.LANDING and self._emergency_landing)

    def set_serial_switch(self, on: bool) -> None:
        """The safety pilot's serial-interface switch: off, the board ignores serial sticks and
        holds its position."""
        if on == self.serial_switch:
            return
        self.serial_switch = on
        log.warning("LL board: the R/C's serial switch is now %s", "on" if on else "off")
        if not on and self.boards.state in (NavState.FLYING, NavState.HOLDING,
                                            NavState.TAKING_OFF, NavState.MANUAL):
            self.boards.airframe.hover()

    def handle(self, event: CommandEvent, now_s: float) -> list[Message]:
        """The board's answer to one parsed command or decode error (a CLOCK is answered by
        the I/O side once the time is reached: here it gives nothing)."""
        if (isinstance(event, CommandError) and event.code is ResultCode.BAD_VALUE
                and event.pd in ACK_PD.values()):
            # An AscTec command whose checksum holds, a field out of its range (a pitch of
            # 3000 counts): intact, so acknowledged as every intact command; not acted on.
            self.boards.handle(Poll(0), now_s)  # a valid packet: the line is alive
            self.ignored["a field out of range"] += 1
            log.info("LL board: command acknowledged, not acted on: %s", event.reason)
            return [Ack(PD(event.pd))]
        if (isinstance(event, CommandError) and event.code is not ResultCode.BAD_CHECKSUM
                and event.pd not in ACK_PD.values()):
            # A skeye frame the board cannot read: a CLOCK whose length field is not its PD's
            # (answered at once, before its CRC came), an unknown skeye PD or a field out of
            # range (its CRC held). A client sent it and waits for its RESULT; answered as the
            # board's other skeye packets are (the boards count it as a packet for the link
            # only if it arrived intact: skeye.wire.packets.arrived_intact).
            replies = self.boards.handle(event, now_s)
            if event.pd == PD.CLOCK:
                return replies  # the one it takes: code 2 or 3, the reason says what is wrong
            self.refused_skeye += 1
            return [Result(event.pd, ResultCode.BAD_VALUE, SKEYE_REFUSAL)]
        if isinstance(event, (CommandError, FrameError)):
            self.boards.handle(event, now_s)  # counted (a bad checksum: LL_STATUS chksum_error)
            return []
        if isinstance(event, Clock):
            self.boards.handle(Poll(0), now_s)  # a valid packet: the line is alive
            return []
        if isinstance(event, Poll):
            return self._switch_shown(self.boards.handle(event, now_s))
        if not isinstance(event, ASCTEC_COMMANDS):
            self.refused_skeye += 1
            return [Result(event_pd(event), ResultCode.BAD_VALUE, SKEYE_REFUSAL)]
        pd = ACK_PD[type(event)]
        if isinstance(event, CtrlInput) and not self.serial_switch:
            self.boards.handle(Poll(0), now_s)
            self.ignored["serial switch off"] += 1
            return [Ack(pd)]
        if isinstance(event, CtrlInput) and self.in_emergency:
            # The serial input is back: the emergency procedure ends, the board holds, then
            # flies the sticks.
            log.warning("LL board: serial input back: emergency procedure ended")
            self.boards.handle(Hold(), now_s)
            self._emergency_landing = False
        replies = self.boards.handle(event, now_s)
        for reply in replies:
            if isinstance(reply, Result) and reply.code is not ResultCode.OK:
                self.ignored[reply.reason or reply.code.name] += 1
                log.info("LL board: %s acknowledged, not acted on: %s", type(event).__name__,
                         reply.reason)
        return [Ack(pd)]

    def tick(self, now_s: float) -> None:
        """Advance the board's time-dependent behaviour (gesture, flight progress, the serial
        timeout and its emergency procedure)."""
        before = self.boards.state
        self.boards.tick(now_s)
        after = self.boards.state
        if after is NavState.FAILSAFE and before is not NavState.FAILSAFE:
            self.emergencies += 1
            log.warning("LL board: serial line silent for %.2f s: emergency procedure "
                        "(hold %g s, then land)", self.settings.serial_timeout_s,
                        self.settings.wait_before_landing_s)
        if before is NavState.FAILSAFE and after is NavState.LANDING:
            self._emergency_landing = True
            log.warning("LL board: no serial input for the wait: landing")
        if after is NavState.LANDED:
            self._emergency_landing = False

    def _switch_shown(self, replies: list[Message]) -> list[Message]:
        if self.serial_switch:
            return replies
        out: list[Message] = []
        for msg in replies:
            if isinstance(msg, RcData):
                channels = list(msg.channels_in)
                channels[SWITCH_CHANNEL] = 0
                msg = replace(msg, channels_in=tuple(channels), channels_out=tuple(channels))
            out.append(msg)
        return out


ACK_PD: dict[type[Message], PD] = {
    CtrlInput: PD.CTRL_INPUT,
    Waypoint: PD.WAYPOINT,
    WaypointGoto: PD.WAYPOINT_GOTO,
    Launch: PD.LAUNCH,
    EndFlight: PD.END_FLIGHT,
    ComeHome: PD.COME_HOME,
}
