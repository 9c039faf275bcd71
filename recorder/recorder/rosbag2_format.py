"""The rosbag2 Jazzy file format as plain data (no rclpy): QoS profiles as ``metadata.yaml``
version 9 and the MCAP channel metadata hold them, the ``metadata.yaml`` layout, RIHS01 type
hashes, and the log time read from a message's own stamp.

QoS profiles are dicts with the keys and order rosbag2 writes them (``history``, ``depth``,
``reliability``, ``durability``, ``deadline``, ``lifespan``, ``liveliness``,
``liveliness_lease_duration``, ``avoid_ros_namespace_conventions``), policies by their rmw names
(``reliable``, ``transient_local``, ...) and durations as ``{sec, nsec}``. Version 8 files name
the policies by their rmw enum numbers; :func:`parse_qos_profiles` reads both.
"""

from __future__ import annotations

import os
import struct
from functools import lru_cache

import yaml

# metadata.yaml version written (Jazzy: QoS as a list with named policies).
METADATA_VERSION = 9
ROS_DISTRO = 'jazzy'

# The rmw enums (rmw/types.h), number -> name as rmw_qos_*_policy_to_str spells them.
HISTORY = {0: 'system_default', 1: 'keep_last', 2: 'keep_all', 3: 'unknown'}
RELIABILITY = {0: 'system_default', 1: 'reliable', 2: 'best_effort', 3: 'unknown',
               4: 'best_available'}
DURABILITY = {0: 'system_default', 1: 'transient_local', 2: 'volatile', 3: 'unknown',
              4: 'best_available'}
LIVELINESS = {0: 'system_default', 1: 'automatic', 2: 'manual_by_node', 3: 'manual_by_topic',
              4: 'unknown', 5: 'best_available'}
POLICIES = {'history': HISTORY, 'reliability': RELIABILITY, 'durability': DURABILITY,
            'liveliness': LIVELINESS}
DURATIONS = ('deadline', 'lifespan', 'liveliness_lease_duration')
QOS_KEYS = ('history', 'depth', 'reliability', 'durability', 'deadline', 'lifespan',
            'liveliness', 'liveliness_lease_duration', 'avoid_ros_namespace_conventions')
