"""One eviction policy for every in-memory cache of derived data: least recently used, bounded
by entry count, keyed by content (never by ``id()``, which Python reuses and which a material
packed anew each frame never hits). Ground floor: imports nothing of lobeview."""

from __future__ import annotations

from collections import OrderedDict
from collections.abc import Callable, Hashable


class BoundedCache:
    """``get(key, make)`` returns the cached value or stores ``make()``; beyond ``capacity``
    entries the least recently used one is dropped and passed to ``on_evict`` (release GPU
    objects there)."""

    def __init__(self, capacity: int, on_evict: Callable[[object], None] | None = None):
        if capacity < 1:
            raise ValueError(f"cache capacity must be >= 1, got {capacity}")
        self.capacity = int(capacity)
        self.on_evict = on_evict
        self._items: OrderedDict = OrderedDict()

    def get(self, key: Hashable, make: Callable[[], object]):
        if key in self._items:
            self._items.move_to_end(key)
            return self._items[key]
        value = make()
        self._items[key] = value
        while len(self._items) > self.capacity:
            _, old = self._items.popitem(last=False)
            if self.on_evict is not None:
                self.on_evict(old)
        return value

    def __contains__(self, key: Hashable) -> bool:
        return key in self._items

    def __len__(self) -> int:
        return len(self._items)

    def values(self):
        return list(self._items.values())

    def clear(self) -> None:
        """Drop every entry (each passed to ``on_evict``)."""
        while self._items:
            _, old = self._items.popitem(last=False)
            if self.on_evict is not None:
                self.on_evict(old)
