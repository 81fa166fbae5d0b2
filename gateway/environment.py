"""The ``DJIGW_*`` environment, checked: a misspelt variable is warned about (pydantic-settings would
ignore it silently), and a bad value is reported with the variable's name, not only the settings key.

Owns the names: a settings key ``metrics.port`` is the variable ``DJIGW_METRICS__PORT`` (nested with
``__``, case-insensitive as pydantic-settings reads them); the console's and the compose stack's own
variables (:data:`OTHER_VARIABLES`) are known too. Knows nothing of what the settings mean; the settings
model is passed in (no import cycle with ``gateway.settings``).
"""

from __future__ import annotations

import difflib
import os
from collections.abc import Iterable, Mapping
from typing import Any

from pydantic import BaseModel

__all__ = ["OTHER_VARIABLES", "PREFIX", "settings_variables", "unknown_variables", "variable_for"]

PREFIX = "DJIGW_"

#: ``DJIGW_*`` variables that are not settings: the console's (send, monitor, fly, status), the simulators'
#: and the compose stack's (mosquitto's users, written into its password file at start).
OTHER_VARIABLES = frozenset(
    {
        "DJIGW_CONSOLE_BROKER",
        "DJIGW_CONSOLE_USERNAME",
        "DJIGW_CONSOLE_PASSWORD",
        "DJIGW_GATEWAY_SN",
        "DJIGW_SIM_HOST",
        "DJIGW_GATEWAY_USER",
        "DJIGW_GATEWAY_PASSWORD",
        "DJIGW_CLOUD_USER",
        "DJIGW_CLOUD_PASSWORD",
        "DJIGW_MQTT_PORT",
    }
)


def _model(annotation: Any) -> type[BaseModel] | None:
    if isinstance(annotation, type) and issubclass(annotation, BaseModel):
        return annotation
    for arg in getattr(annotation, "__args__", ()) or ():
        found = _model(arg)
        if found is not None:
            return found
    return None


def settings_variables(model: type[BaseModel], prefix: str = PREFIX) -> set[str]:
    """Every variable that sets a key of ``model`` (a nested model's keys, and the model as a whole
    as JSON: ``DJIGW_BROKER='{"url": …}'``); lists (``devices``) only whole, as JSON."""
    names: set[str] = set()
    for name, info in model.model_fields.items():
        var = f"{prefix}{name.upper()}"
        names.add(var)
        nested = _model(info.annotation)
        origin = getattr(info.annotation, "__origin__", None)
        if nested is not None and origin not in (list, tuple):
            names |= settings_variables(nested, var + "__")
    return names


def unknown_variables(
    model: type[BaseModel], environ: Mapping[str, str] | None = None
) -> list[tuple[str, str | None]]:
    """``DJIGW_*`` variables that set nothing: (name, the closest known name or None)."""
    env = os.environ if environ is None else environ
    known = settings_variables(model) | OTHER_VARIABLES
    out = []
    for name in sorted(env):
        upper = name.upper()
        if not upper.startswith(PREFIX) or upper in known:
            continue
        near = difflib.get_close_matches(upper, sorted(known), n=1, cutoff=0.75)
        out.append((name, near[0] if near else None))
    return out


def variable_for(loc: Iterable[Any], environ: Mapping[str, str] | None = None) -> str | None:
    """The variable in the environment that set the key at ``loc`` (``("metrics", "port")`` →
    ``DJIGW_METRICS__PORT``, or the enclosing ``DJIGW_METRICS`` when that was given as JSON)."""
    env = {k.upper(): k for k in (os.environ if environ is None else environ)}
    parts = [str(p).upper() for p in loc]
    for end in range(len(parts), 0, -1):
        name = PREFIX + "__".join(parts[:end])
        if name in env:
            return env[name]
    return None


def warnings(model: type[BaseModel], environ: Mapping[str, str] | None = None) -> list[str]:
    """One sentence per unknown variable (what ``run`` logs and ``check-config`` prints)."""
    return [
        f"environment variable {name} sets nothing (ignored)" + (f"; did you mean {near}?" if near else "")
        for name, near in unknown_variables(model, environ)
    ]
