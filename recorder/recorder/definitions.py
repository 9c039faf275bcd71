"""Full ROS 2 message definitions (``ros2msg`` schema encoding) from the installed .msg files.

The text is what rosbag2 writes into an MCAP schema: the type's own .msg file, then each type it
depends on, depth first without repetition, each preceded by a line of 80 '=' and
``MSG: pkg/Type``. Readers such as Foxglove and mcap-ros2-support need the dependencies to decode.
"""

from __future__ import annotations

import re
from pathlib import Path

from ament_index_python.packages import PackageNotFoundError, get_package_share_directory

PRIMITIVES = {
    'bool', 'byte', 'char', 'float32', 'float64', 'int8', 'uint8', 'int16', 'uint16', 'int32',
    'uint32', 'int64', 'uint64', 'string', 'wstring',
}
SEPARATOR = '=' * 80


class DefinitionNotFound(LookupError):
    pass


def split_type(type_name: str) -> tuple[str, str]:
    """'std_msgs/msg/Header' or 'std_msgs/Header' -> ('std_msgs', 'Header')."""
    parts = type_name.split('/')
    if len(parts) == 3 and parts[1] == 'msg':
        return parts[0], parts[2]
    if len(parts) == 2:
        return parts[0], parts[1]
    raise ValueError(f"'{type_name}' is not a message type name (pkg/msg/Type)")


def msg_file(package: str, name: str) -> Path:
    try:
        share = Path(get_package_share_directory(package))
    except PackageNotFoundError:
        raise DefinitionNotFound(f'package {package} is not installed') from None
    path = share / 'msg' / f'{name}.msg'
    if not path.is_file():
        raise DefinitionNotFound(f'{path} does not exist')
    return path


_FIELD = re.compile(r'^\s*([A-Za-z][\w/]*)(?:<=\d+)?(\[[^\]]*\])?\s+[A-Za-z]\w*')


def dependencies(package: str, text: str) -> list[tuple[str, str]]:
    """Non-primitive field types of a .msg text, in order, as (package, Type)."""
    found = []
    for line in text.splitlines():
        line = line.split('#', 1)[0].strip()
        if not line:
            continue
        match = _FIELD.match(line)
        if not match:
            continue
        base = match.group(1)
        if base in PRIMITIVES:
            continue
        if '/' in base:
            dep_package, dep_name = base.split('/')[0], base.split('/')[-1]
        else:
            dep_package, dep_name = package, base
        found.append((dep_package, dep_name))
    return found


def full_definition(type_name: str) -> str:
    """The ros2msg schema text of ``type_name``; DefinitionNotFound if a file is missing."""
    package, name = split_type(type_name)
    root = msg_file(package, name).read_text()
    parts = [root.rstrip('\n')]
    seen = {(package, name)}

    def expand(pkg: str, text: str) -> None:
        for dep in dependencies(pkg, text):
            if dep in seen:
                continue
            seen.add(dep)
            dep_text = msg_file(*dep).read_text()
            parts.append(f'{SEPARATOR}\nMSG: {dep[0]}/{dep[1]}\n{dep_text.rstrip(chr(10))}')
            expand(dep[0], dep_text)

    expand(package, root)
    return '\n'.join(parts) + '\n'
