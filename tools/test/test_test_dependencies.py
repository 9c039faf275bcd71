"""Each package's tests import only what its package.xml declares: the suite's packages, and the
third-party libraries of a known map by their rosdep keys. A key declared as depend,
exec_depend or test_depend counts (REP 140: a test_depend does not repeat an exec_depend).
The pip names of the same libraries are in each setup.py's tests_require."""

import ast
import xml.etree.ElementTree as ElementTree
from pathlib import Path

import pytest

from ato_tools.house import PACKAGES as SUITE
from ato_tools.house import REPOSITORY

# import name -> (rosdep key, or None where there is none; pip name)
LIBRARIES = {
    'pytest': ('python3-pytest', 'pytest'),
    'hypothesis': ('python3-hypothesis', 'hypothesis'),
    'numpy': ('python3-numpy', 'numpy'),
    'scipy': ('python3-scipy', 'scipy'),
    'yaml': ('python3-yaml', 'PyYAML'),
    'matplotlib': ('python3-matplotlib', 'matplotlib'),
    # mcap has no rosdep key of its own: mcap-ros2-support requires it
    'mcap': ('mcap-ros2-support', 'mcap'),
    'mcap_ros2': ('mcap-ros2-support', 'mcap-ros2-support'),
    'rosbags': ('python3-rosbags-pip', 'rosbags'),
    'rclpy': ('rclpy', None),
    'grimp': (None, 'grimp'),
    'tornado': ('python3-tornado', 'tornado'),
    'foxglove': (None, 'foxglove-sdk'),
}
DECLARING = ('depend', 'exec_depend', 'test_depend')


def declared(package_xml: Path) -> set[str]:
    root = ElementTree.parse(package_xml).getroot()
    return {element.text.strip() for tag in DECLARING for element in root.iter(tag)}


def pip_test_requirements(setup_py: Path) -> set[str]:
    for node in ast.walk(ast.parse(setup_py.read_text())):
        if isinstance(node, ast.keyword) and node.arg == 'tests_require':
            return set(ast.literal_eval(node.value))
    return set()


def imports(file: Path):
    """(line, module) of every absolute import in ``file``, function-level ones included."""
    for node in ast.walk(ast.parse(file.read_text(), str(file))):
        if isinstance(node, ast.Import):
            yield from ((node.lineno, alias.name) for alias in node.names)
        elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
            yield node.lineno, node.module


def undeclared_test_imports(package_dir: Path, suite=SUITE) -> list[str]:
    """One line per import of ``package_dir/test/*.py`` that the package does not declare."""
    package = package_dir.name
    keys = declared(package_dir / 'package.xml')
    pip = pip_test_requirements(package_dir / 'setup.py') if (package_dir / 'setup.py').exists() \
        else set()
    problems = []
    for file in sorted((package_dir / 'test').glob('*.py')):
        where = file.relative_to(package_dir.parent)
        for line, module in imports(file):
            top = module.split('.')[0]
            if top == package:
                continue
            if top in suite:
                if top not in keys:
                    problems.append(f'{where}:{line}: imports {module}, but {package}/package.xml '
                                    f'does not declare <test_depend>{top}</test_depend>')
                continue
            if top not in LIBRARIES:
                continue
            key, pip_name = LIBRARIES[top]
            if key is not None and key not in keys:
                problems.append(f'{where}:{line}: imports {module}, but {package}/package.xml '
                                f'does not declare <test_depend>{key}</test_depend>')
            if pip_name is not None and pip_name not in pip:
                problems.append(f'{where}:{line}: imports {module}, but {package}/setup.py '
                                f'does not list {pip_name!r} in tests_require')
    return problems


@pytest.mark.parametrize('package', SUITE)
def test_a_package_s_tests_import_only_what_it_declares(package):
    assert (REPOSITORY / package / 'test').is_dir()
    problems = undeclared_test_imports(REPOSITORY / package)
    assert not problems, '\n'.join(problems)


def test_the_check_names_the_file_and_the_undeclared_import(tmp_path):
    package = tmp_path / 'some_node'
    (package / 'test').mkdir(parents=True)
    (package / 'package.xml').write_text(
        '<package format="3"><name>some_node</name><exec_depend>ato_common</exec_depend>'
        '<exec_depend>python3-numpy</exec_depend><test_depend>python3-pytest</test_depend>'
        '</package>')
    (package / 'setup.py').write_text("setup(name='some_node', tests_require=['pytest', "
                                      "'numpy'])\n")
    (package / 'test' / 'test_it.py').write_text(
        'import numpy\nimport pytest\n\nfrom ato_common.types import Command\n'
        'from some_node import core\n\n\ndef test_it():\n'
        '    from ato_simulation.loop import run_offline\n    import hypothesis\n')
    assert undeclared_test_imports(package) == [
        'some_node/test/test_it.py:9: imports ato_simulation.loop, but some_node/package.xml '
        'does not declare <test_depend>ato_simulation</test_depend>',
        'some_node/test/test_it.py:10: imports hypothesis, but some_node/package.xml does not '
        'declare <test_depend>python3-hypothesis</test_depend>',
        "some_node/test/test_it.py:10: imports hypothesis, but some_node/setup.py does not "
        "list 'hypothesis' in tests_require",
    ]
