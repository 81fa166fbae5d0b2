"""Helpers shared by the per-family CLI contract modules (``adapters/<family>/describe.py``).

Owns the option check and the JSON-ification of decoded field values, so every family rejects a
misspelt option the same way and renders bytes the same way (hex). Must not know any family's options,
tables or frames, nor the CLI's argument parsing. Standard library only.
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping
from typing import Any

__all__ = ["check_options", "jsonable"]


def check_options(options: Mapping[str, Any], allowed: Iterable[str], family: str) -> None:
    """ValueError naming the unknown options and the valid ones: a misspelt option must not be
    silently ignored (it would decode with the default season/firmware and look plausible)."""
    valid = set(allowed)
    unknown = set(options) - valid
    if unknown:
        raise ValueError(
            f"unknown option(s) {sorted(unknown)} for {family}; valid: {', '.join(sorted(valid))}"
        )


def jsonable(value: Any) -> Any:
    """``value`` with bytes as hex strings, mappings as dicts and tuples as lists, recursively (the CLI
    contract's JSON shape); everything else (ints, floats, str, None) is returned unchanged."""
    if isinstance(value, bytes | bytearray):
        return bytes(value).hex()
    if isinstance(value, Mapping):
        return {k: jsonable(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [jsonable(v) for v in value]
    return value
