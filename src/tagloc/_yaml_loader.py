"""The YAML loader behind :func:`tagloc.config.parse_yaml`: safe, strict and bounded.

A safe loader (libyaml's when PyYAML has it) that also refuses duplicate mapping keys, documents
nested deeper than :data:`MAX_YAML_DEPTH`, documents that expand through aliases to more than
:data:`MAX_YAML_NODES` values (checked on the composed node graph, before anything is built),
cyclic aliases, integers beyond 64 bits, and turns the Python errors of odd scalars into YAML
errors at the node.
"""

from __future__ import annotations

from collections.abc import Hashable, Iterator
from typing import Any

import yaml

try:  # libyaml's parser: ~4x faster, and it refuses flow nesting past 1000 levels by itself
    from yaml import CSafeLoader as _SafeLoader
except ImportError:  # pragma: no cover - PyYAML built without libyaml
    from yaml import SafeLoader as _SafeLoader  # type: ignore[assignment]

__all__ = ["MAX_YAML_DEPTH", "MAX_YAML_NODES", "StrictLoader"]

#: Deepest nesting of mappings and sequences in a YAML document (tagloc's files use < 10).
MAX_YAML_DEPTH = 64
#: Most values (scalars, mappings, sequences) a YAML document may hold once aliases are expanded.
MAX_YAML_NODES = 1_000_000


class StrictLoader(_SafeLoader):
    """Safe loader that rejects duplicate mapping keys, deep nesting and alias bombs."""

    def get_single_data(self) -> Any:
        node = self.get_single_node()
        if node is None:
            return None
        _check_node_graph(node)
        return self.construct_document(node)

    def construct_object(self, node: yaml.Node, deep: bool = False) -> Any:
        """The base constructor, with Python errors of odd scalars as YAML errors at the node
        (integers past 4300 digits, ``2001-02-31``, unhashable keys such as ``{[1]: 2}``)."""
        try:
            return super().construct_object(node, deep=deep)
        except (ValueError, TypeError, AttributeError, OverflowError) as exc:
            raise yaml.constructor.ConstructorError(
                None, None, f"cannot read this value ({exc})", node.start_mark
            ) from None


def _children(node: yaml.Node) -> list[yaml.Node]:
    if isinstance(node, yaml.MappingNode):
        return [child for pair in node.value for child in pair]
    if isinstance(node, yaml.SequenceNode):
        return list(node.value)
    return []


def _refuse(node: yaml.Node, problem: str) -> yaml.YAMLError:
    return yaml.composer.ComposerError(None, None, problem, node.start_mark)


def _check_node_graph(root: yaml.Node) -> None:
    """Refuse a node graph that is too deep, cyclic, or too large once aliases are expanded.

    Aliases make the composed graph a DAG whose nodes are shared; the expanded size of each node is
    computed once (memoized) by an explicit-stack depth-first walk, so neither the check's time nor
    its stack grows with the expansion.
    """
    expanded: dict[int, int] = {}
    stack: list[tuple[yaml.Node, Iterator[yaml.Node]]] = [(root, iter(_children(root)))]
    on_path = {id(root)}
    while stack:
        node, pending = stack[-1]
        child = next((c for c in pending if id(c) not in expanded), None)
        if child is not None:
            if id(child) in on_path:
                raise _refuse(child, "an alias refers to a node that contains it (a cycle)")
            if len(stack) >= MAX_YAML_DEPTH:
                raise _refuse(child, f"nested deeper than {MAX_YAML_DEPTH} levels")
            on_path.add(id(child))
            stack.append((child, iter(_children(child))))
            continue
        stack.pop()
        on_path.discard(id(node))
        expanded[id(node)] = 1 + sum(expanded[id(c)] for c in _children(node))
        if expanded[id(node)] > MAX_YAML_NODES:
            raise _refuse(
                node, f"expands to more than {MAX_YAML_NODES} values through aliases (*name)"
            )


def _construct_mapping(loader: StrictLoader, node: yaml.MappingNode) -> dict[Hashable, Any]:
    loader.flatten_mapping(node)
    seen: dict[Hashable, yaml.Mark] = {}
    for key_node, _ in node.value:
        key = loader.construct_object(key_node, deep=True)
        if key in seen:
            raise yaml.constructor.ConstructorError(
                None,
                None,
                f"duplicate key {key!r} (first at line {seen[key].line + 1})",
                key_node.start_mark,
            )
        seen[key] = key_node.start_mark
    return loader.construct_mapping(node, deep=True)


def _construct_int(loader: StrictLoader, node: yaml.ScalarNode) -> int:
    value = loader.construct_yaml_int(node)
    if not -(2**63) <= value < 2**64:  # 0xfff... of 20 000 digits would fail only when printed
        raise yaml.constructor.ConstructorError(
            None, None, "integer out of the 64-bit range", node.start_mark
        )
    return int(value)


StrictLoader.add_constructor(yaml.resolver.BaseResolver.DEFAULT_MAPPING_TAG, _construct_mapping)
StrictLoader.add_constructor("tag:yaml.org,2002:int", _construct_int)
