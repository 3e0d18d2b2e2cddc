"""Safe YAML loading that remembers the line of every mapping key.

``yaml.SafeLoader`` builds only plain data (no Python objects), so spec files cannot run code;
the subclass below adds nothing but line numbers, so that every spec error can point at
``file:line``.
"""

from __future__ import annotations

from typing import Any

import yaml

__all__ = ["LineDict", "LineList", "load_yaml_with_lines"]


class LineDict(dict[str, Any]):
    """A mapping that knows the 1-based line of itself and of each of its keys."""

    line: int = 0
    key_lines: dict[str, int]

    def line_of(self, key: str) -> int:
        return self.key_lines.get(key, self.line)


class LineList(list[Any]):
    """A sequence that knows the 1-based line of itself and of each item."""

    line: int = 0
    item_lines: list[int]

    def line_of(self, index: int) -> int:
        if 0 <= index < len(self.item_lines):
            return self.item_lines[index]
        return self.line


_MERGE_TAG = "tag:yaml.org,2002:merge"


class _LineLoader(yaml.SafeLoader):
    def construct_object(self, node: yaml.Node, deep: bool = False) -> Any:
        try:
            return super().construct_object(node, deep=deep)
        except (yaml.YAMLError, RecursionError):
            raise
        except (ValueError, TypeError, LookupError, AttributeError, ArithmeticError) as exc:
            # PyYAML's safe constructors fail with plain Python errors on values such as
            # `2001-13-01`, `!!int 0x`, `!!int` (empty), `!!bool maybe` or an integer of 5000
            # digits; as a YAML error the value keeps its line.
            tag = str(node.tag).rsplit(":", 1)[-1]
            problem = f"cannot read this value as {tag}"
            if isinstance(exc, (ValueError, ArithmeticError)) and str(exc):
                problem += f" ({exc})"
            raise yaml.constructor.ConstructorError(None, None, problem, node.start_mark) from None

    def construct_mapping(self, node: yaml.MappingNode, deep: bool = False) -> dict[Any, Any]:
        mapping = LineDict()
        mapping.line = node.start_mark.line + 1
        mapping.key_lines = {}
        written = sum(1 for key_node, _ in node.value if key_node.tag != _MERGE_TAG)
        self.flatten_mapping(node)
        # flatten_mapping puts the pairs of merge keys (`<<: *base`) first: the mapping's own
        # keys then override them, as YAML's merge key defines; only its own may not repeat.
        merged = len(node.value) - written
        own_keys: set[str] = set()
        for index, (key_node, value_node) in enumerate(node.value):
            key = self.construct_object(key_node, deep=True)
            if not isinstance(key, str):
                # Keys are names: keep them as written, so that YAML 1.1's booleans do not
                # turn `on:` into True; other non-string keys reach the validator as text.
                key = key_node.value if isinstance(key_node, yaml.ScalarNode) else str(key)
            own = index >= merged
            if key in mapping and own and key in own_keys:
                raise yaml.constructor.ConstructorError(
                    "while constructing a mapping",
                    node.start_mark,
                    f"found duplicate key {key!r}",
                    key_node.start_mark,
                )
            if own:
                own_keys.add(key)
            mapping[key] = self.construct_object(value_node, deep=True)
            mapping.key_lines[key] = key_node.start_mark.line + 1
        return mapping

    def construct_sequence(self, node: yaml.SequenceNode, deep: bool = False) -> list[Any]:
        items = LineList(self.construct_object(child, deep=True) for child in node.value)
        items.line = node.start_mark.line + 1
        items.item_lines = [child.start_mark.line + 1 for child in node.value]
        return items


_LineLoader.add_constructor(
    "tag:yaml.org,2002:map",
    _LineLoader.construct_mapping,
)
_LineLoader.add_constructor(
    "tag:yaml.org,2002:seq",
    _LineLoader.construct_sequence,
)


#: The most values a spec may expand to, aliases counted as often as they are used: a spec of
#: a thousand signals holds a few ten thousands; an alias bomb (nine aliases of nine aliases
#: of …) billions, which no loop over the spec would finish.
MAX_EXPANDED_NODES = 1_000_000


def load_yaml_with_lines(text: str) -> Any:
    """Parse YAML text safely; mappings become :class:`LineDict`, sequences :class:`LineList`.

    Raises ``yaml.YAMLError`` for a document whose aliases expand it beyond
    :data:`MAX_EXPANDED_NODES` values, or that refers to itself.
    """
    loader = _LineLoader(text)
    try:
        root = loader.get_single_node()
        if root is None:
            return None
        _check_expansion(root)
        return loader.construct_document(root)
    finally:
        loader.dispose()


def _check_expansion(root: yaml.Node) -> None:
    """Count the values the document expands to, each alias as often as it is used."""
    sizes: dict[int, int] = {}
    pending: list[tuple[yaml.Node, bool]] = [(root, False)]
    open_nodes: set[int] = set()
    while pending:
        node, children_done = pending.pop()
        if id(node) in sizes:
            continue
        children = _children(node)
        if children_done:
            open_nodes.discard(id(node))
            size = 1 + sum(sizes[id(child)] for child in children)
            if size > MAX_EXPANDED_NODES:
                raise yaml.constructor.ConstructorError(
                    None,
                    None,
                    f"its aliases expand to over {MAX_EXPANDED_NODES:,} values",
                    node.start_mark,
                )
            sizes[id(node)] = size
            continue
        if id(node) in open_nodes:
            raise yaml.constructor.ConstructorError(
                None, None, "an alias refers to the value that holds it", node.start_mark
            )
        open_nodes.add(id(node))
        pending.append((node, True))
        for child in children:
            if id(child) in open_nodes:
                raise yaml.constructor.ConstructorError(
                    None, None, "an alias refers to the value that holds it", child.start_mark
                )
            pending.append((child, False))


def _children(node: yaml.Node) -> list[yaml.Node]:
    if isinstance(node, yaml.MappingNode):
        return [item for pair in node.value for item in pair]
    if isinstance(node, yaml.SequenceNode):
        return list(node.value)
    return []
