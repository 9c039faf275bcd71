"""docs/extending.md is followed as written. In a copy of the repository the law's module is
written where the page says, registered in the tuple that builds ``LAWS``, the preset is added to
``trains.py`` and ``TRAIN_PRESETS``, the scenario becomes a built-in file; then the registry-wide
tests run there, in a fresh process that imports the copy: every law, every preset, every
built-in scenario, the papers' notes, the lists of laws and the reference pages, with the
examples in. A step of the page that the tests refuse fails here."""

import os
import re
import shutil
import subprocess
import sys
from pathlib import Path

import pytest
import yaml

from ato_common import conventions
from ato_common.scenario import parse_scenario
from ato_tools import reference_pages
from ato_tools.house import REPOSITORY

PAGE = (REPOSITORY / 'docs/extending.md').read_text()
#: the packages the walk-through edits: the copy's are imported instead of the installed ones
EDITED = ('ato_common', 'ato_controller_node')
#: the registry-wide test files, run whole in the copy
REGISTRY_WIDE = (
    'ato_controller_node/test/test_paper_notes.py',
    'ato_controller_node/test/test_control_laws.py',
    'ato_controller_node/test/test_properties_laws.py',
    'ato_common/test/test_units_and_trains.py',
    'ato_common/test/test_scenario.py',
    'ato_common/test/test_knowledge.py',
    'profile_node/test/test_target_curve.py',
    'tools/test/test_law_lists.py',
    'tools/test/test_docs.py',
)
#: the example's own cases of the tests parametrised over every law or scenario
PARAMETRISED = ('ato_simulation/test/test_offline_equivalence.py',)


def _blocks(language: str) -> list[str]:
    blocks = re.findall(rf'^( *)```{language}\n(.*?)^\1```', PAGE, flags=re.S | re.M)
    return ['\n'.join(line[len(indent):] for line in body.splitlines())
            for indent, body in blocks]


def test_the_page_has_the_four_walk_throughs():
    assert len(_blocks('python')) == 3 and len(_blocks('yaml')) == 1
    for heading in ('Add a control law', 'Add a train preset', 'Add a scenario', 'Add a topic'):
        assert f'\n## {heading}\n' in PAGE


def _copy_of_the_repository(target: Path) -> Path:
    """The files git knows (tracked, or new and not ignored), as they are now, in a repository
    of their own (the lists-of-laws check asks git for the files)."""
    listed = subprocess.run(['git', 'ls-files', '-co', '--exclude-standard', '-z'],
                            cwd=REPOSITORY, capture_output=True, check=True).stdout
    for name in filter(None, listed.decode().split('\0')):
        source = REPOSITORY / name
        if source.is_symlink():  # ros_ws/src: the list of packages, kept as links
            (target / name).parent.mkdir(parents=True, exist_ok=True)
            (target / name).symlink_to(source.readlink())
        elif source.is_file():
            (target / name).parent.mkdir(parents=True, exist_ok=True)
            shutil.copy2(source, target / name)
    subprocess.run(['git', 'init', '-q'], cwd=target, check=True)
    subprocess.run(['git', 'add', '-A'], cwd=target, check=True)
    return target


def _follow_the_page(root: Path) -> None:
    """Each step as the page gives it."""
    law_block, preset_block, _ = _blocks('python')
    laws = root / 'ato_controller_node/ato_controller_node/laws'
    # 1. the module, as `laws/pd_example.py`
    (laws / 'pd_example.py').write_text(law_block + '\n')
    # 2. the class added to the tuple that builds LAWS in laws/__init__.py
    registry = laws / '__init__.py'
    text = registry.read_text()
    text = text.replace('\nLAWS: dict', '\nfrom ato_controller_node.laws.pd_example import '
                                          'PdExampleLaw\n\nLAWS: dict', 1)
    text, count = re.subn(r'(LAWS: dict\[.*?\] = \{law\.name: law for law in \(\n)',
                          r'\1    PdExampleLaw,\n', text, count=1)
    assert count == 1, 'laws/__init__.py no longer builds LAWS from a tuple: update the page'
    registry.write_text(text)
    # the preset: the function in trains.py and its entry in TRAIN_PRESETS
    trains = root / 'ato_common/ato_common/trains.py'
    text = trains.read_text()
    function = '\n'.join(line for line in preset_block.splitlines()
                         if not line.startswith(('from ', 'import ')))
    text, count = re.subn(r'\nTRAIN_PRESETS = \{\n',
                          '\n' + function.strip() + '\n\n\nTRAIN_PRESETS = {\n'
                          "    'example_8car': _example_8car,\n", text, count=1)
    assert count == 1, 'trains.py has no TRAIN_PRESETS dict: update the page'
    trains.write_text(text)
    # the scenario: a built-in one is a file in ato_common/ato_common/scenarios/
    scenario = yaml.safe_load(_blocks('yaml')[0])
    scenario['train'] = {'preset': 'example_8car'}
    (root / 'ato_common/ato_common/scenarios/example_line.yaml').write_text(
        yaml.safe_dump(scenario, sort_keys=False))


