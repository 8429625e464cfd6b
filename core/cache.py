"""One eviction policy for every in-memory cache of derived data: least recently used, bounded
by entry count, keyed by content (never by ``id()``, which Python reuses and which a material
packed anew each frame never hits); and one way to write such data to the disk cache
(write_cache_file). Ground floor: imports nothing of lobeview."""

from __future__ import annotations

import os
import warnings
import zipfile
from collections import OrderedDict
from collections.abc import Callable, Hashable
from pathlib import Path
from typing import BinaryIO, TypeVar

T = TypeVar("T")
#: what reading a damaged or foreign cache file raises (a truncated .npz: BadZipFile or EOFError)
DAMAGED_CACHE_ERRORS = (OSError, ValueError, KeyError, TypeError, EOFError, zipfile.BadZipFile)


def write_cache_file(path: Path, write: Callable[[BinaryIO], None]) -> bool:
    """Write a derived-data file on disk through ``write(handle)`` into a temporary file beside
    it, then rename it into place: a concurrent reader never sees half a file. A cache folder
    that cannot be written returns False instead of failing (the data is computed again next
    time)."""
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        partial = path.with_suffix(f".{os.getpid()}.tmp")
        with open(partial, "wb") as handle:
            write(handle)
        os.replace(partial, path)
        return True
    except OSError:
        return False


def read_cache_file(path: Path | None, read: Callable[[Path], T], what: str) -> T | None:
    """``read(path)`` of a derived-data file, or None when there is none or it is damaged, which
    is warned (the caller computes the data again and rewrites the file: a cache file is never
    trusted to be whole). ``read`` raises ValueError for content of the wrong shape."""
    if path is None or not path.exists():
        return None
    try:
        return read(path)
    except DAMAGED_CACHE_ERRORS as exc:
        warnings.warn(f"{path}: unusable cached {what} ({type(exc).__name__}: {exc}); computing it again", stacklevel=3)
        return None


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
        self.evictions = 0  # entries dropped so far (what was made from them may be stale)

    def get(self, key: Hashable, make: Callable[[], object]):
        if key in self._items:
            self._items.move_to_end(key)
            return self._items[key]
        value = make()
        self._items[key] = value
        while len(self._items) > self.capacity:
            _, old = self._items.popitem(last=False)
            self.evictions += 1
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
            self.evictions += 1
            if self.on_evict is not None:
                self.on_evict(old)
