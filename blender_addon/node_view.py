"""A material's or world's node tree as Cycles compiles it: node groups inlined, reroutes,
muted links and muted nodes passed through.

Cycles flattens a shader tree before it runs it: a Group node is replaced by the nodes of its
tree (its Group Input's sockets become whatever feeds the Group node's inputs, or their
values), a reroute is a wire, a muted link leaves its input unlinked, and a muted node passes
its inputs through (its internal links) or gives its outputs' default values. The exporter
reads trees through these views, which offer the part of Blender's node API it uses
(`type`, `name`, `inputs`, `is_linked`, `links[0].from_node`/`from_socket`, `default_value`
and every other attribute of the node or socket underneath), so one walk of the tree serves
plain and grouped materials alike.

A node inside groups is named by the Group nodes that hold it and its own name,
'Group/Node' — unique in the flattened tree, as the walks' loop checks and the texture
cache need, and what a warning names.
"""

from dataclasses import dataclass

import numpy as np

from .texture_graph import LUMA

# (deeper than any real file: a guard against a script-made group that contains itself)
MAX_STEPS = 10_000
_SCALAR = ("VALUE", "INT", "BOOLEAN")


class NodeView:
    """A node in the flattened tree: the node, and the Group nodes (outermost first) it sits in."""

    __slots__ = ("node", "groups")

    def __init__(self, node, groups=()):
        self.node = node
        self.groups = groups

    def __getattr__(self, attr):  # (everything else is the node's own)
        return getattr(self.node, attr)

    @property
    def name(self):
        return "/".join([g.name for g in self.groups] + [self.node.name])

    @property
    def inputs(self):
        return _Inputs(self)

    def __eq__(self, other):
        return isinstance(other, NodeView) and self.node == other.node and self.groups == other.groups

    def __hash__(self):
        return hash((self.node.as_pointer(), tuple(g.as_pointer() for g in self.groups)))


class _Inputs:
    """A node's inputs, as views: by name or index, `get`, iteration, `in`."""

    __slots__ = ("view",)

    def __init__(self, view):
        self.view = view

    def __getitem__(self, key):
        return SocketView(self.view.node.inputs[key], self.view)

    def get(self, key, default=None):
        s = self.view.node.inputs.get(key)
        return default if s is None else SocketView(s, self.view)

    def __iter__(self):
        return (SocketView(s, self.view) for s in self.view.node.inputs)

    def __len__(self):
        return len(self.view.node.inputs)

    def __contains__(self, key):
        return key in self.view.node.inputs


@dataclass(frozen=True)
class LinkView:
    from_node: NodeView
    from_socket: object  # the output socket of from_node's node


class SocketView:
    """An input socket of a node view, its link followed through groups, reroutes and muted
    nodes: `links` holds the one link to the node that computes its value (empty when none
    does), `default_value` the value it takes otherwise — its own, or that of the socket the
    chain ended at (a Group node's input, a Group Output's), converted to this socket's type
    as Cycles converts (colour into value: luminance; value into colour: grey)."""

    __slots__ = ("socket", "node", "_link", "_end")

    def __init__(self, socket, node):
        self.socket = socket
        self.node = node
        self._link, self._end = _resolve(socket, node.groups)

    def __getattr__(self, attr):
        return getattr(self.socket, attr)

    @property
    def is_linked(self):
        return self._link is not None

    @property
    def links(self):
        return [] if self._link is None else [self._link]

    @property
    def default_value(self):
        v = getattr(self._end, "default_value", None)
        if v is None:  # (an output or interface socket without a value)
            return self.socket.default_value
        return _convert(v, self._end.type, self.socket.type)


def _live_link(sock):
    """The link into input `sock` that carries a value (not muted, valid), or None."""
    if not sock.is_linked:
        return None
    link = sock.links[0]
    if getattr(link, "is_muted", False) or not getattr(link, "is_valid", True):
        return None
    return link


def _group_output(tree):
    outs = [n for n in tree.nodes if n.type == "GROUP_OUTPUT"]
    return next((n for n in outs if n.is_active_output), outs[0] if outs else None)


def _socket(sockets, identifier):
    return next((s for s in sockets if s.identifier == identifier), None)


def _resolve(sock, groups):
    """(LinkView to the computing node, or None; the socket whose value stands in otherwise)."""
    for _ in range(MAX_STEPS):
        link = _live_link(sock)
        if link is None:
            return None, sock
        n, out = link.from_node, link.from_socket
        if n.type == "REROUTE":
            sock = n.inputs[0]
        elif getattr(n, "mute", False):
            passed = next((il.from_socket for il in n.internal_links if il.to_socket.identifier == out.identifier),
                          None)
            if passed is None:
                return None, out
            sock = passed
        elif n.type == "GROUP":
            gout = _group_output(n.node_tree) if n.node_tree is not None else None
            inner = _socket(gout.inputs, out.identifier) if gout is not None else None
            if inner is None:
                return None, out
            sock, groups = inner, groups + (n,)
        elif n.type == "GROUP_INPUT":
            outer = _socket(groups[-1].inputs, out.identifier) if groups else None
            if outer is None:
                return None, out
            sock, groups = outer, groups[:-1]
        else:
            return LinkView(NodeView(n, groups), out), None
    raise ValueError(f"node groups nested more than {MAX_STEPS} deep through '{sock.node.name}' (a group "
                     f"that contains itself?)")


def _convert(v, src, dst):
    """A socket value of type `src` as a socket of type `dst` takes it."""
    if src == dst or dst not in _SCALAR + ("RGBA", "VECTOR"):
        return v
    if src in _SCALAR:
        x = float(v)
        return x if dst in _SCALAR else (x, x, x, 1.0) if dst == "RGBA" else (x, x, x)
    c = tuple(v)[:3]
    if dst in _SCALAR:
        return float(np.dot(LUMA, c)) if src == "RGBA" else sum(c) / 3.0
    return (*c, 1.0) if dst == "RGBA" else c
