"""Link fault injection: a seeded model of a bad radio link, applied around any :class:`~sitl_bridge.link.Link`.

A :class:`FaultModel` describes one direction of a link: loss (independent or in Gilbert-Elliott bursts),
latency with jitter, duplication, reordering and outages. :class:`LinkFaults` holds one model per direction
(``up``: client to vehicle, ``down``: vehicle to client) and the seed. :class:`FaultyLink` wraps the vehicle's end
of a link and applies them: what the vehicle sends goes through the ``down`` model, what it receives through the
``up`` model. One packet is one ``send`` call (pymavlink writes one MAVLink message per call, and one UDP datagram
carries one message), so every rate below is per MAVLink message.

Time comes from the clock given to the wrapper: the simulated vehicle's time in lockstep (a memory link), so the
same seed gives the same run bit for bit; seconds since the wrapper was made on the wall clock over UDP. Outage
times are on that clock (in a replay: simulated seconds since the vehicle booted).

The same faults are written on the command line as ``KEY=VALUE`` pairs (:func:`parse_link_faults`), e.g.
``loss=0.1,latency_ms=50,jitter_ms=20,outage=30:2``; a key prefixed ``up.`` or ``down.`` sets one direction only.
"""
from __future__ import annotations

import dataclasses
import heapq
import time
from dataclasses import dataclass, field
from typing import Callable

import numpy as np

from missions.validation import check_fields, check_number
from sitl_bridge.link import Link

DIRECTIONS = ("up", "down")


@dataclass(frozen=True)
class Outage:
    """A window during which the link carries nothing: every packet sent in it is lost."""

    start_s: float
    """When the outage begins, in seconds on the link's clock (a replay: simulated seconds since boot)."""
    duration_s: float
    """How long it lasts (s); a packet sent at ``start_s <= t < start_s + duration_s`` is dropped."""

    def __post_init__(self) -> None:
        check_fields(self, (("start_s", 0.0, 1e7), ("duration_s", 0.0, 1e6)))

    def covers(self, time_s: float) -> bool:
        return self.start_s <= time_s < self.start_s + self.duration_s


@dataclass(frozen=True)
class FaultModel:
    """The faults of one direction of a link. The defaults are a perfect link."""

    loss: float = 0.0
    """Share of packets lost in the long run, in [0, 1)."""
    burst_length: float = 1.0
    """Mean number of packets lost in a row (>= 1). 1: each packet is lost independently with probability
    ``loss``. Above 1: a Gilbert-Elliott channel whose bad state loses every packet and lasts ``burst_length``
    packets on average (leaves with probability 1/burst_length), entered from the good state with the
    probability that makes the long-run loss share ``loss``."""
    latency_ms: float = 0.0
    """Mean one-way delay added to every packet (ms)."""
    jitter_ms: float = 0.0
    """Each delay is ``latency_ms`` plus a uniform draw in [-jitter_ms, +jitter_ms] (never below 0). Jitter keeps
    the packets in order, as a serial radio does (reordering is its own fault): a packet never leaves before one
    sent earlier, so when packets come faster than the jitter's spread their delays bunch up towards the top."""
    duplicate: float = 0.0
    """Probability that a delivered packet arrives twice (the copy right after the original)."""
    reorder: float = 0.0
    """Probability that a delivered packet is held back ``reorder_delay_ms`` beyond its delay, so packets sent
    after it overtake it."""
    reorder_delay_ms: float = 100.0
    """Extra delay of a reordered packet (ms)."""
    outages: tuple[Outage, ...] = ()
    """Windows during which every packet is lost, whatever the other faults."""

    def __post_init__(self) -> None:
        check_fields(self, (("loss", 0.0, 0.99), ("burst_length", 1.0, 1000.0), ("latency_ms", 0.0, 60_000.0),
                            ("jitter_ms", 0.0, 60_000.0), ("duplicate", 0.0, 1.0), ("reorder", 0.0, 1.0),
                            ("reorder_delay_ms", 0.0, 60_000.0)))
        if self.loss > 0 and self.burst_length > 1 and self.loss / (1 - self.loss) / self.burst_length > 1:
            raise ValueError(f"FaultModel.loss {self.loss:g} cannot be reached with burst_length "
                             f"{self.burst_length:g}: lower loss or raise burst_length")

    @property
    def perfect(self) -> bool:
        return self == FaultModel()

    def describe(self) -> str:
        """The non-default fields as ``KEY=VALUE`` pairs (the command-line spelling); "none" for a perfect link."""
        parts = []
        for item in dataclasses.fields(self):
            value = getattr(self, item.name)
            if value == item.default:
                continue
            if item.name == "outages":
                parts += [f"outage={o.start_s:g}:{o.duration_s:g}" for o in value]
            else:
                parts.append(f"{SPEC_NAMES.get(item.name, item.name)}={value:g}")
        return ",".join(parts) or "none"


