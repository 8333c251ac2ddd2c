"""The message bus between mated connectors: synchronous rounds, or an unreliable asynchronous network.

Time advances in ticks (one tick = one round of the agents). A ``Channel`` carries one kind of fixed-width
payload over every link of the robot; each link is a directed (module, connector) -> (partner module, partner
connector) pair, and a payload is addressed by its sending connector only (connectors are point to point).

* ``BusConfig(mode="sync")`` (default): every message sent at tick t is delivered at tick t + 1, intact,
  exactly once, in order. No acknowledgements are needed.
* ``BusConfig(mode="async", ...)``: each transmission is lost with probability ``loss``, otherwise delivered
  after a delay drawn uniformly from ``delay_min..delay_max`` ticks and, with probability ``duplication``, a
  second copy with its own delay; messages due at the same tick are delivered in a random order. Different
  delays reorder messages on a link. Every transmission draws four uniforms (loss, duplication, the two
  copies' delays) and every delivered message one (its place in the order), a chunk of ``DRAW_CHUNK`` at a
  time. By default all draws come from the generator the network hands the channels (seeded with
  ``seed``); with ``streams``, consecutive groups of modules that share no link (e.g. the separate robots of
  a batch of runs) draw from generators of their own, seeded with the group's seed, so what one group's
  messages go through does not depend on the other groups. Reliability on top: every data message carries
  a per-link sequence number; the receiver keeps only a message newer than the newest it accepted on that
  connector (so duplicates and overtaken messages are ignored) and acknowledges every data message it
  receives (acknowledgements travel through the same unreliable network); the sender retransmits its
  latest payload every ``retransmit_after`` ticks until that payload's sequence number is acknowledged. So once
  losses stop, every link ends with its latest payload delivered, and the network falls silent.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, cast

import numpy as np

from legkit._validation import integer, is_integer

MODES = ("sync", "async")


@dataclass(frozen=True)
class BusConfig:
    """Network behaviour (see the module docstring). Delays are in ticks, probabilities in [0, 1]."""

    mode: str = "sync"
    delay_min: int = 1
    delay_max: int = 1
    loss: float = 0.0
    duplication: float = 0.0
    retransmit_after: int = 8
    seed: int = 0
    #: (modules, seed) per group of consecutive modules, covering the network; empty: one generator for all.
    streams: tuple[tuple[int, int], ...] = ()

    def __post_init__(self) -> None:
        if self.mode not in MODES:
            raise ValueError(f"mode: must be one of {MODES}, got {self.mode!r}")
        for name in ("delay_min", "delay_max", "retransmit_after", "seed"):
            integer(getattr(self, name), name)
        if self.delay_min < 1 or self.delay_max < self.delay_min:
            raise ValueError(f"delay_min, delay_max: need 1 <= delay_min <= delay_max, got {self.delay_min}, {self.delay_max}")
        if self.retransmit_after < 1:
            raise ValueError(f"retransmit_after: must be >= 1, got {self.retransmit_after}")
        for name in ("loss", "duplication"):
            value = getattr(self, name)
            if not (isinstance(value, (int, float)) and 0.0 <= value < 1.0):
                raise ValueError(f"{name}: must be a probability in [0, 1), got {value!r}")
        if self.mode == "sync" and (self.delay_max != 1 or self.loss or self.duplication):
            raise ValueError("mode: 'sync' is reliable with a delay of one tick; use mode='async' for delay, loss or duplication")
        object.__setattr__(self, "streams", _checked_streams(self.streams))


def _checked_streams(streams: Any) -> tuple[tuple[int, int], ...]:
    """``streams`` as a tuple of (modules >= 1, seed >= 0) int pairs; TypeError/ValueError naming ``streams``."""
    try:
        pairs = [tuple(pair) for pair in streams]
    except TypeError:
        raise TypeError(f"streams: must be a sequence of (modules, seed) pairs, got {streams!r}") from None
    for k, pair in enumerate(pairs):
        if len(pair) != 2 or not all(is_integer(v) for v in pair):
            raise TypeError(f"streams[{k}]: must be a (modules, seed) pair of ints, got {pair!r}")
        if pair[0] < 1 or pair[1] < 0:
            raise ValueError(f"streams[{k}]: need modules >= 1 and seed >= 0, got {pair!r}")
    return tuple((int(m), int(seed)) for m, seed in pairs)


class Channel:
    """One kind of payload (``width`` floats) on every link; see the module docstring.

    ``partner`` / ``partner_slot`` (N, S) give the module and connector mated to each connector (-1: free).
    Counters: ``transmissions`` (data messages put on the wire, including retransmissions; per sending module
    in ``sent_by_module``), ``acknowledgements``, ``retransmissions``, ``lost``, ``duplicated``.

    ``rng`` is the network's generator: the asynchronous channel draws from it, or with ``config.streams``
    seeds its streams' generators from it. The streams cannot change afterwards (``config`` may otherwise).

    Internally a connector is addressed by its link number ``module * S + slot``, so that the per-connector
    state is read and written with one flat index per message.
    """

    def __init__(self, partner: np.ndarray, partner_slot: np.ndarray, width: int, config: BusConfig, rng: np.random.Generator):
        self.partner = partner
        self.partner_slot = partner_slot
        self._config = config
        self.reliable = config.mode == "sync"
        shape = partner.shape
        self.width = width
        self.has_sent = np.zeros(shape, dtype=bool)
        self.last_sent = np.zeros(shape + (width,))
        self.seq_out = np.zeros(shape, dtype=np.int64)
        self.seq_in = np.zeros(shape, dtype=np.int64)
        self.unacked = np.zeros(shape, dtype=bool)
        self.last_transmission = np.zeros(shape, dtype=np.int64)
        self._slots = shape[1]
        self._partner_link = np.where(partner >= 0, partner * self._slots + partner_slot, -1).ravel()
        # The per-connector state by link number (views).
        self._has_sent = self.has_sent.reshape(-1)
        self._last_sent = self.last_sent.reshape(-1, width)
        self._seq_out = self.seq_out.reshape(-1)
        self._seq_in = self.seq_in.reshape(-1)
        self._unacked = self.unacked.reshape(-1)
        self._last_transmission = self.last_transmission.reshape(-1)
        # In-flight messages: due tick, sending link, sequence number, is-ack flag, payload.
        self._due = np.zeros(0, dtype=np.int64)
        self._link = np.zeros(0, dtype=np.int64)
        self._seq = np.zeros(0, dtype=np.int64)
        self._ack = np.zeros(0, dtype=bool)
        self._payload = np.zeros((0, width))
        self.transmissions = 0
        self.sent_by_module = np.zeros(shape[0], dtype=np.int64)
        self.acknowledgements = 0
        self.retransmissions = 0
        self.lost = 0
        self.duplicated = 0
        self._draws = _Draws(*_stream_generators(partner, config.streams, rng), shape[1])

    @property
    def config(self) -> BusConfig:
        return self._config

    @config.setter
    def config(self, config: BusConfig) -> None:
        if config.streams != self._config.streams:
            raise ValueError("bus: the streams cannot change once the channel exists")
        self._config = config

    @property
    def in_flight(self) -> int:
        """Messages (data and acknowledgements) currently on the wire."""
        return int(self._due.size)

    @property
    def idle(self) -> bool:
        """True when nothing is on the wire and every payload sent has been acknowledged."""
        return self.in_flight == 0 and not self.unacked.any()

    def send_changed(self, now: int, modules: np.ndarray, slots: np.ndarray, payloads: np.ndarray) -> int:
        """Send ``payloads[k]`` on connector ``slots[k]`` of module ``modules[k]`` where it differs (bitwise) from
        the last payload sent there, or nothing was sent there yet; returns the number sent. The connectors
        must be connected; ``payloads`` is (k, width)."""
        return self._send_changed(now, np.asarray(modules) * self._slots + np.asarray(slots), np.array(payloads, dtype=float))

    def _send_changed(self, now: int, links: np.ndarray, payloads: np.ndarray) -> int:
        """``send_changed`` by link number (distinct links). Takes ownership of ``links`` and ``payloads``: they
        may go on the wire as they are."""
        changed = _rows_differ(payloads, self._last_sent.take(links, axis=0))
        changed |= ~self._has_sent.take(links)
        if not changed.all():
            links, payloads = links[changed], payloads[changed]
        if links.size == 0:
            return 0
        self._has_sent[links] = True
        self._last_sent[links] = payloads
        seq = self._seq_out.take(links)
        seq += 1
        self._seq_out[links] = seq
        if not self.reliable:
            self._unacked[links] = True
        self._last_transmission[links] = now
        self._transmit(now, links, seq, payloads, acks=False)
        return int(links.size)

    def retransmit(self, now: int) -> int:
        """Asynchronous mode: resend every unacknowledged payload whose last transmission is ``retransmit_after``
        ticks old; returns the number resent."""
        if self.reliable:
            return 0
        due = self.unacked & (now - self.last_transmission >= self.config.retransmit_after)
        links = np.flatnonzero(due)
        if links.size:
            self._last_transmission[links] = now
            self.retransmissions += int(links.size)
            self._transmit(now, links, self._seq_out[links], self._last_sent[links], acks=False)
        return int(links.size)

    def _transmit(self, now: int, links: np.ndarray, seq: np.ndarray, payload: np.ndarray, acks: bool) -> None:
        count = links.size
        if acks:
            self.acknowledgements += count
        else:
            self.transmissions += count
            self.sent_by_module += np.bincount(links // self._slots, minlength=self.sent_by_module.size)
        if self.reliable:
            due = np.full(count, now + 1, dtype=np.int64)
        else:
            config = self.config
            draws = self._draws(links, 4)  # loss, duplication, delay of the message, delay of its copy
            keep = draws[:, 0] >= config.loss
            extra = keep & (draws[:, 1] < config.duplication)
            self.lost += int(count - keep.sum())
            self.duplicated += int(extra.sum())
            delays = config.delay_min + (draws[:, 2:] * (config.delay_max - config.delay_min + 1)).astype(np.int64)
            copies = np.concatenate([np.flatnonzero(keep), np.flatnonzero(extra)])
            links, seq, payload = links[copies], seq[copies], payload[copies]
            due = now + np.concatenate([delays[keep, 0], delays[extra, 1]])
        ack = np.full(links.size, acks)
        if self._due.size:
            self._due = np.concatenate([self._due, due])
            self._link = np.concatenate([self._link, links])
            self._seq = np.concatenate([self._seq, seq])
            self._ack = np.concatenate([self._ack, ack])
            self._payload = np.concatenate([self._payload, payload])
        else:  # nothing on the wire (every synchronous round): the arrays are this call's own
            self._due, self._link, self._seq, self._ack, self._payload = due, links, seq, ack, payload

    def deliver(self, now: int) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """Deliver the messages due by tick ``now``.

        Returns the accepted data messages as (receiving module, receiving connector, sending module, sending
        connector, payload (k, width)), at most one per receiving connector (the newest). Acknowledgements are
        consumed here."""
        receivers, senders, payload = self._deliver(now)
        order = np.argsort(receivers, kind="stable")
        receivers, senders, payload = receivers[order], senders[order], payload[order]
        return receivers // self._slots, receivers % self._slots, senders // self._slots, senders % self._slots, payload

    def _deliver(self, now: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """``deliver`` by link number: (receiving links, sending links, payloads), one per receiving link, in no
        particular order."""
        ready = self._due <= now
        if not ready.any():
            empty = np.zeros(0, dtype=np.int64)
            return empty, empty, np.zeros((0, self.width))
        if self.reliable and ready.all():  # the usual synchronous round: everything on the wire arrives
            link, seq, payload = self._link, self._seq, self._payload
            self._due, self._link, self._seq, self._ack = self._due[:0], self._link[:0], self._seq[:0], self._ack[:0]
            self._payload = self._payload[:0]
            receiver = self._partner_link.take(link)
            if np.bincount(receiver).max() == 1:  # one message per connector: nothing to choose between
                newer = seq > self._seq_in.take(receiver)
                if not newer.all():
                    receiver, link, seq, payload = receiver[newer], link[newer], seq[newer], payload[newer]
                self._seq_in[receiver] = seq
                return receiver, link, payload
        else:
            index = np.flatnonzero(ready)
            if not self.reliable:  # a random order: by a uniform draw per message
                index = index[np.argsort(self._draws(self._link.take(index), 1)[:, 0])]
            link, seq, ack, payload = self._link[index], self._seq[index], self._ack[index], self._payload[index]
            waiting = ~ready
            self._due, self._link, self._seq, self._ack = self._due[waiting], self._link[waiting], self._seq[waiting], self._ack[waiting]
            self._payload = self._payload[waiting]
            receiver = self._partner_link.take(link)

        if not self.reliable:
            # Acknowledgements: the receiver of an ack is the original sender.
            acked = ack & (seq == self._seq_out.take(receiver))
            self._unacked[receiver[acked]] = False
            data = np.flatnonzero(~ack)
            if data.size:
                self._transmit(now, receiver[data], seq[data], np.zeros((data.size, self.width)), acks=True)
            receiver, link, seq, payload = receiver[data], link[data], seq[data], payload[data]
        # Keep, per receiving connector, the newest message, and only if newer than what was accepted before.
        order = np.lexsort((seq, receiver))
        receiver, link, seq = receiver[order], link[order], seq[order]
        last_of_group = np.ones(receiver.size, dtype=bool)
        last_of_group[:-1] = receiver[1:] != receiver[:-1]
        newer = last_of_group & (seq > self._seq_in.take(receiver))
        keep = order[newer]
        receiver, link = receiver[newer], link[newer]
        self._seq_in[receiver] = seq[newer]
        return receiver, link, payload[keep]


def _rows_differ(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """(k,) True where row k of ``a`` and ``b`` (k, w) differ anywhere (``!=``: -0.0 equals +0.0)."""
    # Reduced component-major: numpy reduces a few long rows much faster than many short ones.
    differs = np.not_equal(a.T, b.T)
    # numpy's stubs type any(axis=0) as a scalar or an array; over an axis of a 2-D array it is the (k,) array.
    return cast(np.ndarray, np.ascontiguousarray(differs).any(axis=0))


DRAW_CHUNK = 4096  # uniforms drawn from a stream's generator at a time


def _stream_generators(
    partner: np.ndarray, streams: tuple[tuple[int, int], ...], rng: np.random.Generator
) -> tuple[np.ndarray, list[np.random.Generator]]:
    """Each module's stream (N,) and the streams' generators: ``rng`` alone without ``streams``; else one per
    stream, seeded with its seed and a salt drawn from ``rng`` (so the channels of one network, which share
    ``rng``, draw differently, and equally in every network of the same ``BusConfig.seed``). ValueError
    naming ``bus`` if the streams do not cover the modules or a link joins two streams."""
    n = partner.shape[0]
    if not streams:
        return np.zeros(n, dtype=np.int64), [rng]
    sizes = [modules for modules, _ in streams]
    if sum(sizes) != n:
        raise ValueError(f"bus: streams cover {sum(sizes)} modules, the network has {n}")
    stream = np.repeat(np.arange(len(sizes)), sizes)
    module, _ = np.nonzero(partner >= 0)
    crossing = stream[module] != stream[partner[partner >= 0]]
    if crossing.any():
        k = int(np.flatnonzero(crossing)[0])
        raise ValueError(f"bus: streams: modules {module[k]} and {partner[partner >= 0][k]} are linked but in different streams")
    salt = int(rng.integers(2**63))
    return stream, [np.random.default_rng([seed, salt]) for _, seed in streams]


class _Draws:
    """Uniform draws in [0, 1) for messages, each from the generator of its sending link's stream.

    A call ``draws(links, width)`` gives message k the next ``width`` uniforms of its stream, messages of a
    stream in the order they come in ``links``; so a stream's messages get the same numbers whatever the
    other streams' messages in the same call. Each stream keeps a buffer of its generator's next uniforms,
    refilled ``DRAW_CHUNK`` at a time (a loop over the streams that ran out, never over messages)."""

    def __init__(self, stream_of_module: np.ndarray, generators: list[np.random.Generator], slots: int):
        self._stream_of_link = np.repeat(stream_of_module, slots)
        self._generators = generators
        self._buffer = np.zeros((len(generators), DRAW_CHUNK))
        self._used = np.full(len(generators), DRAW_CHUNK)  # uniforms of each buffer row already handed out

    def __call__(self, links: np.ndarray, width: int) -> np.ndarray:
        if len(self._generators) == 1:  # one stream: the next uniforms in order
            needed = links.size * width
            self._refill(np.array([needed]), np.zeros(1, dtype=np.int64))
            start = self._used[0]
            self._used[0] += needed
            return self._buffer[0, start:start + needed].reshape(links.size, width)
        stream = self._stream_of_link.take(links)
        messages = np.bincount(stream, minlength=len(self._generators))
        self._refill(messages * width, np.flatnonzero(messages))
        # Each message's rank among its stream's messages in this call (a stable sort keeps their order).
        order = np.argsort(stream, kind="stable")
        rank = np.empty(links.size, dtype=np.int64)
        rank[order] = np.arange(links.size) - np.repeat(np.cumsum(messages) - messages, messages)
        start = self._used.take(stream) + rank * width
        self._used += messages * width
        return self._buffer[stream[:, None], start[:, None] + np.arange(width)]

    def _refill(self, needed: np.ndarray, streams: np.ndarray) -> None:
        """Make ``needed[s]`` unread uniforms available in the buffer of each stream s of ``streams``, keeping the
        unread ones first (so a stream's numbers are its generator's sequence however they are chunked)."""
        filled = self._buffer.shape[1]
        short = streams[self._used[streams] + needed[streams] > filled]
        if short.size == 0:
            return
        columns = max(DRAW_CHUNK, int(needed.max()))
        if columns > filled:  # a burst larger than a buffer: widen them all, refill them all
            self._buffer = np.pad(self._buffer, ((0, 0), (0, columns - filled)))
            short = np.arange(len(self._generators))
        for s in short:
            unread = self._buffer[s, self._used[s]:filled].copy()
            self._buffer[s, :unread.size] = unread
            self._buffer[s, unread.size:] = self._generators[s].random(self._buffer.shape[1] - unread.size)
            self._used[s] = 0
