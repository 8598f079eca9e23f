"""Counting a library function's calls in a test (how often the panorama is turned, say)."""

from __future__ import annotations

import pytest


def counting_calls(
    monkeypatch: pytest.MonkeyPatch, module: object, name: str, argument: int = 0
) -> list[object]:
    """Every call of ``module.name`` from here on, by its positional ``argument``.

    The function still runs; the returned list grows by that argument at each call.
    """
    calls: list[object] = []
    real = getattr(module, name)

    def counted(*args: object, **kwargs: object) -> object:
        calls.append(args[argument])
        return real(*args, **kwargs)

    monkeypatch.setattr(module, name, counted)
    return calls
