"""The recorded past of every signal, as the controllers read it (oldest first, now excluded).

Appending is amortised O(1) (arrays double when full); :meth:`History.view` returns the last
``keep`` samples as read-only numpy views, no copying, so handing the past to both controller
levels every step costs nothing whatever the run's length.
"""

from __future__ import annotations

from typing import Iterable, Mapping

import numpy as np

__all__ = ["History"]


class History:
    """Past samples of named signals; ``keep`` [samples] is the longest past any rule reads."""

    def __init__(self, names: Iterable[str], keep: int, capacity: int = 256) -> None:
        self.names = tuple(names)
        self.keep = max(0, int(keep))
        self._data = np.zeros((len(self.names), max(capacity, 1)))
        self._n = 0
        self._row = {name: i for i, name in enumerate(self.names)}

    def __len__(self) -> int:
        return self._n

    def append(self, sample: Mapping[str, float]) -> None:
        """Record one sample (every name must be present)."""
        if self._n == self._data.shape[1]:
            # keep only what can still be read, then grow
            start = max(0, self._n - self.keep)
            kept = self._data[:, start:self._n]
            grown = np.zeros((len(self.names), max(2 * kept.shape[1], 256)))
            grown[:, : kept.shape[1]] = kept
            self._data, self._n = grown, kept.shape[1]
        col = self._n
        for name, i in self._row.items():
            self._data[i, col] = sample[name]
        self._n += 1

    def view(self) -> dict[str, np.ndarray]:
        """The last ``keep`` samples of every signal, oldest first (read-only views)."""
        start = max(0, self._n - self.keep)
        out = {}
        for name, i in self._row.items():
            a = self._data[i, start:self._n]
            a.flags.writeable = False
            out[name] = a
        return out
