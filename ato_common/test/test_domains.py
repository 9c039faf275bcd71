"""Runs side by side hold distinct DDS domains (ato_common.domains)."""

import pytest

from ato_common import domains
from ato_common.domains import NoFreeDomain, free_domain


def test_concurrent_holders_get_distinct_domains_and_release_them(tmp_path):
    with free_domain(tmp_path) as first, free_domain(tmp_path) as second:
        assert first != second
        assert domains.FIRST_DOMAIN <= first <= domains.LAST_DOMAIN
    with free_domain(tmp_path) as again:
        assert again == first  # released at the end of the block


def test_no_free_domain_is_a_clear_error(tmp_path, monkeypatch):
    monkeypatch.setattr(domains, 'LAST_DOMAIN', domains.FIRST_DOMAIN)
    with free_domain(tmp_path):
        with pytest.raises(NoFreeDomain, match='every one is locked by another run'):
            with free_domain(tmp_path):
                pass
