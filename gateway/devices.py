"""The devices behind this gateway and who controls them: routing tables and authority state.

Owns which adapter serves a method (by ``payload_index`` for payload methods, by capability for
the rest) and the flight / payload control authority that ``*_authority_grab`` sets and ``state``
reports. Knows adapters only through :class:`adapters.base.Adapter`; knows nothing of MQTT.
"""

from __future__ import annotations

from collections.abc import Iterable, Iterator
from dataclasses import dataclass, field

from adapters.base import Adapter, Domain

__all__ = ["AuthorityState", "DeviceTable"]


@dataclass
class AuthorityState:
    """Control authority held by this gateway's cloud (source "A"); cleared when a device takes it back."""

    flight: set[str] = field(default_factory=set)  # sn of aircraft whose flight authority is held
    payloads: set[str] = field(default_factory=set)  # payload_index values whose authority is held


class DeviceTable:
    def __init__(self, adapters: Iterable[Adapter]) -> None:
        self._by_sn: dict[str, Adapter] = {}
        self._by_payload: dict[str, Adapter] = {}
        for adapter in adapters:
            if adapter.info.sn in self._by_sn:
                raise ValueError(f"duplicate device sn {adapter.info.sn}")
            self._by_sn[adapter.info.sn] = adapter
            if adapter.info.payload_index:
                self._by_payload[adapter.info.payload_index] = adapter
        self.authority = AuthorityState()

    def __iter__(self) -> Iterator[Adapter]:
        return iter(self._by_sn.values())

    def __len__(self) -> int:
        return len(self._by_sn)

    def by_sn(self, sn: str) -> Adapter | None:
        return self._by_sn.get(sn)

    def by_payload(self, payload_index: str) -> Adapter | None:
        return self._by_payload.get(payload_index)

    def serving(self, method: str) -> list[Adapter]:
        """Adapters that implement ``method``, aircraft first (they own flight methods)."""
        found = [a for a in self._by_sn.values() if a.supports(method)]
        return sorted(found, key=lambda a: a.info.domain != Domain.AIRCRAFT)

    def payload_indexes(self) -> list[str]:
        return sorted(self._by_payload)
