"""No import cycles among the modules of the suite's packages (function-level imports and
imports under TYPE_CHECKING included): a cycle means code that lives in the wrong module."""

import grimp

from ato_tools.house import PACKAGES as SUITE


def import_cycles(graph) -> list[list[str]]:
    """Every strongly connected component of the import graph with more than one module, and
    every module importing itself: each sorted, the list sorted (Tarjan, iterative)."""
    imports = {m: sorted(graph.find_modules_directly_imported_by(m)) for m in graph.modules}
    index, low, on_stack, stack, cycles = {}, {}, set(), [], []
    for root in sorted(imports):
        if root in index:
            continue
        work = [(root, iter(imports[root]))]
        index[root] = low[root] = len(index)
        stack.append(root)
        on_stack.add(root)
        while work:
            module, successors = work[-1]
            for successor in successors:
                if successor not in imports:
                    continue
                if successor not in index:
                    index[successor] = low[successor] = len(index)
                    stack.append(successor)
                    on_stack.add(successor)
                    work.append((successor, iter(imports[successor])))
                    break
                if successor in on_stack:
                    low[module] = min(low[module], index[successor])
            else:
                work.pop()
                if work:
                    parent = work[-1][0]
                    low[parent] = min(low[parent], low[module])
                if low[module] == index[module]:
                    component = []
                    while True:
                        member = stack.pop()
                        on_stack.discard(member)
                        component.append(member)
                        if member == module:
                            break
                    if len(component) > 1 or module in imports[module]:
                        cycles.append(sorted(component))
    return sorted(cycles)


def describe(graph, cycle: list[str]) -> str:
    """The imports that close a cycle, with their lines."""
    lines = [' <-> '.join(cycle)]
    for importer in cycle:
        for imported in cycle:
            for detail in graph.get_import_details(importer=importer, imported=imported):
                lines.append(f'    {importer} -> {imported} (line {detail["line_number"]}: '
                             f'{detail["line_contents"]})')
    return '\n'.join(lines)


def test_the_suite_has_no_import_cycles():
    graph = grimp.build_graph(*SUITE, cache_dir=None)
    assert {'ato_ros', 'ato_simulation.loop', 'recorder.report'} <= graph.modules
    cycles = import_cycles(graph)
    for cycle in cycles:
        print(describe(graph, cycle))
    assert not cycles, 'import cycles:\n' + '\n'.join(describe(graph, c) for c in cycles)


def test_the_cycle_finder_finds_cycles_through_function_level_imports_and_self_imports(
        tmp_path, monkeypatch):
    package = tmp_path / 'cyclic_pkg'
    package.mkdir()
    files = {
        '__init__.py': '',
        'a.py': 'import cyclic_pkg.b\n',
        'b.py': 'def later():\n    from cyclic_pkg import c\n    return c\n',
        'c.py': 'from cyclic_pkg.a import *  # noqa\n',           # a -> b -> c -> a
        'd.py': 'import cyclic_pkg.a\n',                         # imports the cycle, not in it
        'e.py': 'import cyclic_pkg.e\n',                         # imports itself
        'f.py': 'import cyclic_pkg.d\n',
    }
    for name, text in files.items():
        (package / name).write_text(text)
    monkeypatch.syspath_prepend(str(tmp_path))
    graph = grimp.build_graph('cyclic_pkg', cache_dir=None)
    cycles = import_cycles(graph)
    assert cycles == [['cyclic_pkg.a', 'cyclic_pkg.b', 'cyclic_pkg.c'], ['cyclic_pkg.e']]
    assert 'cyclic_pkg.b -> cyclic_pkg.c (line 2: from cyclic_pkg import c)' in describe(
        graph, cycles[0])


#: the ROS edge: the modules that may import rclpy, an rcl* module, a message package or
#: launch (each node's adapter, the rclpy helpers, the recorder's ROS side, the bring-up)
ROS_EDGE = {
    'ato_ros.lifecycle', 'ato_ros.messages', 'ato_ros.params', 'ato_ros.publishing',
    'train_plant_node.node', 'profile_node.node', 'ato_controller_node.node', 'recorder.node',
    'recorder.live', 'recorder.replay', 'recorder.ros_io', 'recorder.cli',
    # each node's executable: it starts the node (ato_ros.interrupts first, then the adapter)
    'train_plant_node.entry', 'profile_node.entry', 'ato_controller_node.entry',
}
ROS_EDGE_PACKAGES = ('ato_bringup',)


def is_ros(module: str) -> bool:
    """rclpy, an rcl* module, the launch system, the message and interface packages."""
    top = module.split('.')[0]
    return (top in ('rclpy', 'launch', 'launch_ros', 'builtin_interfaces', 'rosidl_runtime_py')
            or top.startswith('rcl') or top.endswith(('_msgs', '_interfaces')))


def ros_reached(graph, module: str) -> str | None:
    """The first import chain from ``module`` to a ROS module, shown, or None."""
    for external in sorted(m for m in graph.modules if is_ros(m)):
        chain = graph.find_shortest_chain(importer=module, imported=external)
        if chain:
            return ' -> '.join(chain)
    return None


def test_the_pure_modules_import_no_ros():
    """Everything but the ROS edge is pure Python: the domain model (ato_common), the cores of
    the nodes, the closed loop, the campaigns. A pure module that reached rclpy (directly or
    through another module) could not be used or tested without ROS."""
    graph = grimp.build_graph(*SUITE, include_external_packages=True, cache_dir=None)
    assert any(is_ros(m) for m in graph.modules), 'the graph must see the ROS imports'
    edge = ROS_EDGE | {m for m in graph.modules if m.split('.')[0] in ROS_EDGE_PACKAGES}
    assert edge - {m for m in edge if m.split('.')[0] in ROS_EDGE_PACKAGES} <= graph.modules
    pure = sorted(m for m in graph.modules if m.split('.')[0] in SUITE and m not in edge)
    assert {'ato_common.scenario', 'ato_simulation.loop', 'train_plant_node.simulation'} <= \
        set(pure)
    reached = [chain for chain in map(lambda m: ros_reached(graph, m), pure) if chain]
    assert not reached, 'pure modules that reach ROS:\n' + '\n'.join(reached)


def test_the_purity_check_finds_a_chain_through_a_pure_module(tmp_path, monkeypatch):
    package = tmp_path / 'mixed_pkg'
    package.mkdir()
    files = {'__init__.py': '', 'core.py': 'import mixed_pkg.helper\n',
             'helper.py': 'def later():\n    import rclpy\n    return rclpy\n',
             'clean.py': 'import math\n'}
    for name, text in files.items():
        (package / name).write_text(text)
    monkeypatch.syspath_prepend(str(tmp_path))
    graph = grimp.build_graph('mixed_pkg', include_external_packages=True, cache_dir=None)
    assert ros_reached(graph, 'mixed_pkg.core') == 'mixed_pkg.core -> mixed_pkg.helper -> rclpy'
    assert ros_reached(graph, 'mixed_pkg.clean') is None
