"""``data`` of cloud-control authorisation, as DJI documents it for the RC Plus 2 and the RC Pro
(DJI Pilot 2, "DRC" page: ``cloud_control_auth_request``, ``cloud_control_release`` and the
``cloud_control_auth_notify`` event; docs/cloud-api.md names the pages and the copies read).

Owns the request (who asks, for which control keys), the release, their replies, and the notify event
(``output.status``: ``ok`` the operator agreed, ``failed`` denied or no answer, ``canceled`` another
user's request replaced this one). Knows nothing of who decides or how (gateway/control_auth.py).
"""

from __future__ import annotations

import enum
from typing import Annotated, Literal

from pydantic import Field, StringConstraints

from .base import InboundModel, OutboundModel, Reason
from .results import ResultValue

__all__ = [
    "AuthStatus",
    "CloudControlAuthNotify",
    "CloudControlAuthRequest",
    "CloudControlRelease",
    "CloudControlReply",
    "ControlKey",
]

#: The only control key DJI's pages define ("flight": flight control authority); a request for
#: anything else is refused by the contract (325001), never granted in part.
ControlKey = Literal["flight"]

#: A user id or call sign as a cloud sends it: text, at least one character (the page: "length": "").
UserText = Annotated[str, StringConstraints(strict=True, min_length=1, max_length=128)]

_KEYS = 'The control keys: DJI defines "flight" (flight control authority) only, one key ("size": 1).'


class AuthStatus(enum.StrEnum):
    """``cloud_control_auth_notify`` ``output.status`` (DJI: RC Plus 2 § Authorization result)."""

    OK = "ok"  # the user (here: the operator or the allow-list) agreed
    FAILED = "failed"  # an error, or the user denied (here also: no answer in time)
    CANCELED = "canceled"  # another user's request replaced this one


class CloudControlAuthRequest(InboundModel):
    """Ask for cloud control (RC Plus 2 / RC Pro § Request cloud control authorization): the RC shows a
    pop-up naming the cloud user; here the gateway's allow-list or its operator answers, and the outcome
    comes later as ``cloud_control_auth_notify``."""

    user_id: UserText = Field(description="The cloud user asking (the allow-list matches it).")
    user_callsign: UserText = Field(description="The cloud user's nickname, shown to the operator.")
    control_keys: list[ControlKey] = Field(min_length=1, max_length=1, description=_KEYS)


class CloudControlRelease(InboundModel):
    """Give cloud control back (RC Plus 2 / RC Pro § Release cloud control)."""

    control_keys: list[ControlKey] = Field(min_length=1, max_length=1, description=_KEYS)


class ReplyOutput(OutboundModel):
    """``output`` of the replies: DJI's examples show ``{"status": "ok"}`` with result 0; a refusal says
    why."""

    status: Literal["ok"] | None = Field(default=None, description='"ok": the request was taken in.')
    reason: Reason | None = Field(default=None, description="Why the request failed, for a human.")


class CloudControlReply(OutboundModel):
    """Reply to ``cloud_control_auth_request`` and ``cloud_control_release``: ``result`` 0 means the
    request was taken in (for a request: the decision follows in ``cloud_control_auth_notify``)."""

    result: ResultValue
    output: ReplyOutput | None = None


class NotifyOutput(OutboundModel):
    status: AuthStatus = Field(
        description="ok: the user agreed; failed: error or the user denied (here also: no answer in "
        "time); canceled: another user's authorisation request replaced this one."
    )


class CloudControlAuthNotify(OutboundModel):
    """The outcome of a ``cloud_control_auth_request`` (RC Plus 2 / RC Pro § Authorization result
    notification), on ``events`` with ``need_reply`` 0 as DJI's example; its ``bid`` is the request's."""

    result: ResultValue
    output: NotifyOutput
