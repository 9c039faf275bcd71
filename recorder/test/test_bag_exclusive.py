"""Two recorders given one folder at the same moment: the second is refused, the first's file
is its own (the file is created exclusively)."""

import pytest

from recorder import bag
from recorder.bag import BagError, BagWriter


def test_a_bag_file_created_meanwhile_by_another_recorder_is_refused(tmp_path, monkeypatch):
    folder = tmp_path / 'bag'
    real_bag_file = bag.bag_file

    def another_recorder_gets_there_first(path):
        target = real_bag_file(path)
        target.write_bytes(b'the other recorder')  # between the emptiness check and the open
        return target

    monkeypatch.setattr(bag, 'bag_file', another_recorder_gets_there_first)
    with pytest.raises(BagError, match='just created by another recorder'):
        BagWriter(folder)
    assert real_bag_file(folder).read_bytes() == b'the other recorder'
