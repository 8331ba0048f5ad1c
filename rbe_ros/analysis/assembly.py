"""The geometry stage of a check: posed blocks and their contact interfaces."""
from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from ..geometry.block import PosedBlock, pose_blocks
from ..geometry.contacts import ContactOptions, Interface, detect_interfaces
from ..scene import Scene


@dataclass(frozen=True)
class Assembly:
    """Posed blocks, the interfaces between them (not between two supports), and gravity."""

    blocks: tuple[PosedBlock, ...]
    interfaces: tuple[Interface, ...]
    gravity: np.ndarray

    @classmethod
    def from_scene(cls, scene: Scene, contact: ContactOptions = ContactOptions()) -> "Assembly":
        blocks = tuple(pose_blocks(scene.blocks))
        interfaces = tuple(it for it in detect_interfaces(list(blocks), contact)
                           if not (blocks[it.a].support and blocks[it.b].support))
        Interface.compute_kerns(interfaces)
        return cls(blocks, interfaces, np.asarray(scene.gravity, dtype=float))

    def subset(self, ids, held=()) -> "Assembly":
        """The assembly of the blocks named in ``ids``, with the interfaces among them; the
        blocks named in ``held`` become supports (held by a robot, a scaffold, or treated as
        rigid by a relaxation), and interfaces between two supports are dropped."""
        keep, held = set(ids), set(held)
        index = {}
        for old, b in enumerate(self.blocks):
            if b.id in keep:
                index[old] = len(index)
        blocks = tuple(replace(self.blocks[i], support=True) if self.blocks[i].id in held
                       else self.blocks[i] for i in index)
        interfaces = tuple(it.between(index[it.a], index[it.b])
                           for it in self.interfaces if it.a in index and it.b in index
                           and not (blocks[index[it.a]].support and blocks[index[it.b]].support))
        return Assembly(blocks, interfaces, self.gravity)
