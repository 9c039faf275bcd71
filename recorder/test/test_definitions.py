"""The ros2msg schema texts against the rules by which rosbag2 Jazzy's recorder builds them
(recorder.definitions states them): the .msg files verbatim, a blank line before each
separator, the dependencies of each text in sorted order, depth first, each type once."""

import pytest

from ato_common.conventions import TOPICS
from recorder.definitions import SEPARATOR, dependencies, full_definition, msg_file, split_type


def text(type_name: str) -> str:
    return msg_file(*split_type(type_name)).read_text()


def part(type_name: str) -> str:
    """A dependency's part of a full text: the separator, its name, its file."""
    return f'\n{SEPARATOR}\nMSG: {type_name}\n{text(type_name)}'


def test_diagnostic_array_lists_its_dependencies_in_sorted_order_depth_first():
    # DiagnosticArray names std_msgs/Header before DiagnosticStatus; the sorted order puts
    # diagnostic_msgs/DiagnosticStatus (and its KeyValue) first, then the Header and its Time.
    expected = (text('diagnostic_msgs/msg/DiagnosticArray')
                + part('diagnostic_msgs/DiagnosticStatus') + part('diagnostic_msgs/KeyValue')
                + part('std_msgs/Header') + part('builtin_interfaces/Time'))
    assert full_definition('diagnostic_msgs/msg/DiagnosticArray') == expected


def test_a_file_s_own_newline_leaves_a_blank_line_before_each_separator():
    full = full_definition('trajectory_msgs/msg/JointTrajectory')
    assert full.count(SEPARATOR) == 4
    assert full.count(f'\n\n{SEPARATOR}\n') == 4
    assert full.startswith(text('trajectory_msgs/msg/JointTrajectory'))
    assert full.endswith(text('builtin_interfaces/Duration'))  # no newline added at the end


def sections(full: str) -> list[tuple[str, str]]:
    """(type, text) of each part of a full text, the root first (named '')."""
    pieces = full.split(f'\n{SEPARATOR}\nMSG: ')
    out = [('', pieces[0])]
    for piece in pieces[1:]:
        name, _, body = piece.partition('\n')
        out.append((name, body))
    return out


def preorder(root: str) -> list[str]:
    """The order the rules give, walked independently of full_definition: each text's
    dependencies sorted, depth first, each type once over the whole text."""
    seen, order = set(), []

    def walk(name: str) -> None:
        for dependency in dependencies(split_type(name)[0], text(name)):
            if dependency not in seen:
                seen.add(dependency)
                order.append(dependency)
                walk(dependency)
    walk(root)
    return order


@pytest.mark.parametrize('type_name', sorted({t.type_name for t in TOPICS.values()}
                                            | {'rcl_interfaces/msg/Log',
                                               'rcl_interfaces/msg/ParameterEvent'}))
def test_every_recorded_type_follows_the_rules(type_name):
    full = sections(full_definition(type_name))
    assert full[0] == ('', text(type_name))                     # rule 1: the file verbatim
    for name, body in full[1:]:
        assert body == text(name), name                         # rule 1, each dependency
        assert '/msg/' not in name                              # named as the field names it
    assert [name for name, _ in full[1:]] == preorder(type_name)  # rules 3 and 4
    for (_, before), _ in zip(full, full[1:]):
        assert before.endswith('\n')                            # the blank line before '===='


def test_which_words_are_dependencies():
    msg = ('# Header h: a comment names no type\n'
           'Header header\n'
           'string<=10 bounded\n'
           'Point[<=3] few  # unqualified: this package\n'
           'geometry_msgs/Vector3[] many\n'
           'uint8 OK=0\n'
           '  builtin_interfaces/Time indented\n'
           'float64 x 0.5\n')
    assert dependencies('my_msgs', msg) == ['builtin_interfaces/Time',
                                            'geometry_msgs/Vector3', 'my_msgs/Header',
                                            'my_msgs/Point']


def test_a_type_name_that_is_not_one_is_refused():
    with pytest.raises(ValueError, match='is not a message type name'):
        full_definition('not a type')
    assert split_type('std_msgs/Header') == split_type('std_msgs/msg/Header') == (
        'std_msgs', 'Header')
