"""Decoded device values made JSON-safe, for every place that prints or serves them (``dji-gateway
decode``, the web console's frame inspector and pushes).

Owns one rule: JSON has no NaN or infinity. Knows nothing of devices, MQTT or HTTP.
"""

from __future__ import annotations

import math
from typing import Any


def json_safe(value: Any) -> Any:
    """JSON has no NaN or infinity; a float register on the wire can hold them, so they print as strings."""
    if isinstance(value, float) and not math.isfinite(value):
        return repr(value)
    if isinstance(value, dict):
        return {k: json_safe(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [json_safe(v) for v in value]
    return value
