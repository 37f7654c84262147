"""Ordering by dependencies: definitions that use one another (parameters defined by expressions of
other parameters), each placed after what it uses, in time linear in their number (Kahn's algorithm)."""

from __future__ import annotations

from collections.abc import Hashable, Iterable, Mapping
from typing import TypeVar

__all__ = ["dependency_order"]

Key = TypeVar("Key", bound=Hashable)


def dependency_order(uses: Mapping[Key, Iterable[Key]]) -> tuple[list[Key], set[Key]]:
    """``(order, unresolved)``: the keys of ``uses`` each after the keys it uses (uses of keys not in
    ``uses`` are ignored), and the keys that cannot be placed, the cycles and what depends on them
    (empty when there is no cycle)."""
    used_by: dict[Key, list[Key]] = {key: [] for key in uses}
    waiting: dict[Key, int] = {}
    for key, used in uses.items():
        inside = set(used) & used_by.keys()
        waiting[key] = len(inside)
        for other in inside:
            used_by[other].append(key)
    order = [key for key, count in waiting.items() if count == 0]  # grows while it is read: first in, first out
    for key in order:
        for user in used_by[key]:
            waiting[user] -= 1
            if waiting[user] == 0:
                order.append(user)
    return order, uses.keys() - set(order)