# RMW_DURATION_INFINITE (INT64_MAX ns) and the values older rmw used for it (rosbag2 reads
# them as infinite too).
INFINITE_NS = 2 ** 63 - 1
_OLD_INFINITES = ((0x7FFFFFFF, 0xFFFFFFFF), (0x7FFFFFFF, 0x7FFFFFFF),
                  (INFINITE_NS // 10 ** 9, INFINITE_NS % 10 ** 9))


class FormatError(ValueError):
    """A QoS or metadata entry that is not in the rosbag2 format; the message says which."""


def duration(ns: int) -> dict[str, int]:
    """Nanoseconds as rosbag2 writes a duration."""
    ns = int(ns)
    return {'sec': ns // 10 ** 9, 'nsec': ns % 10 ** 9}


def duration_ns(value) -> int:
    """A ``{sec, nsec}`` duration in nanoseconds; the infinities of every rmw are INFINITE_NS."""
    try:
        sec, nsec = int(value['sec']), int(value['nsec'])
    except (TypeError, KeyError, ValueError):
        raise FormatError(f'{value!r} is not a duration {{sec, nsec}}') from None
    if (sec, nsec) in _OLD_INFINITES or sec * 10 ** 9 + nsec >= INFINITE_NS:
        return INFINITE_NS
    return sec * 10 ** 9 + nsec


def _policy(key: str, value) -> str:
    names = POLICIES[key]
    if isinstance(value, bool):
        raise FormatError(f'{key}: {value!r} is not a policy')
    if isinstance(value, int):
        if value not in names:
            raise FormatError(f'{key}: {value} is not an rmw {key} policy number '
                              f'({", ".join(f"{k}: {v}" for k, v in names.items())})')
        return names[value]
    if isinstance(value, str) and value.lower() in names.values():
        return value.lower()
    raise FormatError(f'{key}: {value!r} is not one of {", ".join(names.values())}')


def normalise_qos(entry) -> dict:
    """One offered profile, from version 8 (numbers) or 9 (names), as version 9 writes it."""
    if not isinstance(entry, dict):
        raise FormatError(f'{entry!r} is not a QoS profile (a mapping)')
    missing = [k for k in QOS_KEYS if k not in entry]
    if missing:
        raise FormatError(f'QoS profile without {", ".join(missing)}')
    out: dict[str, object] = {}
    for key in QOS_KEYS:
        value = entry[key]
        if key in POLICIES:
            out[key] = _policy(key, value)
        elif key in DURATIONS:
            out[key] = duration(duration_ns(value))
        elif key == 'depth':
            if isinstance(value, bool) or not isinstance(value, int) or value < 0:
                raise FormatError(f'depth: {value!r} is not a non-negative integer')
            out[key] = value
        else:
            if not isinstance(value, bool):
                raise FormatError(f'{key}: {value!r} is not true or false')
            out[key] = value
    return out


def parse_qos_profiles(value) -> list[dict]:
    """The offered profiles of a topic: a version 9 list, or the YAML string of version 8 and
    of the MCAP channel metadata (with numbers or names); '' or None is no profile."""
    if value is None or value == '':
        return []
    if isinstance(value, str):
        try:
            value = yaml.safe_load(value)
        except yaml.YAMLError as error:
            raise FormatError(f'offered_qos_profiles is not YAML: {error}') from None
        if value is None:
            return []
    if not isinstance(value, list):
        raise FormatError(f'offered_qos_profiles is not a list of profiles: {value!r}')
    return [normalise_qos(entry) for entry in value]


class _Dumper(yaml.SafeDumper):
    """Block YAML with sequences indented under their key, as yaml-cpp writes them."""

    def increase_indent(self, flow=False, indentless=False):
        return super().increase_indent(flow, False)


def dump_yaml(data) -> str:
    return yaml.dump(data, Dumper=_Dumper, sort_keys=False, default_flow_style=False,
                     allow_unicode=True)


def dump_qos_profiles(profiles: list[dict]) -> str:
    """The ``offered_qos_profiles`` string of an MCAP channel: version 9 YAML."""
    return dump_yaml([normalise_qos(p) for p in profiles]) if profiles else ''


def bag_metadata(*, start_ns: int, end_ns: int, relative_path: str,
                 topics: list[dict], custom_data: dict[str, str] | None,
                 storage_identifier: str = 'mcap', compression_format: str = '',
                 compression_mode: str = '') -> dict:
    """The ``rosbag2_bagfile_information`` of a one-file bag, keys in the order Jazzy writes
    them. ``topics`` holds dicts with name, type, serialization_format, offered_qos_profiles
    (list), type_description_hash and message_count. An empty custom_data is null, as
    yaml-cpp writes an empty map."""
    count = sum(t['message_count'] for t in topics)
    for key, value in (custom_data or {}).items():
        if not isinstance(key, str) or not isinstance(value, str):
            raise FormatError(f'custom_data holds strings only: {key!r}: {value!r}')
    return {
        'version': METADATA_VERSION,
        'storage_identifier': storage_identifier,
        'duration': {'nanoseconds': end_ns - start_ns},
        'starting_time': {'nanoseconds_since_epoch': start_ns},
        'message_count': count,
        'topics_with_message_count': [
            {'topic_metadata': {
                'name': t['name'], 'type': t['type'],
                'serialization_format': t.get('serialization_format', 'cdr'),
                'offered_qos_profiles': [normalise_qos(p) for p in t['offered_qos_profiles']],
                'type_description_hash': t['type_description_hash']},
             'message_count': t['message_count']} for t in topics],
        'compression_format': compression_format,
        'compression_mode': compression_mode,
        'relative_file_paths': [relative_path],
        'files': [{'path': relative_path,
                   'starting_time': {'nanoseconds_since_epoch': start_ns},
                   'duration': {'nanoseconds': end_ns - start_ns},
                   'message_count': count}],
        'custom_data': dict(custom_data) if custom_data else None,
        'ros_distro': os.environ.get('ROS_DISTRO') or ROS_DISTRO,
    }


def opening_metadata(relative_path: str, custom_data: dict[str, str] | None) -> dict:
    """The ``rosbag2_bagfile_information`` rosbag2 Jazzy's writer stores in the ``rosbag2``
    record when it opens a bag (``SequentialWriter::open``: no topic and no message yet, the
    starting times at their "none yet" value, the largest time point, the custom data given)."""
    metadata = bag_metadata(start_ns=NOT_STARTED_NS, end_ns=NOT_STARTED_NS,
                            relative_path=relative_path, topics=[], custom_data=custom_data)
    return metadata


#: the starting time of a bag with no message yet, as rosbag2 initialises it (the largest
#: nanosecond time point)
NOT_STARTED_NS = 2 ** 63 - 1


# Type hashes ------------------------------------------------------------------------------

@lru_cache(maxsize=None)
def _typestore():
    from rosbags.typesys import Stores, get_typestore
    return get_typestore(Stores.ROS2_JAZZY)


def type_hash(type_name: str, definition: str = '') -> str:
    """The RIHS01 hash of a message type (REP-2011), computed by rosbags: from its Jazzy type
    store, or else from the ros2msg ``definition`` (the type and its dependencies). '' when
    neither knows the type, as rosbag2 writes for a type without a hash."""
    from rosbags.typesys import get_types_from_msg
    from rosbags.typesys.base import TypesysError
    store = _typestore()
    if type_name not in store.fielddefs and definition:
        try:
            types = {}
            for index, part in enumerate(definition.split('=' * 80 + '\n')):
                if index == 0:
                    name, text = type_name, part
                else:
                    header, _, text = part.partition('\n')
                    name = header.removeprefix('MSG: ').strip()
                    if '/msg/' not in name:
                        name = name.replace('/', '/msg/')
                types.update(get_types_from_msg(text, name))
            store.register(types)
        except (TypesysError, ValueError, KeyError) as error:
            del error
            return ''
    try:
        return store.hash_rihs01(type_name)
    except (TypesysError, KeyError):
        return ''


# Stamps ------------------------------------------------------------------------------------

_TIME = 'builtin_interfaces/msg/Time'


@lru_cache(maxsize=None)
def starts_with_stamp(type_name: str) -> bool:
    """Whether the type's first field, followed down its first fields, is a
    builtin_interfaces/Time (a std_msgs/Header's stamp, /clock's clock): its CDR bytes then
    carry the stamp right after the encapsulation header."""
    store = _typestore()
    seen = set()
    name = type_name
    while name not in seen:
        seen.add(name)
        if name == _TIME:
            return True
        fields = store.fielddefs.get(name)
        if not fields or not fields[1]:
            return False
        _, (kind, detail) = fields[1][0]
        if getattr(kind, 'name', '') != 'NAME':
            return False
        name = detail
    return False


def cdr_stamp_ns(data: bytes) -> int | None:
    """The Time at the start of a CDR message (after its 4-byte encapsulation header), in ns;
    None when the bytes are too short to hold one or it is not a valid time."""
    if len(data) < 12:
        return None
    endian = '<' if data[1] & 1 else '>'
    sec, nanosec = struct.unpack_from(endian + 'iI', data, 4)
    if sec < 0 or nanosec >= 10 ** 9:
        return None
    return sec * 10 ** 9 + nanosec
