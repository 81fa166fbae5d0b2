"""Counts of fuzz cases run in this session, printed in pytest's terminal summary."""

from __future__ import annotations

from collections import Counter

CASES: Counter[str] = Counter()


def count(name: str) -> None:
    CASES[name] += 1
