"""The one exception the monitors raise for bad input (the trace layer turns it into diagnostics)."""

from __future__ import annotations


class MonitorError(Exception):
    """A formula cannot be evaluated on the given signals.

    ``name`` is the signal, constant, rule or built-in the problem is about (``""`` if none).
    """

    def __init__(self, message: str, name: str = "") -> None:
        super().__init__(message)
        self.message = message
        self.name = name

    def __reduce__(self) -> tuple[type, tuple[str, str]]:
        return (type(self), (self.message, self.name))