@dataclass(frozen=True)
class LinkFaults:
    """Faults of both directions of a link and the seed of their random draws."""

    up: FaultModel = field(default_factory=FaultModel)
    """Client (companion computer, ground station) to vehicle: commands and setpoints."""
    down: FaultModel = field(default_factory=FaultModel)
    """Vehicle to client: telemetry, heartbeats, COMMAND_ACKs."""
    seed: int | None = None
    """Seed of the fault draws; None: the run's seed."""

    def __post_init__(self) -> None:
        if self.seed is not None:
            check_number("LinkFaults", "seed", self.seed, 0, 2**32 - 1, integer=True)

    @property
    def perfect(self) -> bool:
        return self.up.perfect and self.down.perfect

    def describe(self) -> str:
        """In words, with the command-line spelling of each direction; "none" for a perfect link."""
        if self.perfect:
            return "none"
        up, down = self.up.describe(), self.down.describe()
        text = f"both ways {up}" if up == down else f"up {up}; down {down}"
        return text + (f"; seed {self.seed}" if self.seed is not None else "")


# ------------------------------------------------------------------------------------------- the command-line spec
SPEC_NAMES = {"burst_length": "burst", "duplicate": "dup"}
"""Short spellings of FaultModel fields on the command line (the field names are accepted too)."""
_SPEC_FIELDS = {SPEC_NAMES.get(f.name, f.name): f.name for f in dataclasses.fields(FaultModel) if f.name != "outages"}
SPEC_HELP = ("comma-separated KEY=VALUE: loss=SHARE, burst=PACKETS, latency_ms=MS, jitter_ms=MS, dup=SHARE, "
             "reorder=SHARE, reorder_delay_ms=MS, outage=START_S:LENGTH_S (repeatable), seed=N; prefix a key "
             "with up. or down. for one direction (e.g. 'loss=0.1,latency_ms=50,jitter_ms=20,outage=30:2')")


def parse_link_faults(text: str, option: str = "--link-faults") -> LinkFaults:
    """``KEY=VALUE,...`` (see :data:`SPEC_HELP`) as :class:`LinkFaults`; a one-line ValueError names the bad part."""
    values: dict[str, dict] = {"up": {}, "down": {}}
    seed = None
    for part in filter(None, (p.strip() for p in text.split(","))):
        key, sep, value = part.partition("=")
        key, value = key.strip().lower(), value.strip()
        prefix, dot, name = key.partition(".")
        directions, name = ((prefix,), name) if dot and prefix in DIRECTIONS else (DIRECTIONS, key)
        if not sep or not value:
            raise ValueError(f"{option}: expected KEY=VALUE, got {part!r}; {SPEC_HELP}")
        if name == "seed" and len(directions) == 2:
            seed = _number(value, option, part, integer=True)
            continue
        if name == "outage":
            start, colon, length = value.partition(":")
            if not colon:
                raise ValueError(f"{option}: outage needs START_S:LENGTH_S (e.g. outage=30:2), got {part!r}")
            parsed = (_number(start, option, part), _number(length, option, part))
            for direction in directions:
                values[direction].setdefault("outages", []).append(parsed)
            continue
        if name not in _SPEC_FIELDS:
            raise ValueError(f"{option}: unknown key {name!r} in {part!r}; known keys: "
                             f"{', '.join([*_SPEC_FIELDS, 'outage', 'seed'])}")
        for direction in directions:
            values[direction][_SPEC_FIELDS[name]] = _number(value, option, part)
    try:
        models = {}
        for direction, fields in values.items():
            outages = tuple(Outage(start, length) for start, length in fields.pop("outages", []))
            models[direction] = FaultModel(**fields, outages=outages)
        return LinkFaults(**models, seed=seed)
    except ValueError as exc:
        raise ValueError(f"{option}: {exc}") from None


def _number(text: str, option: str, part: str, integer: bool = False) -> float:
    try:
        return int(text) if integer else float(text)
    except ValueError:
        kind = "an integer" if integer else "a number"
        raise ValueError(f"{option}: {text!r} in {part!r} is not {kind}") from None


