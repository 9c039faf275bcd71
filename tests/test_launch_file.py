"""The launch file's own logic, without the launch package (not installable from the Jazzy
wheels): the launch and launch_ros classes it uses are replaced by recorders with the real
keyword-only signatures (launch 3.4, launch_ros 0.26), so a wrong keyword fails here as it
would under ``ros2 launch``. What is checked: every node is watched by an OnProcessExit handler,
a node that ends with 0 shuts the launch down with its name, one that fails raises (launch logs
it as an error and exits with 1) naming the node and its code, and the namespace argument
pushes each node into it with a /clock of its own."""

import importlib.util
import sys
import types
from pathlib import Path

import pytest

LAUNCH_FILE = Path(__file__).parents[1] / 'ato_bringup/launch/ato.launch.py'


def recorder_class(name, *keywords, positional=()):
    """A class that keeps the keywords it was built with and refuses any other."""
    def __init__(self, *args, **kwargs):
        if len(args) > len(positional):
            raise TypeError(f'{name} takes {len(positional)} positional arguments')
        kwargs.update(dict(zip(positional, args)))
        unknown = set(kwargs) - set(keywords) - set(positional)
        if unknown:
            raise TypeError(f'{name}() got unexpected keyword arguments {sorted(unknown)}')
        self.kwargs = kwargs
    return type(name, (), {'__init__': __init__})


@pytest.fixture
def launch_file(monkeypatch):
    modules = {
        'launch': {'LaunchDescription': recorder_class('LaunchDescription', 'initial_entities',
                                                       positional=('initial_entities',))},
        'launch.actions': {
            'DeclareLaunchArgument': recorder_class(
                'DeclareLaunchArgument', 'default_value', 'description', 'choices',
                positional=('name',)),
            'EmitEvent': recorder_class('EmitEvent', 'event'),
            'OpaqueFunction': recorder_class('OpaqueFunction', 'function', 'args', 'kwargs'),
            'RegisterEventHandler': recorder_class('RegisterEventHandler', 'event_handler',
                                                   positional=('event_handler',)),
            'SetEnvironmentVariable': recorder_class('SetEnvironmentVariable',
                                                     positional=('name', 'value'))},
        'launch.event_handlers': {'OnProcessExit': recorder_class(
            'OnProcessExit', 'target_action', 'on_exit', 'handle_once')},
        'launch.events': {'Shutdown': recorder_class('Shutdown', 'reason', 'due_to_sigint')},
        'launch.substitutions': {'LaunchConfiguration': recorder_class(
            'LaunchConfiguration', 'default', positional=('variable_name',))},
        'launch_ros': {},
        'launch_ros.actions': {'Node': recorder_class(
            'Node', 'executable', 'package', 'name', 'namespace', 'exec_name', 'parameters',
            'remappings', 'ros_arguments', 'arguments', 'output')},
        'launch_ros.parameter_descriptions': {'ParameterValue': recorder_class(
            'ParameterValue', 'value_type', positional=('value',))},
    }
    for module_name, names in modules.items():
        module = types.ModuleType(module_name)
        module.__dict__.update(names)
        monkeypatch.setitem(sys.modules, module_name, module)
    spec = importlib.util.spec_from_file_location('ato_launch_under_test', LAUNCH_FILE)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def stack_entities(launch_file, namespace=''):
    description = launch_file.generate_launch_description()
    entities = description.kwargs['initial_entities']
    declared = {e.kwargs['name'] for e in entities if type(e).__name__ == 'DeclareLaunchArgument'}
    assert {'controller', 'scenario', 'lockstep', 'rate_hz', 'end_time_s',
            'namespace'} <= declared
    opaque = [e for e in entities if type(e).__name__ == 'OpaqueFunction']
    assert len(opaque) == 1
    context = types.SimpleNamespace(launch_configurations={'namespace': namespace})
    return opaque[0].kwargs['function'](context)


