"""The frame inspector: what crossed each device link, kept bounded, decoded by the CLI's own decoders.

Owns :class:`FrameTap`, the observer a link calls from its threads for every CAN frame or serial chunk
it receives and every one it sends (one ``deque.append``: thread-safe, O(1), bounded); and
:class:`LinkInspector`, which turns a tap's records into protocol frames (each direction, and on CAN each
id, is one byte stream cut by the family's own :class:`~adapters.wire.stream.FrameRules`) and describes
each frame with the family's describe module (:mod:`adapters.families`: ``frame_rules``, ``options_for``,
``REPLY_OPTION``/``REPLY_FLAG``) — the code behind ``dji-gateway decode``, so the page
and the command line never disagree. A reply is described against the command with the same seq sent
before it (``reply_to`` / ``ack_command``), as the CLI does within one input. Downloads: a candump log of
the CAN frames (``dji-gateway decode rsdk`` reads it back) or one frame per line as hex (serial).

Memory is bounded: a tap keeps its last ``keep`` records, an inspector its last ``keep`` frames, a
half-received frame at most one frame. Records a slow reader missed are counted as a gap and the
streams restart. Decoding runs where :meth:`LinkInspector.poll` is called (the web server's thread, in
small slices), never in a link's thread nor on the gateway's loop; a live view decodes at most the
newest records of a flood (``catch_up``), so a busy link cannot make the console hold the interpreter
lock for long while the gateway answers the cloud.

Must not know HTTP, the page, the adapters' internals, or any frame layout (the families' rules and
describe modules know them).
"""

from __future__ import annotations

import itertools
import threading
from collections import deque
from collections.abc import Iterable, Mapping
from types import ModuleType
from typing import Any

from adapters import families
from adapters.wire.stream import BadFrame, FrameRules, StreamDecoder
from gateway.clock import SYSTEM_CLOCK, Clock
from gateway.jsonsafe import json_safe

__all__ = ["FrameTap", "LinkInspector", "Record", "inspectable"]

#: one tap record: (running number, wall time s, "rx" | "tx", CAN id or None, bytes)
Record = tuple[int, float, str, int | None, bytes]


def inspectable(family: str) -> ModuleType | None:
    """The describe module of a registered family whose links the inspector can cut into frames (it
    has ``frame_rules``), or None."""
    try:
        module = families.get(family).describe_module()
    except families.UnknownFamily:
        return None
    return module if module is not None and hasattr(module, "frame_rules") else None


class FrameTap:
    """A link's observer: ``tap(direction, can_id, data)`` from any thread keeps the last ``keep`` records."""

    __slots__ = ("_clock", "_count", "records", "sent")

    def __init__(self, keep: int, clock: Clock = SYSTEM_CLOCK) -> None:
        self.records: deque[Record] = deque(maxlen=keep)
        #: the records sent, kept apart: a device's flood of pushes must not push the gateway's own
        #: commands out before anyone looked (issue #35: the inspector opened after the send shows it)
        self.sent: deque[Record] = deque(maxlen=keep)
        self._count = itertools.count()
        self._clock = clock  # read from the link's threads: a clock's reads are thread-safe

    def __call__(self, direction: str, can_id: int | None, data: bytes) -> None:
        record = (next(self._count), self._clock.time_ms() / 1000, direction, can_id, data)
        self.records.append(record)
        if direction == "tx":
            self.sent.append(record)

    def snapshot(self, sent: bool = False) -> tuple[Record, ...]:
        """The records now held (``sent``: the ones sent), oldest first (a copy: the link's threads keep
        appending)."""
        held = self.sent if sent else self.records
        for _ in range(10):
            try:
                return tuple(held)
            except RuntimeError:  # appended to while copied; the copy is retried
                continue
        return ()


class _RawRules:
    """A family's frame rules that hand back the frame's bytes instead of its parsed form."""

    def __init__(self, rules: FrameRules[Any]) -> None:
        self.sof = rules.sof
        self.header_len = rules.header_len
        self._rules = rules

    def frame_length(self, header: bytes) -> int | str:
        return self._rules.frame_length(header)

    def parse(self, frame: bytes) -> bytes | str:
        result = self._rules.parse(frame)
        return result if isinstance(result, str) else frame