# ------------------------------------------------------------------------------------------- applying the faults
class FaultChannel:
    """One direction of a faulty link: packets go in with :meth:`push`, come out when due with :meth:`pop_due`."""

    def __init__(self, model: FaultModel, rng: np.random.Generator):
        self.model = model
        self.rng = rng
        self.bad_state = False  # Gilbert-Elliott: in a loss burst
        self._queue: list[tuple[float, int, bytes]] = []  # (due time, sequence, packet), a heap
        self._sequence = 0
        self._last_in_order_due = -np.inf
        self.counts = {"sent": 0, "lost": 0, "outage": 0, "duplicated": 0, "reordered": 0, "delivered": 0}

    def _lost(self, draw: float) -> bool:
        model = self.model
        if model.burst_length <= 1.0:
            return draw < model.loss
        leave = 1.0 / model.burst_length
        enter = model.loss * leave / (1.0 - model.loss)  # stationary bad share = enter / (enter + leave) = loss
        self.bad_state = draw >= leave if self.bad_state else draw < enter
        return self.bad_state

    def push(self, data: bytes, now_s: float) -> None:
        """A packet sent at ``now_s``: lose it, or queue it (maybe twice) for its delivery time."""
        model = self.model
        self.counts["sent"] += 1
        # Four draws per packet whatever the faults, so changing one rate never shifts the others' draws.
        loss_draw, jitter_draw, duplicate_draw, reorder_draw = self.rng.random(4)
        lost = self._lost(loss_draw)
        if any(outage.covers(now_s) for outage in model.outages):
            self.counts["outage"] += 1
            return
        if lost:
            self.counts["lost"] += 1
            return
        delay_s = max(0.0, model.latency_ms + (2.0 * jitter_draw - 1.0) * model.jitter_ms) / 1000.0
        due = now_s + delay_s
        if reorder_draw < model.reorder:
            self.counts["reordered"] += 1
            due += model.reorder_delay_ms / 1000.0
        else:
            due = max(due, self._last_in_order_due)  # jitter never reorders
            self._last_in_order_due = due
        copies = 2 if duplicate_draw < model.duplicate else 1
        self.counts["duplicated"] += copies - 1
        for _ in range(copies):
            heapq.heappush(self._queue, (due, self._sequence, data))
            self._sequence += 1

    def pop_due(self, now_s: float) -> list[bytes]:
        """Every queued packet whose delivery time has come, in delivery order."""
        due = []
        while self._queue and self._queue[0][0] <= now_s + 1e-9:
            due.append(heapq.heappop(self._queue)[2])
        self.counts["delivered"] += len(due)
        return due


class FaultyLink:
    """A :class:`Link` (the vehicle's end) whose traffic goes through :class:`LinkFaults`.

    ``send`` puts a packet into the ``down`` channel, ``receive`` takes what the wrapped link received through the
    ``up`` channel; both deliver whatever has become due, so a caller that uses the link every tick (the vehicle
    receives once per physics tick) delivers delayed packets on time to within one tick.
    """

    def __init__(self, link: Link, faults: LinkFaults, clock: Callable[[], float], seed: int = 0):
        """``clock()``: seconds on the run's clock; ``seed`` is used when ``faults.seed`` is None."""
        self.link = link
        self.name = link.name
        self.faults = faults
        self.clock = clock
        seed = faults.seed if faults.seed is not None else seed
        # One independent stream per direction: the downlink's traffic never shifts the uplink's draws.
        self.up = FaultChannel(faults.up, np.random.default_rng([seed, 1]))
        self.down = FaultChannel(faults.down, np.random.default_rng([seed, 2]))

    def _flush_down(self, now_s: float) -> None:
        for data in self.down.pop_due(now_s):
            self.link.send(data)

    def send(self, data: bytes) -> None:
        now = self.clock()
        self.down.push(bytes(data), now)
        self._flush_down(now)

    def receive(self) -> list[bytes]:
        now = self.clock()
        self._flush_down(now)
        for data in self.link.receive():
            self.up.push(data, now)
        return self.up.pop_due(now)

    def close(self) -> None:
        self.link.close()

    def counts(self) -> dict[str, dict[str, int]]:
        """Packets per fate and direction (for reports and benchmarks)."""
        return {"up": dict(self.up.counts), "down": dict(self.down.counts)}


def wall_clock_since_now() -> Callable[[], float]:
    """Seconds on the wall clock since this call: the fault clock of a real-time (UDP) link."""
    start = time.monotonic()
    return lambda: time.monotonic() - start


def apply_faults(links: list[Link], faults: LinkFaults | None, clock: Callable[[], float],
                 seed: int = 0) -> list[Link]:
    """``links`` each wrapped in a :class:`FaultyLink` (seeds ``seed``, ``seed + 1``, ...), or as they are when
    ``faults`` is None or perfect."""
    if faults is None or faults.perfect:
        return list(links)
    return [FaultyLink(link, faults, clock, seed + index) for index, link in enumerate(links)]
