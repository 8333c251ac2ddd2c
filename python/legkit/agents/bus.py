"""The message bus between mated connectors: synchronous rounds, or an unreliable asynchronous network.

Time advances in ticks (one tick = one round of the agents). A ``Channel`` carries one kind of fixed-width
payload over every link of the robot; each link is a directed (module, connector) -> (partner module, partner
connector) pair, and a payload is addressed by its sending connector only (connectors are point to point).

* ``BusConfig(mode="sync")`` (default): every message sent at tick t is delivered at tick t + 1, intact,
  exactly once, in order. No acknowledgements are needed.
* ``BusConfig(mode="async", ...)``: each transmission is lost with probability ``loss``, otherwise delivered
  after a delay drawn uniformly from ``delay_min..delay_max`` ticks and, with probability ``duplication``, a
  second copy with its own delay; messages due at the same tick are delivered in a random order. Different
  delays reorder messages on a link. All draws come from one ``numpy.random.Generator`` seeded with
  ``seed``. Reliability on top: every data message carries a per-link sequence number; the receiver keeps
  only a message newer than the newest it accepted on that connector (so duplicates and overtaken messages
  are ignored) and acknowledges every data message it receives (acknowledgements travel through the same
  unreliable network); the sender retransmits its latest payload every ``retransmit_after`` ticks until
  that payload's sequence number is acknowledged. So once losses stop, every link ends with its latest
  payload delivered, and the network falls silent.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

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

    def __post_init__(self) -> None:
        if self.mode not in MODES:
            raise ValueError(f"mode: must be one of {MODES}, got {self.mode!r}")
        for name in ("delay_min", "delay_max", "retransmit_after", "seed"):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, (int, np.integer)):
                raise TypeError(f"{name}: must be an int, got {type(value).__name__}")
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


class Channel:
    """One kind of payload (``width`` floats) on every link; see the module docstring.

    ``partner`` / ``partner_slot`` (N, S) give the module and connector mated to each connector (-1: free).
    Counters: ``transmissions`` (data messages put on the wire, including retransmissions; per sending module
    in ``sent_by_module``), ``acknowledgements``, ``retransmissions``, ``lost``, ``duplicated``.
    """

    def __init__(self, partner: np.ndarray, partner_slot: np.ndarray, width: int, config: BusConfig, rng: np.random.Generator):
        self.partner = partner
        self.partner_slot = partner_slot
        self.config = config
        self.rng = rng
        self.reliable = config.mode == "sync"
        shape = partner.shape
        self.width = width
        self.has_sent = np.zeros(shape, dtype=bool)
        self.last_sent = np.zeros(shape + (width,))
        self.seq_out = np.zeros(shape, dtype=np.int64)
        self.seq_in = np.zeros(shape, dtype=np.int64)
        self.unacked = np.zeros(shape, dtype=bool)
        self.last_transmission = np.zeros(shape, dtype=np.int64)
        # In-flight messages: due tick, sending module and connector, sequence number, is-ack flag, payload.
        self._due = np.zeros(0, dtype=np.int64)
        self._module = np.zeros(0, dtype=np.int64)
        self._slot = np.zeros(0, dtype=np.int64)
        self._seq = np.zeros(0, dtype=np.int64)
        self._ack = np.zeros(0, dtype=bool)
        self._payload = np.zeros((0, width))
        self.transmissions = 0
        self.sent_by_module = np.zeros(shape[0], dtype=np.int64)
        self.acknowledgements = 0
        self.retransmissions = 0
        self.lost = 0
        self.duplicated = 0

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
        changed = ~self.has_sent[modules, slots] | np.any(payloads != self.last_sent[modules, slots], axis=-1)
        modules, slots, payloads = modules[changed], slots[changed], payloads[changed]
        if modules.size == 0:
            return 0
        self.has_sent[modules, slots] = True
        self.last_sent[modules, slots] = payloads
        self.seq_out[modules, slots] += 1
        self.unacked[modules, slots] = not self.reliable
        self.last_transmission[modules, slots] = now
        self._transmit(now, modules, slots, self.seq_out[modules, slots], payloads, acks=False)
        return int(modules.size)

    def retransmit(self, now: int) -> int:
        """Asynchronous mode: resend every unacknowledged payload whose last transmission is ``retransmit_after``
        ticks old; returns the number resent."""
        if self.reliable:
            return 0
        due = self.unacked & (now - self.last_transmission >= self.config.retransmit_after)
        modules, slots = np.nonzero(due)
        if modules.size:
            self.last_transmission[modules, slots] = now
            self.retransmissions += int(modules.size)
            self._transmit(now, modules, slots, self.seq_out[modules, slots], self.last_sent[modules, slots], acks=False)
        return int(modules.size)

    def _transmit(self, now: int, modules: np.ndarray, slots: np.ndarray, seq: np.ndarray, payload: np.ndarray, acks: bool) -> None:
        count = modules.size
        if acks:
            self.acknowledgements += count
        else:
            self.transmissions += count
            np.add.at(self.sent_by_module, modules, 1)
        if self.reliable:
            due = np.full(count, now + 1, dtype=np.int64)
        else:
            keep = self.rng.random(count) >= self.config.loss
            self.lost += int(count - keep.sum())
            copies = np.flatnonzero(keep)
            extra = copies[self.rng.random(copies.size) < self.config.duplication]
            self.duplicated += int(extra.size)
            copies = np.concatenate([copies, extra])
            modules, slots, seq, payload = modules[copies], slots[copies], seq[copies], payload[copies]
            due = now + self.rng.integers(self.config.delay_min, self.config.delay_max + 1, size=copies.size)
        self._due = np.concatenate([self._due, due])
        self._module = np.concatenate([self._module, modules])
        self._slot = np.concatenate([self._slot, slots])
        self._seq = np.concatenate([self._seq, seq])
        self._ack = np.concatenate([self._ack, np.full(modules.size, acks)])
        self._payload = np.concatenate([self._payload, payload])

    def deliver(self, now: int) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """Deliver the messages due by tick ``now``.

        Returns the accepted data messages as (receiving module, receiving connector, sending module, sending
        connector, payload (k, width)), at most one per receiving connector (the newest). Acknowledgements are
        consumed here."""
        ready = self._due <= now
        if not ready.any():
            empty = np.zeros(0, dtype=np.int64)
            return empty, empty, empty, empty, np.zeros((0, self.width))
        index = np.flatnonzero(ready)
        if not self.reliable:
            index = index[self.rng.permutation(index.size)]
        module, slot, seq, ack, payload = self._module[index], self._slot[index], self._seq[index], self._ack[index], self._payload[index]
        keep = ~ready
        self._due, self._module, self._slot = self._due[keep], self._module[keep], self._slot[keep]
        self._seq, self._ack, self._payload = self._seq[keep], self._ack[keep], self._payload[keep]
        receiver, receiver_slot = self.partner[module, slot], self.partner_slot[module, slot]

        # Acknowledgements: the receiver of an ack is the original sender.
        acked = ack & (seq == self.seq_out[receiver, receiver_slot])
        self.unacked[receiver[acked], receiver_slot[acked]] = False

        data = np.flatnonzero(~ack)
        if not self.reliable and data.size:
            self._transmit(now, receiver[data], receiver_slot[data], seq[data], np.zeros((data.size, self.width)), acks=True)
        # Keep, per receiving connector, the newest message, and only if newer than what was accepted before.
        data = data[np.lexsort((seq[data], receiver_slot[data], receiver[data]))]
        if data.size:
            last_of_group = np.ones(data.size, dtype=bool)
            last_of_group[:-1] = (receiver[data][1:] != receiver[data][:-1]) | (receiver_slot[data][1:] != receiver_slot[data][:-1])
            data = data[last_of_group]
            data = data[seq[data] > self.seq_in[receiver[data], receiver_slot[data]]]
            self.seq_in[receiver[data], receiver_slot[data]] = seq[data]
        return receiver[data], receiver_slot[data], module[data], slot[data], payload[data]
