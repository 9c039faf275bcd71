"""Reading the files the suite is given (scenarios and their line and train files, campaigns,
TTOBench JSON), hardened against hostile input: every file is read through this module.

A file is refused with a :class:`~ato_common.validation.ConfigError` that names the file, the
field and, for YAML, the line, in time and memory bounded by the limits below, when it is

- larger than ``MAX_YAML_BYTES`` (YAML) or ``MAX_JSON_BYTES`` (JSON);
- nested deeper than ``MAX_DEPTH`` mappings and lists (YAML: also once its aliases are
  expanded). The parsers recurse once per level: 5000 nested brackets would end in a
  RecursionError;
- a YAML document whose aliases expand it beyond ``MAX_EXPANDED`` (an "alias bomb": a few lines
  whose aliases refer to aliases of aliases stand for billions of nodes; whatever walks the
  loaded data, an error message's ``repr``, a hash of the scenario, would walk them all), or an
  alias inside the node it refers to (a document that contains itself);
- a mapping (YAML or JSON, at any level) that gives a key twice: the parsers would silently keep
  the last value, and a file that says two things is refused instead.

The expanded size of a YAML document counts one per node (scalar, list, mapping) plus the
characters of every scalar, each alias counted as the whole node it refers to. It is computed
while the document is composed, once per node (a node an alias refers to is complete by then),
so checking it costs no more than reading the file.
"""

from __future__ import annotations

import io
import json
from pathlib import Path
from typing import Any, Iterable

import yaml
from yaml.composer import Composer
from yaml.constructor import SafeConstructor
from yaml.nodes import MappingNode, ScalarNode
from yaml.resolver import Resolver

from ato_common.validation import ConfigError

#: the largest YAML file read, bytes (its nodes are composed in Python: seconds at this size)
MAX_YAML_BYTES = 4 * 1024 * 1024
#: the largest JSON file read, bytes
MAX_JSON_BYTES = 16 * 1024 * 1024
#: the deepest nesting of mappings and lists accepted (the suite's files need fewer than 10)
MAX_DEPTH = 64
#: the largest expanded size of a YAML document (nodes plus scalar characters, aliases
#: expanded): twice the largest file, which no document without aliases can reach
MAX_EXPANDED = 2 * MAX_YAML_BYTES

MERGE_TAG = 'tag:yaml.org,2002:merge'
STR_TAG = 'tag:yaml.org,2002:str'


def read_text(path: str | Path, limit: int) -> str:
    """The text of a regular file of at most ``limit`` bytes (a larger one is not read past the
    limit), decoded as UTF-8; ConfigError naming the file otherwise."""
    path = Path(path)
    try:
        if not path.is_file():
            raise ConfigError(f'{path}: not a readable file')
        with path.open('rb') as handle:
            data = handle.read(limit + 1)
    except OSError as error:
        raise ConfigError(f'{path}: cannot read: {error}') from None
    if len(data) > limit:
        raise ConfigError(f'{path}: larger than the limit of {limit} bytes')
    try:
        return data.decode('utf-8')
    except UnicodeDecodeError as error:
        raise ConfigError(f'{path}: cannot read: {error}') from None


def _segment(index: Any) -> str:
    """A path segment of a node composed at ``index`` (Composer.compose_node's argument: the key
    node of a mapping's value, the position in a list, None for a key)."""
    if isinstance(index, int):
        return f'[{index}]'
    if isinstance(index, ScalarNode):
        return f'.{index.value}'
    return '.<key>' if index is None else '.<complex key>'


def _where(mark: Any) -> str:
    return f'line {mark.line + 1}, column {mark.column + 1}'


try:  # libyaml's scanner and parser (in C), when PyYAML was built with it
    from yaml._yaml import CParser as _Parser

    def _parser_init(loader: Any, text: str, origin: str) -> None:
        stream = io.StringIO(text)
        stream.name = origin  # type: ignore[attr-defined]  # in libyaml's messages
        _Parser.__init__(loader, stream)
