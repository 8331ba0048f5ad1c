"""The contact graph of an assembly: which blocks touch, and how free blocks group.

Free blocks joined by contacts between free blocks form *components*; supports (and held
blocks) cut them apart. Components share no variable and no constraint of the equilibrium
problem, so the analyses solve, cache and decompose by component. One graph serves them all:
the verdict (floating blocks), the per-step regions (:mod:`.incremental`), the hold search
(:mod:`.holds`) and the planner.
"""
from __future__ import annotations

from collections import deque

from .assembly import Assembly


class ContactGraph:
    """Adjacency of the blocks of an assembly (block indices) through its interfaces."""

    def __init__(self, assembly: Assembly):
        self.ids = [b.id for b in assembly.blocks]
        self.support = [b.support for b in assembly.blocks]
        self.adjacent: list[set[int]] = [set() for _ in assembly.blocks]
        for it in assembly.interfaces:
            self.adjacent[it.a].add(it.b)
            self.adjacent[it.b].add(it.a)
        self.free = [k for k, s in enumerate(self.support) if not s]

    def neighbours(self, region) -> set[int]:
        """Blocks touching ``region`` and not in it."""
        return {n for k in region for n in self.adjacent[k]} - set(region)

    def free_neighbours(self, region) -> set[int]:
        return {n for n in self.neighbours(region) if not self.support[n]}

    def support_neighbours(self, region) -> set[int]:
        return {n for n in self.neighbours(region) if self.support[n]}

    def component(self, start) -> set[int]:
        """The free blocks of ``start`` and those joined to them by chains of contacts
        between free blocks."""
        found = {k for k in start if not self.support[k]}
        stack = list(found)
        while stack:
            for n in self.adjacent[stack.pop()]:
                if n not in found and not self.support[n]:
                    found.add(n)
                    stack.append(n)
        return found

    def components(self, held=()) -> list[tuple[frozenset, frozenset]]:
        """(free blocks, supports and held blocks they touch) of each component when the
        blocks ``held`` (indices) are supports too, in the order of their first block."""
        held = set(held)
        seen: set[int] = set()
        out = []
        for k in self.free:
            if k in held or k in seen:
                continue
            comp, touched, stack = {k}, set(), [k]
            while stack:
                j = stack.pop()
                for m in self.adjacent[j]:
                    if self.support[m] or m in held:
                        touched.add(m)
                    elif m not in comp:
                        comp.add(m)
                        stack.append(m)
            seen |= comp
            out.append((frozenset(comp), frozenset(touched)))
        return out

    def floating_blocks(self) -> list[str]:
        """Free blocks with no chain of interfaces to a support (no equilibrium is possible),
        in assembly order."""
        floating = set()
        for free, touched in self.components():
            if not touched:
                floating |= free
        return [self.ids[k] for k in sorted(floating)]

    def path_to_support(self, start) -> set[int]:
        """Free blocks on a shortest chain of contacts from ``start`` to a support."""
        parent = {k: None for k in start}
        queue = deque(start)
        while queue:
            k = queue.popleft()
            for n in sorted(self.adjacent[k]):
                if n in parent:
                    continue
                parent[n] = k
                if self.support[n]:
                    path, node = set(), k
                    while node is not None:
                        path.add(node)
                        node = parent[node]
                    return path
                queue.append(n)
        return set()