def test_every_node_is_watched_and_its_exit_ends_the_launch(launch_file):
    entities = stack_entities(launch_file)
    nodes = [e for e in entities if type(e).__name__ == 'Node']
    handlers = [e.kwargs['event_handler'] for e in entities
                if type(e).__name__ == 'RegisterEventHandler']
    assert sorted(n.kwargs['name'] for n in nodes) == sorted(launch_file.NODES)
    watched = {id(h.kwargs['target_action']): h for h in handlers}
    assert set(watched) == {id(n) for n in nodes}  # one handler per node, none for another
    for node in nodes:
        name = node.kwargs['name']
        on_exit = watched[id(node)].kwargs['on_exit']
        actions = on_exit(types.SimpleNamespace(returncode=0), None)
        (emit,) = actions
        assert type(emit.kwargs['event']).__name__ == 'Shutdown'
        assert name in emit.kwargs['event'].kwargs['reason']
        for code in (2, 1, -9):
            with pytest.raises(launch_file.NodeFailed, match=f'{name} exited with code {code}'):
                on_exit(types.SimpleNamespace(returncode=code), None)


def test_the_namespace_argument_gives_each_node_its_clock(launch_file):
    root = [e for e in stack_entities(launch_file, '') if type(e).__name__ == 'Node']
    assert all(n.kwargs['namespace'] == '/' and n.kwargs['remappings'] == [] for n in root)
    pushed = [e for e in stack_entities(launch_file, 'train1') if type(e).__name__ == 'Node']
    for node in pushed:
        assert node.kwargs['namespace'] == '/train1'
        assert node.kwargs['remappings'] == [('/clock', '/train1/clock')]
    with pytest.raises(ValueError, match='namespace'):
        stack_entities(launch_file, 'train 1')


def test_composed_starts_one_process_with_a_section_per_node(launch_file):
    import yaml
    description = launch_file.generate_launch_description()
    declared = {e.kwargs['name']: e for e in description.kwargs['initial_entities']
                if type(e).__name__ == 'DeclareLaunchArgument'}
    assert declared['composed'].kwargs['default_value'] == 'false'
    (opaque,) = [e for e in description.kwargs['initial_entities']
                 if type(e).__name__ == 'OpaqueFunction']
    configurations = {'namespace': 'train1', 'composed': 'true', 'controller': 'luo_xu',
                      'scenario': 'short_line', 'lockstep': 'true', 'rate_hz': '0.0',
                      'end_time_s': '12.5'}
    entities = opaque.kwargs['function'](types.SimpleNamespace(
        launch_configurations=configurations))
    (node,) = [e for e in entities if type(e).__name__ == 'Node']
    (handler,) = [e.kwargs['event_handler'] for e in entities
                  if type(e).__name__ == 'RegisterEventHandler']
    assert (node.kwargs['package'], node.kwargs['executable']) == ('ato_bringup', 'ato_stack')
    assert 'name' not in node.kwargs  # a name would rename all three nodes of the process
    assert node.kwargs['namespace'] == '/train1'
    assert node.kwargs['remappings'] == [('/clock', '/train1/clock')]
    assert handler.kwargs['target_action'] is node
    with pytest.raises(launch_file.NodeFailed, match='ato_stack .* exited with code 2'):
        handler.kwargs['on_exit'](types.SimpleNamespace(returncode=2), None)
    (path,) = node.kwargs['parameters']
    sections = yaml.safe_load(Path(path).read_text())
    Path(path).unlink()
    assert set(sections) == {f'/**/{name}' for name in launch_file.NODES}
    controller = sections['/**/ato_controller_node']['ros__parameters']
    assert controller['controller'] == 'luo_xu' and controller['lockstep'] is True
    plant = sections['/**/train_plant_node']['ros__parameters']
    assert plant['end_time_s'] == 12.5 and 'controller' not in plant


def test_the_nodes_get_the_middleware_defaults_unless_the_user_set_them(launch_file,
                                                                          monkeypatch):
    from ato_ros.middleware import DEFAULTS, FASTDDS_PROFILE

    def environment():
        return {e.kwargs['name']: e.kwargs['value']
                for e in launch_file.generate_launch_description().kwargs['initial_entities']
                if type(e).__name__ == 'SetEnvironmentVariable'}
    for name in DEFAULTS:
        monkeypatch.delenv(name, raising=False)
    assert environment() == DEFAULTS
    assert FASTDDS_PROFILE.is_file()
    monkeypatch.setenv('FASTRTPS_DEFAULT_PROFILES_FILE', '/their/own.xml')
    assert 'FASTRTPS_DEFAULT_PROFILES_FILE' not in environment()