def _pytest(root: Path, *args: str) -> subprocess.CompletedProcess:
    env = dict(os.environ)
    env['PYTHONPATH'] = os.pathsep.join(
        [str(root / package) for package in EDITED] + [str(root / 'tools')]
        + [p for p in env.get('PYTHONPATH', '').split(os.pathsep) if p])
    return subprocess.run([sys.executable, '-m', 'pytest', '-q', '-rA', '-p', 'no:cacheprovider',
                           '-p', 'no:randomly', *args], cwd=root, env=env, capture_output=True,
                          text=True, timeout=1200, check=False)


def test_following_the_page_gives_a_law_preset_and_scenario_the_registry_wide_tests_accept(
        tmp_path):
    root = _copy_of_the_repository(tmp_path / 'repository')
    _follow_the_page(root)
    done = _pytest(root, *REGISTRY_WIDE)
    assert done.returncode == 0, done.stdout[-6000:] + done.stderr[-3000:]
    # the copy, not the installed packages, was tested: the examples are among the cases
    assert 'example_line' in done.stdout and 'example_8car' in done.stdout
    done = _pytest(root, *PARAMETRISED, '-k', 'pd_example')
    assert done.returncode == 0, done.stdout[-6000:] + done.stderr[-3000:]
    assert re.search(r'PASSED .*pd_example', done.stdout), done.stdout[-3000:]


def test_the_example_scenario_parses_as_the_page_shows_it():
    scenario = parse_scenario(yaml.safe_load(_blocks('yaml')[0]), 'extending.md')
    assert [s.name for s in scenario.line.stations] == ['Origin', 'Middle', 'Terminus']


def test_the_example_topic_appears_on_the_topics_page(monkeypatch):
    namespace = {}
    exec(_blocks('python')[2], namespace)  # noqa: S102 - the page's own example
    monkeypatch.setitem(conventions.TOPICS, 'example', namespace['TOPIC'])
    monkeypatch.setattr(reference_pages, 'TOPICS', conventions.TOPICS)
    assert '| `ato/example` | `std_msgs/msg/Float64` |' in reference_pages.topics_page()


@pytest.mark.parametrize('step', ['law', 'registration', 'preset'])
def test_a_step_the_tests_refuse_fails_the_walk_through(tmp_path, step):
    """The walk-through can fail: a law without ``paper``, a registration the registry does not
    see, or a preset without its maximum speed's source each make the registry-wide tests
    fail."""
    root = _copy_of_the_repository(tmp_path / 'repository')
    _follow_the_page(root)
    if step == 'law':
        module = root / 'ato_controller_node/ato_controller_node/laws/pd_example.py'
        text, count = re.subn(r'^ *paper = None.*\n', '', module.read_text(), flags=re.M)
        assert count == 1
        module.write_text(text)
        tests = ('ato_controller_node/test/test_paper_notes.py',)
    elif step == 'registration':
        registry = root / 'ato_controller_node/ato_controller_node/laws/__init__.py'
        registry.write_text(registry.read_text().replace('    PdExampleLaw,\n', ''))
        tests = ('ato_simulation/test/test_offline_equivalence.py', '-k', 'pd_example')
    else:
        trains = root / 'ato_common/ato_common/trains.py'
        trains.write_text(trains.read_text().replace(
            "                 'max_speed_mps': 'the design maximum speed, and where it is "
            "stated'},", '},'))
        tests = ('ato_common/test/test_units_and_trains.py',)
    assert _pytest(root, *tests).returncode != 0
