"""mkdocs-gen-files script (mkdocs.yml): write the reference pages generated from the code."""

import mkdocs_gen_files

from ato_tools.reference_pages import PAGES

for path, page in PAGES.items():
    with mkdocs_gen_files.open(path, 'w') as handle:
        handle.write(page())
