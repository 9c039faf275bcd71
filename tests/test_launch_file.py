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
            'LogInfo': recorder_class('LogInfo', 'msg'),
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


RUNNING = types.SimpleNamespace(is_shutdown=False)  # a launch context, not shutting down


def stack_entities(launch_file, namespace='', **configurations):
    description = launch_file.generate_launch_description()
    entities = description.kwargs['initial_entities']
    declared = {e.kwargs['name'] for e in entities if type(e).__name__ == 'DeclareLaunchArgument'}
    assert {'controller', 'scenario', 'model', 'lockstep', 'rate_hz', 'end_time_s',
            'namespace'} <= declared
    opaque = [e for e in entities if type(e).__name__ == 'OpaqueFunction']
    assert len(opaque) == 1
    context = types.SimpleNamespace(launch_configurations={'namespace': namespace,
                                                           **configurations})
    return opaque[0].kwargs['function'](context)


def node_parameters(node) -> dict:
    """A Node's parameters, text values unwrapped (ParameterValue(value_type=str))."""
    (parameters,) = node.kwargs['parameters']
    return {name: value.kwargs['value'] if type(value).__name__ == 'ParameterValue' else value
            for name, value in parameters.items()}


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
        log, emit = on_exit(types.SimpleNamespace(returncode=0), RUNNING)
        assert type(emit.kwargs['event']).__name__ == 'Shutdown'
        assert name in emit.kwargs['event'].kwargs['reason'] and name in log.kwargs['msg']
        for code in (2, 1, -9):
            with pytest.raises(launch_file.NodeFailed, match=f'{name} exited with code {code}'):
                on_exit(types.SimpleNamespace(returncode=code), RUNNING)


def test_once_the_launch_stops_an_exit_is_expected_not_a_failure(launch_file):
    """Ctrl-C: every node ends (a node still importing with its signal's code); the launch
    ends with 0, not with "the run has failed"."""
    stopping = types.SimpleNamespace(is_shutdown=True)
    for node in [e for e in stack_entities(launch_file) if type(e).__name__ == 'Node']:
        (handler,) = [e.kwargs['event_handler'] for e in stack_entities(launch_file)
                      if type(e).__name__ == 'RegisterEventHandler'
                      and e.kwargs['event_handler'].kwargs['target_action'].kwargs['name']
                      == node.kwargs['name']]
        for code in (0, -2, 1):
            assert handler.kwargs['on_exit'](types.SimpleNamespace(returncode=code),
                                             stopping) is None


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
        handler.kwargs['on_exit'](types.SimpleNamespace(returncode=2), RUNNING)
    (path,) = node.kwargs['parameters']
    sections = yaml.safe_load(Path(path).read_text())
    Path(path).unlink()
    assert set(sections) == {f'/**/{name}' for name in launch_file.NODES}
    controller = sections['/**/ato_controller_node']['ros__parameters']
    assert controller['controller'] == 'luo_xu' and controller['lockstep'] is True
    plant = sections['/**/train_plant_node']['ros__parameters']
    assert plant['end_time_s'] == 12.5 and 'controller' not in plant
    assert plant['model'] == 'point_mass'
    # composed, the 4-car unit gets the multi-car plant too
    configurations.update(scenario='mao_4car', controller='mao_multibody_rigid')
    entities = opaque.kwargs['function'](types.SimpleNamespace(
        launch_configurations=configurations))
    (node,) = [e for e in entities if type(e).__name__ == 'Node']
    (path,) = node.kwargs['parameters']
    sections = yaml.safe_load(Path(path).read_text())
    Path(path).unlink()
    assert sections['/**/train_plant_node']['ros__parameters']['model'] == 'multi_car'


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


def test_the_plant_model_follows_the_scenario_unless_named(launch_file):
    from ato_bringup.launch_arguments import LaunchRefused
    entities = stack_entities(launch_file, scenario='mao_4car', controller='mao_multibody_rigid')
    nodes = {n.kwargs['name']: n for n in entities if type(n).__name__ == 'Node'}
    plant = node_parameters(nodes['train_plant_node'])
    assert plant['model'] == 'multi_car' and plant['scenario'] == 'mao_4car'
    assert any('multi_car' in e.kwargs['msg'] for e in entities if type(e).__name__ == 'LogInfo')
    # a law that cannot drive the plant it is given: refused before any node, naming why
    with pytest.raises(LaunchRefused, match='mao_multibody_rigid cannot drive scenario mao_4car '
                                            'on the point_mass plant: .*4 cars'):
        stack_entities(launch_file, scenario='mao_4car', controller='mao_multibody_rigid',
                       model='point_mass')
    with pytest.raises(LaunchRefused, match='mao_2017 cannot drive scenario mao_4car'):
        stack_entities(launch_file, scenario='mao_4car', controller='mao_2017')


def test_the_run_ends_at_the_scenario_s_end_unless_told_otherwise(launch_file):
    from ato_bringup.launch_arguments import LaunchRefused
    from ato_common.scenario import load_scenario
    from ato_simulation.plans import cached_plan, run_end_time_s

    def plant(**configurations):
        (node,) = [n for n in stack_entities(launch_file, **configurations)
                   if type(n).__name__ == 'Node' and n.kwargs['name'] == 'train_plant_node']
        return node_parameters(node)
    scenario = load_scenario('short_line')
    assert plant()['end_time_s'] == run_end_time_s(scenario, cached_plan(scenario)) > 900.0
    assert plant(end_time_s='never')['end_time_s'] == 0.0  # the plant's "run on"
    assert plant(end_time_s='300')['end_time_s'] == 300.0
    with pytest.raises(LaunchRefused, match="end_time_s:=0: .*never"):
        plant(end_time_s='0')
    # under a launch the plant's last wait fits launch's 5 s escalation from SIGINT to SIGTERM
    assert plant()['final_delivery_timeout_s'] < 5.0


def test_text_parameters_stay_text_and_a_law_gets_the_rate_it_applies_at(launch_file):
    entities = stack_entities(launch_file, controller='liu_li')
    nodes = {n.kwargs['name']: n for n in entities if type(n).__name__ == 'Node'}
    (controller,) = nodes['ato_controller_node'].kwargs['parameters']
    # launch_ros reads a plain text value as YAML: a scenario named "on" would become true
    assert type(controller['scenario']).__name__ == 'ParameterValue'
    assert controller['scenario'].kwargs['value_type'] is str
    assert node_parameters(nodes['ato_controller_node'])['rate_hz'] == 200.0
    assert node_parameters(nodes['train_plant_node'])['control_rate_hz'] == 200.0