class LinkInspector:
    """One device link as the inspector shows it (``kind`` "can" or "serial")."""

    def __init__(
        self,
        *,
        family: str,
        kind: str,
        where: str,
        keep: int,
        options: Mapping[str, Any] | None = None,
        clock: Clock = SYSTEM_CLOCK,
    ) -> None:
        describe = inspectable(family)
        if describe is None:
            raise ValueError(f"no frame inspector for family {family!r}")
        self.family, self.kind, self.where = family, kind, where
        self.options = dict(options or {})
        self.tap = FrameTap(keep, clock)
        self.frames: deque[dict[str, Any]] = deque(maxlen=keep)
        self.gaps = 0  # times records were lost before they were read (the streams restarted)
        self.skipped = 0  # records a live view skipped to catch up with a flood (the downloads keep them)
        self._restarted: set[str] = set()  # directions whose stream restarted after a gap
        self._describe = describe
        #: the describe option naming the command a reply answers, and the record key marking a reply
        self._reply_option: str | None = getattr(describe, "REPLY_OPTION", None)
        self._reply_flag: str | None = getattr(describe, "REPLY_FLAG", None)
        self._streams: dict[tuple[str, int | None], StreamDecoder[bytes]] = {}
        self._sent: dict[Any, str] = {}  # seq of a command sent -> its name (replies are described by it)
        self._last = -1  # the last tap record read (the tap numbers them from 0)
        self._numbers = itertools.count()
        self._lock = threading.Lock()

    # -- decoding -----------------------------------------------------------------------------------
    def poll(self, limit: int | None = None, catch_up: int | None = None) -> list[dict[str, Any]]:
        """Decode the records that arrived since the last call (at most ``limit`` of them; :attr:`behind`
        says whether more wait); returns the new frames, also kept. ``catch_up``: when more than that many
        records wait, the older ones are skipped (counted in :attr:`skipped`): a live view shows the
        newest frames, a flood must not make it decode the past."""
        with self._lock:
            new: list[dict[str, Any]] = []
            held = self.tap.snapshot()
            pending = [r for r in held if r[0] > self._last]
            # what was sent and has left the ring of all records unread (a device's pushes flooded it):
            # decoded from the ring of sent records first, so the gateway's own commands are never lost
            oldest = held[0][0] if held else 0
            lost_sent = [r for r in self.tap.snapshot(sent=True) if self._last < r[0] < oldest]
            if catch_up is not None:
                lost_sent = lost_sent[-catch_up:]
            if catch_up is not None and len(pending) > catch_up:
                self.skipped += len(pending) - catch_up
                pending = pending[-catch_up:]
            for n, t, direction, can_id, data in [*lost_sent, *pending[:limit]]:
                if n != self._last + 1:  # records were dropped (by the tap, or skipped to catch up)
                    self.gaps += 1
                    self._streams.clear()  # a frame may have lost its middle: start again on a SOF
                    self._restarted = {"rx", "tx"}
                self._last = n
                stream = self._streams.get((direction, can_id))
                if stream is None:
                    rules = _RawRules(self._describe.frame_rules(self.options))
                    stream = self._streams[(direction, can_id)] = StreamDecoder(rules)
                for item in stream.feed(data):
                    if direction in self._restarted and isinstance(item, BadFrame):
                        continue  # the tail of a frame whose start was skipped: not the link's fault
                    self._restarted.discard(direction)
                    record = self._describe_one(item, direction)
                    record.update(n=next(self._numbers), t=round(t, 6), dir=direction, can_id=can_id)
                    self.frames.append(record)
                    new.append(record)
            return new

    @property
    def behind(self) -> bool:
        """Records wait that :meth:`poll` has not read yet."""
        records = self.tap.records
        try:
            return bool(records) and records[-1][0] > self._last
        except IndexError:
            return False

    def _describe_one(self, item: bytes | BadFrame, direction: str) -> dict[str, Any]:
        if isinstance(item, BadFrame):
            return {
                "protocol": self.family,
                "valid": False,
                "command": None,
                "fields": None,
                "error": item.reason,
                "hex": item.raw.hex(),
            }
        options = self.options
        record = self._describe.decode_bytes(item, **options)[0]
        flag, option = self._reply_flag, self._reply_option
        if flag is not None and option is not None:
            key = record.get("seq")
            if direction == "tx" and not record.get(flag) and record.get("command"):
                self._sent[key] = str(record["command"])
                if len(self._sent) > 512:
                    self._sent.pop(next(iter(self._sent)))
            elif direction == "rx" and record.get(flag) and key in self._sent:
                answered = {**options, option: self._sent[key]}
                record = self._describe.decode_bytes(item, **answered)[0]
        record = dict(json_safe(record))
        record["hex"] = item.hex()
        return record

    # -- downloads ------------------------------------------------------------------------------------
    def candump(self, directions: Iterable[str] = ("rx", "tx")) -> str:
        """The CAN frames held, as a ``candump -l`` log (``(time) channel ID#DATA``)."""
        want = set(directions)
        channel = "".join(ch for ch in self.where if not ch.isspace()) or "can0"
        lines = [
            f"({t:.6f}) {channel} {can_id:03X}#{data.hex().upper()}"
            for _n, t, direction, can_id, data in self.tap.snapshot()
            if direction in want and can_id is not None
        ]
        return "\n".join(lines) + ("\n" if lines else "")

    def hex_lines(self, directions: Iterable[str] = ("rx", "tx")) -> str:
        """The frames held, one per line as hex (``dji-gateway decode <family> -`` reads it back)."""
        self.poll()
        want = set(directions)
        lines = [f["hex"].upper() for f in list(self.frames) if f["dir"] in want and f.get("valid")]
        return "\n".join(lines) + ("\n" if lines else "")
