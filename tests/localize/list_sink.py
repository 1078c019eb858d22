"""A node output sink that keeps every output in a list, for the node's tests."""

from __future__ import annotations

from tagloc.localize.outputs import NodeOutput


class ListSink:
    def __init__(self) -> None:
        self.outputs: list[NodeOutput] = []

    def write(self, output: NodeOutput) -> None:
        self.outputs.append(output)

    def of(self, kind: type) -> list:  # type: ignore[type-arg]
        return [o for o in self.outputs if isinstance(o, kind)]
