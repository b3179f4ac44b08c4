"""Which nodes are shown at an instant: ``KHR_node_visibility``, as the file sets it and as
``KHR_animation_pointer`` animates it.

A node is visible when its own ``visible`` is true and its parent is visible (the extension's
specification, "Extending Nodes"): a hidden node hides its meshes and its lights and those of every
node below it, never a camera. The animated value is a boolean, written as unsigned bytes with
STEP interpolation (KHR_animation_pointer, "Output Accessor Component Types"); any key other than
0 shows the node. A hidden mesh keeps its triangles, collapsed to its node's origin where no ray
meets them (pipeline/scene/scene.py), so that triangle and element numbering stay those of the file;
a mesh hidden at every instant is not loaded at all (pipeline/scene/loader.py).
"""
from __future__ import annotations

import numpy as np

from .animation import Sampler
from .nodes import Node

EXTENSION = "KHR_node_visibility"


def visible_nodes(nodes: list[Node], order: list[int], channels: dict[int, Sampler], t: float) -> np.ndarray:
    """(n_nodes,) bool: whether each node of ``order`` (parents before children) is shown at ``t``,
    ``channels`` being the animated ``visible`` of some nodes; nodes outside ``order`` are False."""
    shown = np.zeros(len(nodes), bool)
    for i in order:
        node = nodes[i]
        own = bool(channels[i].evaluate(t)[0] != 0) if i in channels else node.visible
        shown[i] = own and (node.parent is None or shown[node.parent])
    return shown


def always_hidden(nodes: list[Node], order: list[int], channels: dict[int, Sampler]) -> set[int]:
    """Nodes of ``order`` hidden at every instant: they or an ancestor are hidden in the file and
    nothing animates that ancestor's visibility (a channel may show it)."""
    hidden: set[int] = set()
    for i in order:
        node = nodes[i]
        if (i not in channels and not node.visible) or (node.parent is not None and node.parent in hidden):
            hidden.add(i)
    return hidden
