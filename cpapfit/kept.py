"""The last few results of a computation, by a key of what they were made from: work asked for
again with the same inputs (a cushion refined, a face's ceiling grid, a rim's convex hull) is
handed back, without holding on to the objects it was made from."""

from collections import OrderedDict
from typing import Callable, Hashable


class Kept:
    """The last `size` results, by key."""

    def __init__(self, size: int):
        self.size = size
        self._items: OrderedDict = OrderedDict()

    def get(self, key: Hashable, make: Callable[[], object]):
        """The result kept for `key`; else `make()`, kept (the least recently asked for let go)."""
        if key in self._items:
            self._items.move_to_end(key)
            return self._items[key]
        value = self._items[key] = make()
        while len(self._items) > self.size:
            self._items.popitem(last=False)
        return value
