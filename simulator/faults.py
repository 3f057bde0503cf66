"""Faults on demand: scheduled in the scenario or commanded at run time.

Kinds (``FaultSpec``): ``drop`` (close every client connection), ``stall`` (stop answering),
``exception`` (Modbus exception responses), ``nan`` (serve NaN), ``bad`` (OPC UA status Bad;
NaN over Modbus), ``restart`` (servers down for a while, then up again).

Scheduled faults start at a *simulated* second (``at_s``); every duration is in *wall-clock*
seconds, because the faults act on connections, which live in wall time.

Run-time control: the admin interface (one command per line on a local TCP port, answered by
one line) and POSIX signals (SIGUSR1 = drop connections, SIGUSR2 = restart for 5 s)::

    status                        -> JSON: simulated time, steps, lag, active faults
    drop [modbus|opcua|both]
    stall SECONDS [modbus|opcua|both]
    exception CODE SECONDS        (Modbus exception code 1-11, 4 = device failure)
    nan SECONDS [LOOP [SIGNAL]]
    bad SECONDS [LOOP [SIGNAL]]
    restart SECONDS [modbus|opcua|both]
    clear                         (end every active fault)
    tune LOOP KC TI_S             (the loop's PI from now on: Kc in % of travel per % of
                                   span, negative for direct action; Ti in seconds)
"""

from __future__ import annotations

import asyncio
import json
import math
import time
from collections.abc import Callable
from dataclasses import dataclass, field

from plantcheck.simulator.scenario import SIGNALS, FaultSpec


@dataclass
class ActiveFault:
    """A fault in force until ``until`` (``time.monotonic()`` seconds)."""

    kind: str
    target: str
    until: float
    loop: str = ""
    signal: str = ""
    code: int = 4

    def hits(self, target: str) -> bool:
        return self.target in (target, "both")


@dataclass
class FaultState:
    """Active faults and the scheduled ones still to come; one-shot actions are handed to
    ``on_action`` (``drop`` / ``restart`` with their fault) when they start."""

    scheduled: list[FaultSpec] = field(default_factory=list)
    active: list[ActiveFault] = field(default_factory=list)
    on_action: Callable[[ActiveFault], None] | None = None

    def __post_init__(self) -> None:
        self.scheduled = sorted(self.scheduled, key=lambda f: f.at_s)

    def start(self, fault: ActiveFault) -> None:
        """Put ``fault`` in force (one-shot kinds are passed to ``on_action``)."""
        self.active.append(fault)
        if fault.kind in ("drop", "restart") and self.on_action:
            self.on_action(fault)

    def update(self, sim_t: float) -> None:
        """Start the scheduled faults due at simulated second ``sim_t``; expire old ones."""
        now = time.monotonic()
        while self.scheduled and self.scheduled[0].at_s <= sim_t:
            f = self.scheduled.pop(0)
            self.start(ActiveFault(f.kind, f.target, now + f.duration_s, f.loop, f.signal, f.code))
        self.active = [f for f in self.active if f.until > now]

    def _live(self, kind: str, target: str) -> list[ActiveFault]:
        now = time.monotonic()
        return [f for f in self.active if f.kind == kind and f.hits(target) and f.until > now]

    def stalled(self, target: str) -> bool:
        return bool(self._live("stall", target))

    def exception_code(self, target: str = "modbus") -> int | None:
        live = self._live("exception", target)
        return live[-1].code if live else None

    def masked(self, kind: str, target: str, loop: str, signal: str) -> bool:
        """Whether ``kind`` (``nan``/``bad``) hits ``loop``'s ``signal`` on ``target``."""
        return any(
            (not f.loop or f.loop == loop) and (not f.signal or f.signal == signal)
            for f in self._live(kind, target)
        )

    def clear(self) -> None:
        self.active.clear()

    def describe(self) -> list[dict[str, object]]:
        now = time.monotonic()
        return [
            {
                "kind": f.kind,
                "target": f.target,
                "remaining_s": round(f.until - now, 1),
                "loop": f.loop,
                "signal": f.signal,
            }
            for f in self.active
            if f.until > now
        ]


class AdminError(ValueError):
    """A malformed admin command (the message says what is expected)."""


@dataclass(frozen=True)
class Retune:
    """``tune LOOP KC TI_S``: new PI settings for one loop (issue 48: a proposal applied)."""

    loop: str
    Kc: float
    Ti_s: float


_TARGETS = ("modbus", "opcua", "both")


