"""The allocators built in this process: an LRU bounded in entries and in bytes, with a
smaller byte budget for allocators of inline problems (see :mod:`service.pool`)."""

from __future__ import annotations

import threading
from collections import OrderedDict
from collections.abc import Callable, Hashable

import alloc

__all__ = ["AllocatorCache", "INLINE_ENTRY_BYTES"]

#: an allocator built for an inline problem larger than this is not cached
INLINE_ENTRY_BYTES = 4 * 1024 * 1024


class AllocatorCache:
    """A thread-safe LRU of built allocators, bounded in entries and in bytes.

    ``inline_bytes`` bounds the share of entries keyed ``("inline", ...)``.
    """

    def __init__(self, size: int, max_bytes: int, inline_bytes: int) -> None:
        self._size, self._max_bytes, self._inline_max = size, max_bytes, inline_bytes
        self._items: OrderedDict[Hashable, tuple[alloc.Allocator, int]] = OrderedDict()
        self._lock = threading.Lock()
        self.bytes = 0
        self.inline_bytes = 0
        self.builds = 0

    def __len__(self) -> int:
        return len(self._items)

    def lookup(self, key: Hashable) -> alloc.Allocator | None:
        with self._lock:
            found = self._items.get(key)
            if found is None:
                return None
            self._items.move_to_end(key)
            return found[0]

    @staticmethod
    def _inline(key: Hashable) -> bool:
        return isinstance(key, tuple) and bool(key) and key[0] == "inline"

    def _pop(self, key: Hashable) -> None:
        item = self._items.pop(key, None)
        if item is not None:
            self.bytes -= item[1]
            if self._inline(key):
                self.inline_bytes -= item[1]

    def keep_limit(self, key: Hashable) -> int:
        """The largest allocator (bytes) this cache keeps under ``key``."""
        if isinstance(key, tuple) and key and key[0] == "private":
            return 0
        if self._inline(key):
            return min(INLINE_ENTRY_BYTES, self._inline_max, self._max_bytes // 4)
        return self._max_bytes // 4

    def put(self, key: Hashable, allocator: alloc.Allocator, nbytes: int) -> bool:
        """Cache ``allocator`` (``nbytes`` held); ``False`` when it is too large to keep."""
        inline = self._inline(key)
        with self._lock:
            self.builds += 1
            if nbytes > self.keep_limit(key):
                return False
            self._pop(key)
            self._items[key] = (allocator, nbytes)
            self.bytes += nbytes
            if inline:
                self.inline_bytes += nbytes
            while len(self._items) > self._size or self.bytes > self._max_bytes:
                self._pop(next(iter(self._items)))
            while self.inline_bytes > self._inline_max:
                self._pop(next(k for k in self._items if self._inline(k)))
            return True

    def keys_where(self, predicate: Callable[[Hashable], bool]) -> list[Hashable]:
        """Matching keys, least recently used first."""
        with self._lock:
            return [k for k in self._items if predicate(k)]

    def drop(self, keys: list[Hashable]) -> None:
        with self._lock:
            for k in keys:
                self._pop(k)
