"""Full ROS 2 message definitions (``ros2msg`` schema encoding) from the installed .msg files,
built as rosbag2 Jazzy's recorder builds the schema of a topic (rosbag2_cpp's local message
definition source, branch jazzy), so that a schema compares equal, byte for byte, with a Jazzy
bag's:

1. The text of a type is its ``.msg`` file as installed, unchanged: comments, blank lines and
   the final newline kept.
2. The types a text depends on are the words that open a line (after any spaces), are followed
   by an optional array bound ``[...]`` and then by white space, and are not primitive types. A
   name without a package (``Header`` in std_msgs) belongs to the package of the file it is
   in; a name with one keeps its spelling (``builtin_interfaces/Time``, no ``msg/``). A bounded
   string (``string<=10``) is not followed by white space and so is no dependency (it is a
   primitive anyway).
3. Each text's dependencies are taken in sorted order (byte order of ``pkg/Type``), each name
   once per text.
4. The full text is the root type's text; then, for each dependency in that order that no
   earlier part of the full text has brought in, a newline, a line of 80 ``=``, a line
   ``MSG: pkg/Type`` and that type's own full text, built by the same rule (depth first). The
   root type itself is not counted as brought in.

Since a ``.msg`` file ends with a newline, rule 4 leaves a blank line before each separator.
Readers such as Foxglove, mcap-ros2-support and rosbags need the dependencies to decode.
"""

from __future__ import annotations

import re
from pathlib import Path

from ament_index_python.packages import PackageNotFoundError, get_package_share_directory

PRIMITIVES = {
    'bool', 'byte', 'char', 'float32', 'float64', 'int8', 'uint8', 'int16', 'uint16', 'int32',
    'uint32', 'int64', 'uint64', 'string',
}
SEPARATOR = '=' * 80
#: rule 2: a word opening a line, an optional array bound, then white space
_DEPENDENCY = re.compile(r'(?:^|\n)\s*([a-zA-Z0-9_/]+)(?:\[[^\]]*\])?\s+')
_TYPE_NAME = re.compile(r'^([a-zA-Z0-9_]+)/(?:msg/)?([a-zA-Z0-9_]+)$')
#: how deep a definition may nest (rosbag2's limit)
MAX_DEPTH = 50


class DefinitionNotFound(LookupError):
    pass


def split_type(type_name: str) -> tuple[str, str]:
    """'std_msgs/msg/Header' or 'std_msgs/Header' -> ('std_msgs', 'Header')."""
    match = _TYPE_NAME.match(type_name)
    if match is None:
        raise ValueError(f"'{type_name}' is not a message type name (pkg/msg/Type)")
    return match.group(1), match.group(2)


def msg_file(package: str, name: str) -> Path:
    try:
        share = Path(get_package_share_directory(package))
    except PackageNotFoundError:
        raise DefinitionNotFound(f'package {package} is not installed') from None
    path = share / 'msg' / f'{name}.msg'
    if not path.is_file():
        raise DefinitionNotFound(f'{path} does not exist')
    return path


def dependencies(package: str, text: str) -> list[str]:
    """The types the .msg ``text`` of a type of ``package`` depends on (rule 2), sorted and
    each once (rule 3), as ``pkg/Type``."""
    found = set()
    for match in _DEPENDENCY.finditer(text):
        name = match.group(1)
        if name in PRIMITIVES:
            continue
        found.add(name if '/' in name else f'{package}/{name}')
    return sorted(found)


def full_definition(type_name: str) -> str:
    """The ros2msg schema text of ``type_name`` (rules 1 to 4); DefinitionNotFound if a file is
    missing, ValueError for a name that is not a type's."""
    seen: set[str] = set()
    texts: dict[str, str] = {}

    def text_of(name: str) -> str:
        if name not in texts:
            texts[name] = msg_file(*split_type(name)).read_text()
        return texts[name]

    def expand(name: str, depth: int) -> str:
        if depth <= 0:
            raise ValueError(f'the definition of {type_name} nests deeper than {MAX_DEPTH} types')
        text = text_of(name)
        parts = [text]
        for dependency in dependencies(split_type(name)[0], text):
            if dependency not in seen:
                seen.add(dependency)
                parts.append(f'\n{SEPARATOR}\nMSG: {dependency}\n'
                             + expand(dependency, depth - 1))
        return ''.join(parts)

    return expand(type_name, MAX_DEPTH)
