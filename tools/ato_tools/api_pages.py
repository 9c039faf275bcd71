"""The API reference of the documentation: one page per package of the suite, each module's
docstring and its public classes and functions, rendered by mkdocstrings from the code
(``scripts/gen_reference_docs.py`` writes these pages when the site is built; the nav of
``mkdocs.yml`` names them, so a package without a page, or a page without a package, fails the
strict build).
"""

from __future__ import annotations

import ast
from pathlib import Path

from ato_tools.house import PACKAGES, REPOSITORY

GENERATED = ('*Generated from the docstrings by `ato_tools.api_pages` and mkdocstrings when the '
             'site is built; edit the code, not this page.*')


def modules(package: str) -> list[str]:
    """The package's public modules, in path order: every ``.py`` of its package folder but
    ``__init__`` and private (``_``) modules; sub-packages as dotted names."""
    folder = REPOSITORY / package / package
    found = []
    for path in sorted(folder.rglob('*.py')):
        relative = path.relative_to(folder).with_suffix('')
        if any(part.startswith('_') for part in relative.parts):
            continue
        found.append('.'.join((package, *relative.parts)))
    return found


def summary(package: str) -> str:
    """The first paragraph of the package's docstring, else its package.xml description."""
    init = REPOSITORY / package / package / '__init__.py'
    docstring = ast.get_docstring(ast.parse(init.read_text())) if init.is_file() else None
    if docstring:
        return docstring.split('\n\n')[0]
    import xml.etree.ElementTree as ElementTree
    return ElementTree.parse(REPOSITORY / package / 'package.xml').getroot().findtext(
        'description', '').strip()


def package_page(package: str) -> str:
    lines = [f'# `{package}`', '', GENERATED, '', ' '.join(summary(package).split()), '']
    for module in modules(package):
        lines += [f'::: {module}', '']
    return '\n'.join(lines)


def pages() -> dict[str, str]:
    """Path under ``docs/`` -> the page's text, one per package."""
    return {f'reference/api/{package}.md': package_page(package) for package in PACKAGES}


def source_paths() -> list[Path]:
    """Where mkdocstrings finds the packages: each package's folder (its parent of the code)."""
    return [REPOSITORY / package for package in PACKAGES]
