"""The documentation: a short README that points into the site, reference pages generated from
the code that cover every topic, parameter, law, scenario and preset, and a navigation that
holds every page."""

import re
import subprocess
from pathlib import Path

import yaml

from ato_common.conventions import TOPICS
from ato_common.scenario import builtin_scenarios
from ato_common.trains import TRAIN_PRESETS
from ato_controller_node.laws import LAWS
from ato_controller_node.node import NODE_PARAMS, gain_params
from ato_tools import api_pages, reference_pages
from profile_node.node import PARAMS as PROFILE_PARAMS
from train_plant_node.node import PARAMS as PLANT_PARAMS

ROOT = Path(__file__).resolve().parents[2]
README = (ROOT / 'README.md').read_text()


def test_the_readme_is_short_and_points_into_the_docs():
    assert len(README.encode()) <= 10_500, 'the README is at most about 10 KB: move detail to docs/'
    for path in re.findall(r'`(docs/[^`]+)`', README):
        assert (ROOT / path).exists(), f'the README names {path}, which does not exist'


def test_ci_runs_the_readme_test_command():
    ci = (ROOT / '.ci/run').read_text()
    assert 'make test' in README and 'make test' in ci


def _nav_pages(entries) -> list[str]:
    pages = []
    for entry in entries:
        value = next(iter(entry.values())) if isinstance(entry, dict) else entry
        pages += _nav_pages(value) if isinstance(value, list) else [value]
    return pages


def test_every_page_is_in_the_navigation_and_every_generated_page_too():
    config = yaml.safe_load((ROOT / 'mkdocs.yml').read_text())
    nav = _nav_pages(config['nav'])
    written = sorted(str(p.relative_to(ROOT / 'docs')) for p in (ROOT / 'docs').rglob('*.md'))
    generated = set(reference_pages.PAGES) | set(api_pages.pages())
    assert sorted(set(nav) - generated) == written
    assert generated <= set(nav)


def test_the_reference_pages_cover_the_code():
    topics = reference_pages.topics_page()
    for t in TOPICS.values():
        assert f'| `{t.name}` | `{t.type_name}` | {t.qos.describe()} |' in topics, t.name
    parameters = reference_pages.parameters_page()
    for p in PLANT_PARAMS + PROFILE_PARAMS + NODE_PARAMS + tuple(gain_params()):
        assert f'| `{p.name}` |' in parameters, p.name
    laws = reference_pages.laws_page()
    for name in LAWS:
        assert f'\n## {name}\n' in laws, name
    scenarios = reference_pages.scenarios_page()
    for name in builtin_scenarios():
        assert f'\n## {name}\n' in scenarios, name
    trains = reference_pages.trains_page()
    for name in TRAIN_PRESETS:
        assert f'\n## {name}\n' in trains, name


def test_a_changed_description_changes_the_generated_page(monkeypatch):
    """The pages are computed from the code each time, not kept: change a topic's description
    and the page changes with it."""
    from dataclasses import replace
    name = next(iter(TOPICS))
    changed = dict(TOPICS)
    changed[name] = replace(TOPICS[name], description='a description only this test uses')
    monkeypatch.setattr(reference_pages, 'TOPICS', changed)
    assert 'a description only this test uses' in reference_pages.topics_page()


#: a code span that names a file of the repository
_PATH = re.compile(r'`([A-Za-z0-9_.\-]+(?:/[A-Za-z0-9_.\-]+)+'
                   r'\.(?:py|yaml|yml|json|md|sh|txt|xml|toml|ini))(?:::[A-Za-z0-9_]+)?[ `]')
#: paths that are examples or made by a run, not files of the repository
_NOT_IN_REPOSITORY = ('runs/', 'journeys/', 'trains/', 'tracks/', '/path/', 'share/')


def test_every_file_the_docs_name_exists():
    """A hand-written page that names a file of the repository (a test, a module, a data
    file) names one that exists: a moved file fails here until the page follows it."""
    tracked = subprocess.run(['git', '-C', str(ROOT), 'ls-files'], capture_output=True,
                             text=True, check=True).stdout.split()
    missing = []
    for page in [ROOT / 'README.md', *sorted((ROOT / 'docs').rglob('*.md'))]:
        for number, line in enumerate(page.read_text().splitlines(), 1):
            for path in _PATH.findall(line + ' '):
                if path.startswith(_NOT_IN_REPOSITORY) or 'my_' in path or 'example' in path:
                    continue
                # a path relative to the repository, or to a package folder (`laws/base.py`)
                if not (ROOT / path).exists() and not any(t.endswith('/' + path)
                                                          for t in tracked):
                    missing.append(f'{page.relative_to(ROOT)}:{number}: {path}')
    assert not missing, 'the docs name files that do not exist:\n' + '\n'.join(missing)


def test_the_api_reference_has_a_page_per_package_naming_every_public_module():
    from ato_tools.house import PACKAGES
    pages = api_pages.pages()
    assert sorted(pages) == sorted(f'reference/api/{p}.md' for p in PACKAGES)
    common = pages['reference/api/ato_common.md']
    assert '::: ato_common.scenario\n' in common and '::: ato_common.units\n' in common
    assert '::: ato_controller_node.laws.pid\n' in pages['reference/api/ato_controller_node.md']
    assert not any('._' in line for page in pages.values() for line in page.splitlines()
                   if line.startswith(':::'))
