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
        self.flatten_mapping(node)
        for key_node, value_node in node.value:
            key = self.construct_object(key_node, deep=True)
            if not isinstance(key, str):
                # Keys are names: keep them as written, so that YAML 1.1's booleans do not
                # turn `on:` into True; other non-string keys reach the validator as text.
                key = key_node.value if isinstance(key_node, yaml.ScalarNode) else str(key)
            if key in mapping:
                raise yaml.constructor.ConstructorError(
                    "while constructing a mapping",
                    node.start_mark,
                    f"found duplicate key {key!r}",
                    key_node.start_mark,
                )
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


def load_yaml_with_lines(text: str) -> Any:
    """Parse YAML text safely; mappings become :class:`LineDict`, sequences :class:`LineList`."""
    return yaml.load(text, Loader=_LineLoader)
