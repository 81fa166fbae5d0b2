"""Requests from the gateway to the cloud (``thing/product/{gw}/requests``) and their answers
(``…/requests_reply``): e.g. ``flighttask_resource_get``.

Owns the pending table by ``tid``: a request is validated against the contract before it leaves, re-sent
with the *same* tid when unanswered (so a late answer to the first copy still counts), and completed by
exactly one answer: the first reply with its tid; later copies and replies for no pending tid are counted
and dropped. Runs on the event loop. Knows nothing of paho or of what a request is for.
"""

from __future__ import annotations

import asyncio
import logging
import secrets
import uuid
from typing import Any

from pydantic import ValidationError

from gateway.clock import Clock
from gateway.dispatcher import Outbox
from gateway.metrics import Metrics
from schemas import TopicKind, topic
from schemas.registry import Registry

log = logging.getLogger(__name__)

__all__ = ["CloudRequestError", "CloudRequests"]


class CloudRequestError(Exception):
    """No usable answer: unanswered after every attempt, or the request could not be built."""


class CloudRequests:
    def __init__(
        self, *, gateway_sn: str, registry: Registry, outbox: Outbox, clock: Clock, metrics: Metrics
    ) -> None:
        self.gateway_sn = gateway_sn
        self.registry = registry
        self.outbox = outbox
        self.clock = clock
        self.metrics = metrics
        self._pending: dict[str, asyncio.Future[Any]] = {}

    async def request(
        self,
        method: str,
        data: dict[str, Any],
        *,
        bid: str | None = None,
        timeout: float = 3.0,
        attempts: int = 2,
    ) -> Any:
        """Send one request and return the answer's validated ``data`` (its result may be non-zero)."""
        tid = str(uuid.UUID(bytes=secrets.token_bytes(16), version=4))
        try:
            msg = self.registry.build(TopicKind.REQUESTS, method, data, tid=tid, bid=bid or tid,
                                      timestamp=self.clock.time_ms(), gateway=self.gateway_sn)  # fmt: skip
        except (ValidationError, KeyError) as exc:
            raise CloudRequestError(f"{method}: request breaks the contract: {exc}") from None
        raw = msg.model_dump_json().encode()
        fut: asyncio.Future[Any] = asyncio.get_running_loop().create_future()
        self._pending[tid] = fut
        try:
            for _ in range(max(1, attempts)):
                self.outbox.publish(topic(TopicKind.REQUESTS, self.gateway_sn), raw, qos=1)
                self.metrics.inc("requests_published_total", method=method)
                try:
                    return await self.clock.wait_for(asyncio.shield(fut), timeout)
                except TimeoutError:
                    continue
            self.metrics.inc("requests_unanswered_total", method=method)
            raise CloudRequestError(f"{method}: the cloud did not answer")
        finally:
            self._pending.pop(tid, None)

    def answer(self, msg: Any) -> None:
        """A validated requests_reply (the dispatcher's): completes the request with its tid, once."""
        fut = self._pending.get(msg.tid)
        if fut is None or fut.done():
            self.metrics.inc("inbound_rejected_total", reason="requests_reply_unmatched")
            log.info("ignored a %s answer for no pending request", msg.method)
            return
        fut.set_result(msg.data)
