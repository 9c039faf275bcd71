"""mkdocs-gen-files script (mkdocs.yml): write the reference pages generated from the code, and
the API reference pages that mkdocstrings fills from the docstrings."""

import mkdocs_gen_files

from ato_tools import api_pages
from ato_tools.reference_pages import PAGES

for path, page in PAGES.items():
    with mkdocs_gen_files.open(path, 'w') as handle:
        handle.write(page())
for path, text in api_pages.pages().items():
    with mkdocs_gen_files.open(path, 'w') as handle:
        handle.write(text)
