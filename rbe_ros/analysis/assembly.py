"""The geometry stage of a check: posed blocks and their contact interfaces."""
from __future__ import annotations

from dataclasses import dataclass, replace
from functools import cached_property

import numpy as np

from ..geometry.block import PosedBlock, pose_blocks
from ..geometry.contacts import ContactOptions, Interface, detect_contacts
from ..rbe.model import Grip
from ..scene import Scene


@dataclass(frozen=True)
class Assembly:
    """Posed blocks, the interfaces between them (not between two supports), gravity, and
    the near contacts (face pairs just beyond the contact tolerance, not between two
    supports; see :mod:`rbe_ros.geometry.uncertainty`); ``grips``: the robots' holds of
    held blocks (flagged supports, checked as free blocks with a bounded wrench by
    :mod:`rbe_ros.analysis.verdict`; without a grip a held block is a plain support)."""

    blocks: tuple[PosedBlock, ...]
    interfaces: tuple[Interface, ...]
    gravity: np.ndarray
    near: tuple[Interface, ...] = ()
    grips: tuple[Grip, ...] = ()

    @classmethod
    def from_scene(cls, scene: Scene, contact: ContactOptions = ContactOptions()) -> "Assembly":
        blocks = tuple(pose_blocks(scene.blocks))
        interfaces, near = (tuple(it for it in found
                                  if not (blocks[it.a].support and blocks[it.b].support))
                            for found in detect_contacts(list(blocks), contact))
        Interface.compute_kerns(interfaces)
        return cls(blocks, interfaces, np.asarray(scene.gravity, dtype=float), near)

    @cached_property
    def index(self) -> dict[str, int]:
        """Each block's position in ``blocks`` by its id (the one lookup of a block by id:
        grips, the robots' actions and the planner's ranks use it)."""
        return {b.id: k for k, b in enumerate(self.blocks)}

    def block(self, block_id: str) -> PosedBlock:
        """The block ``block_id`` (KeyError when there is none)."""
        return self.blocks[self.index[block_id]]

    def subset(self, ids, held=(), grips=()) -> "Assembly":
        """The assembly of the blocks named in ``ids``, with the interfaces among them; the
        blocks named in ``held`` become supports (held by a robot, a scaffold, or treated as
        rigid by a relaxation), and interfaces between two supports are dropped, except
        those of a held block with a grip (of ``grips``, on held blocks), which is free in
        the equilibrium."""
        keep, held = set(ids), set(held)
        index = {}
        for old, b in enumerate(self.blocks):
            if b.id in keep:
                index[old] = len(index)
        blocks = tuple(replace(self.blocks[i], support=True) if self.blocks[i].id in held
                       else self.blocks[i] for i in index)
        grips = tuple(g for g in grips if g.block in held and g.block in keep)
        gripped = {g.block for g in grips}
        rigid = [b.support and b.id not in gripped for b in blocks]
        if len(index) == len(self.blocks):      # every block kept: no renumbering
            interfaces, near = (tuple(it for it in found if not (rigid[it.a] and rigid[it.b]))
                                for found in (self.interfaces, self.near))
        else:
            interfaces, near = (tuple(it.between(index[it.a], index[it.b])
                                      for it in found if it.a in index and it.b in index
                                      and not (rigid[index[it.a]] and rigid[index[it.b]]))
                                for found in (self.interfaces, self.near))
        return Assembly(blocks, interfaces, self.gravity, near, grips)
