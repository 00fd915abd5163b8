"""Small text helpers for messages and reports."""

from __future__ import annotations

__all__ = ["plural"]


def plural(n: int, noun: str, many: str | None = None) -> str:
    """``n`` and the noun in the number it takes: ``1 load step``, ``0 load steps``.

    >>> plural(1, "iteration"), plural(3, "iteration"), plural(2, "cutback"), plural(1, "is", "are")
    ('1 iteration', '3 iterations', '2 cutbacks', '1 is')
    """
    return f"{n} {noun if n == 1 else (many if many is not None else noun + 's')}"