def _seconds(word: str) -> float:
    try:
        v = float(word)
    except ValueError:
        raise AdminError(f"expected a number of seconds, got {word!r}") from None
    if not 0 <= v <= 86_400:
        raise AdminError("seconds must be within 0..86400")
    return v


def parse_command(line: str, loops: set[str]) -> ActiveFault | Retune | str:
    """An admin command line → the fault to start, the retuning, or ``"status"`` /
    ``"clear"``."""
    words = line.split()
    if not words:
        raise AdminError("empty command; try: status, drop, stall, exception, nan, bad, restart")
    cmd, args = words[0].lower(), words[1:]
    now = time.monotonic()
    if cmd in ("status", "clear"):
        return cmd
    if cmd == "drop":
        target = args[0] if args else "both"
        if target not in _TARGETS:
            raise AdminError(f"target must be one of {', '.join(_TARGETS)}")
        return ActiveFault("drop", target, now + 0.5)
    if cmd in ("stall", "restart"):
        if not args:
            raise AdminError(f"usage: {cmd} SECONDS [modbus|opcua|both]")
        target = args[1] if len(args) > 1 else "both"
        if target not in _TARGETS:
            raise AdminError(f"target must be one of {', '.join(_TARGETS)}")
        return ActiveFault(cmd, target, now + _seconds(args[0]))
    if cmd == "exception":
        if len(args) != 2 or not args[0].isdigit() or not 1 <= int(args[0]) <= 11:
            raise AdminError("usage: exception CODE SECONDS (CODE 1..11)")
        return ActiveFault("exception", "modbus", now + _seconds(args[1]), code=int(args[0]))
    if cmd in ("nan", "bad"):
        if not args:
            raise AdminError(f"usage: {cmd} SECONDS [LOOP [SIGNAL]]")
        loop = args[1] if len(args) > 1 else ""
        signal = args[2] if len(args) > 2 else ""
        if loop and loop not in loops:
            raise AdminError(f"unknown loop {loop!r}")
        if signal and signal not in SIGNALS:
            raise AdminError(f"signal must be one of {', '.join(SIGNALS)}")
        return ActiveFault(cmd, "both", now + _seconds(args[0]), loop, signal)
    if cmd == "tune":
        if len(args) != 3:
            raise AdminError("usage: tune LOOP KC TI_S")
        if args[0] not in loops:
            raise AdminError(f"unknown loop {args[0]!r}")
        try:
            kc, ti = float(args[1]), float(args[2])
        except ValueError:
            raise AdminError("KC and TI_S must be numbers") from None
        if not (math.isfinite(kc) and kc != 0 and math.isfinite(ti) and ti > 0):
            raise AdminError("KC must be a non-zero number and TI_S a positive one")
        return Retune(args[0], kc, ti)
    raise AdminError(
        f"unknown command {cmd!r}; try: status, drop, stall, exception, nan, bad, tune"
    )


async def serve_admin(
    host: str,
    port: int,
    faults: FaultState,
    loops: set[str],
    status: Callable[[], dict[str, object]],
    retune: Callable[[Retune], None] | None = None,
) -> asyncio.Server:
    """Start the line-oriented admin server (local use only: bind to loopback)."""

    async def handle(reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
        try:
            while line := await reader.readline():
                try:
                    cmd = parse_command(line.decode("utf-8", "replace"), loops)
                    if cmd == "status":
                        reply = json.dumps({**status(), "faults": faults.describe()})
                    elif cmd == "clear":
                        faults.clear()
                        reply = "ok"
                    elif isinstance(cmd, Retune):
                        if retune is None:
                            raise AdminError("this simulator cannot retune")
                        retune(cmd)
                        reply = f"ok tune {cmd.loop} Kc={cmd.Kc:g} Ti_s={cmd.Ti_s:g}"
                    else:
                        assert isinstance(cmd, ActiveFault)
                        faults.start(cmd)
                        reply = f"ok {cmd.kind}"
                except AdminError as exc:
                    reply = f"error: {exc}"
                writer.write(reply.encode() + b"\n")
                await writer.drain()
        except ConnectionError:
            pass
        finally:
            writer.close()

    return await asyncio.start_server(handle, host, port)


async def send_admin(host: str, port: int, command: str, timeout: float = 5.0) -> str:
    """Send one admin command and return the one-line answer."""
    reader, writer = await asyncio.wait_for(asyncio.open_connection(host, port), timeout)
    try:
        writer.write(command.strip().encode() + b"\n")
        await writer.drain()
        line = await asyncio.wait_for(reader.readline(), timeout)
        return line.decode().strip()
    finally:
        writer.close()