except ImportError:  # pragma: no cover - PyYAML without libyaml
    from yaml.parser import Parser as _PythonParser
    from yaml.reader import Reader
    from yaml.scanner import Scanner

    class _Parser(Reader, Scanner, _PythonParser):  # type: ignore[no-redef]
        """PyYAML's pure-Python reader, scanner and parser."""

    def _parser_init(loader: Any, text: str, origin: str) -> None:
        Reader.__init__(loader, text)
        loader.name = origin
        Scanner.__init__(loader)
        _PythonParser.__init__(loader)


class _Loader(Composer, SafeConstructor, Resolver, _Parser):
    """PyYAML's safe loader (events from the parser, composed into nodes in Python, constructed
    by the safe constructor) checking the nesting, the expansion of aliases and duplicate keys
    while it composes the document, before anything is constructed from it. Composer's
    recursion is bounded by MAX_DEPTH."""

    def __init__(self, text: str, origin: str):
        _parser_init(self, text, origin)
        Composer.__init__(self)
        SafeConstructor.__init__(self)
        Resolver.__init__(self)
        self.origin = origin
        self.path: list[str] = []
        #: (expanded size, expanded depth) of each complete node, by id (the nodes stay alive
        #: in the document)
        self.extent: dict[int, tuple[int, int]] = {}

    def refuse(self, problem: str, mark: Any = None) -> ConfigError:
        field = self.field()
        return ConfigError(f'{self.origin}: {field + ": " if field else ""}{problem}'
                           + (f' ({_where(mark)})' if mark is not None else ''))

    def field(self) -> str:
        """The path of the node being composed ('line.stations[1].name'), its middle left out
        when it is long ('a[0][0][0]...[0][0][0]', 64 levels deep)."""
        if len(self.path) <= 8:
            return ''.join(self.path).lstrip('.')
        return (''.join(self.path[:4]).lstrip('.') + '...'
                + ''.join(self.path[-3:]).lstrip('.'))

    def compose_node(self, parent: Any, index: Any) -> Any:
        event: Any = self.peek_event()
        if isinstance(event, yaml.AliasEvent):
            node = self.anchors.get(event.anchor)
            if node is not None and id(node) not in self.extent:
                self.path.append(_segment(index) if parent is not None else '')
                raise self.refuse(f'the alias *{event.anchor} is inside the node it refers '
                                  'to (a document that contains itself)', event.start_mark)
            return super().compose_node(parent, index)  # an undefined alias: PyYAML's error
        # the collection starting here is nested in len(self.path) others
        if (isinstance(event, (yaml.SequenceStartEvent, yaml.MappingStartEvent))
                and len(self.path) >= MAX_DEPTH):
            raise self.refuse(f'nested deeper than {MAX_DEPTH} levels', event.start_mark)
        self.path.append(_segment(index) if parent is not None else '')
        node = super().compose_node(parent, index)
        self.measure(node)
        self.path.pop()
        return node

    def measure(self, node: Any) -> None:
        """The node's expanded size and depth from its children's (each complete), within the
        limits; a mapping's keys each given once."""
        if isinstance(node, ScalarNode):
            self.extent[id(node)] = (1 + len(node.value), 0)
            return
        if isinstance(node, MappingNode):
            self.refuse_duplicate_keys(node)
            children = [child for pair in node.value for child in pair]
        else:
            children = list(node.value)
        extents = [self.extent[id(child)] for child in children]
        size = 1 + sum(s for s, _ in extents)
        depth = 1 + max((d for _, d in extents), default=0)
        if size > MAX_EXPANDED:
            raise self.refuse(f'its aliases expand it beyond {MAX_EXPANDED} nodes and '
                              'characters (an alias bomb?)', node.start_mark)
        if depth > MAX_DEPTH:
            raise self.refuse(f'nested deeper than {MAX_DEPTH} levels once its aliases are '
                              'expanded', node.start_mark)
        self.extent[id(node)] = (size, depth)

    def refuse_duplicate_keys(self, node: MappingNode) -> None:
        seen: dict[Any, Any] = {}
        for key_node, _ in node.value:
            if not isinstance(key_node, ScalarNode):
                continue  # a list or a mapping as a key: the constructor refuses it
            key = (key_node.value if key_node.tag in (STR_TAG, MERGE_TAG)
                   else self.construct_object(key_node, deep=True))
            try:
                first = seen.setdefault(key, key_node)
            except TypeError:  # not hashable: the constructor refuses it
                continue
            if first is not key_node:
                raise self.refuse(f'the key {key_node.value!r} is given twice, at '
                                  f'{_where(first.start_mark)} and {_where(key_node.start_mark)}')


def load_yaml_text(text: str, origin: str) -> Any:
    """The data of one YAML document (None if empty), or ConfigError naming ``origin`` (the
    file), the field and the line: a syntax error, a limit of this module passed, a key given
    twice, a value PyYAML cannot construct (a date out of range, an integer of more digits than
    Python converts)."""
    if len(text) > MAX_YAML_BYTES:
        raise ConfigError(f'{origin}: larger than the limit of {MAX_YAML_BYTES} bytes')
    loader = _Loader(text, origin)
    try:
        node = loader.get_single_node()
        return None if node is None else loader.construct_document(node)
    except ConfigError:
        raise
    except (yaml.YAMLError, ValueError, OverflowError) as error:
        raise ConfigError(f'{origin}: not valid YAML: {error}') from None
    finally:
        loader.dispose()


def load_yaml(path: str | Path) -> Any:
    """:func:`load_yaml_text` of a file, read with :func:`read_text`."""
    return load_yaml_text(read_text(path, MAX_YAML_BYTES), str(path))


def _json_path(data: Any, target: int) -> str:
    """The path of the container of id ``target`` within ``data`` (the first found)."""
    stack: list[tuple[Any, str]] = [(data, '')]
    while stack:
        value, path = stack.pop()
        if id(value) == target:
            return path
        items = (value.items() if isinstance(value, dict)
                 else enumerate(value) if isinstance(value, list) else ())
        for key, child in items:
            if isinstance(child, (dict, list)):
                stack.append((child, f'{path}[{key}]' if isinstance(value, list)
                              else f'{path}.{key}' if path else str(key)))
    return ''


def _too_deep(data: Any) -> int | None:
    """The id of a container nested deeper than MAX_DEPTH, or None."""
    stack: list[tuple[Any, int]] = [(data, 1)]
    while stack:
        value, depth = stack.pop()
        if depth > MAX_DEPTH:
            return id(value)
        children = value.values() if isinstance(value, dict) else value
        stack.extend((child, depth + 1) for child in children
                     if isinstance(child, (dict, list)))
    return None


def _first_repeated(keys: Iterable[str]) -> str:
    seen: set[str] = set()
    for key in keys:
        if key in seen:
            return key
        seen.add(key)
    raise ValueError('no key is repeated')


def load_json_text(text: str, origin: str) -> Any:
    """The data of a JSON text, or ConfigError naming ``origin`` (the file) and the field: a
    syntax error, nesting deeper than MAX_DEPTH, an object giving a key twice."""
    if len(text) > MAX_JSON_BYTES:
        raise ConfigError(f'{origin}: larger than the limit of {MAX_JSON_BYTES} bytes')
    duplicates: list[tuple[dict, str]] = []

    def no_duplicates(pairs: list[tuple[str, Any]]) -> dict:
        data = dict(pairs)
        if len(data) < len(pairs) and not duplicates:
            duplicates.append((data, _first_repeated(key for key, _ in pairs)))
        return data

    try:
        data = json.loads(text, object_pairs_hook=no_duplicates)
    except RecursionError:  # the C decoder recurses per level; far deeper than MAX_DEPTH
        raise ConfigError(f'{origin}: nested deeper than {MAX_DEPTH} levels') from None
    except ValueError as error:  # JSONDecodeError; an integer of too many digits
        raise ConfigError(f'{origin}: not valid JSON: {error}') from None
    if isinstance(data, (dict, list)):
        deep = _too_deep(data)
        if deep is not None:
            field = _json_path(data, deep)
            raise ConfigError(f'{origin}: {field + ": " if field else ""}nested deeper than '
                              f'{MAX_DEPTH} levels')
    if duplicates:
        container, key = duplicates[0]
        field = _json_path(data, id(container))
        raise ConfigError(f'{origin}: {field + ": " if field else ""}the key {key!r} is '
                          'given twice')
    return data


def load_json(path: str | Path) -> Any:
    """:func:`load_json_text` of a file, read with :func:`read_text`."""
    return load_json_text(read_text(path, MAX_JSON_BYTES), str(path))
