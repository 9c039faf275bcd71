"""A damaged recording's error tells the user what to type to recover it: ``ros2 run recorder
recover`` with a full ROS 2 install, ``ato run recorder recover`` with the wheels (no ros2)."""

import pytest

from recorder.bag import BagError, read_messages


@pytest.mark.parametrize('ros2_on_path', [False, True])
def test_the_recover_hint_names_the_command_that_works_here(tmp_path, monkeypatch,
                                                            ros2_on_path):
    bin_dir = tmp_path / 'bin'
    bin_dir.mkdir()
    if ros2_on_path:
        (bin_dir / 'ros2').write_text('#!/bin/sh\n')
        (bin_dir / 'ros2').chmod(0o755)
    monkeypatch.setenv('PATH', str(bin_dir))
    damaged = tmp_path / 'run.mcap'
    damaged.write_bytes(b'\x89MCAP0\r\n' + b'\x00' * 40)  # the magic, then nothing readable
    with pytest.raises(BagError) as error:
        list(read_messages(damaged))
    cli = 'ros2' if ros2_on_path else 'ato'
    assert f'with: {cli} run recorder recover {damaged}' in str(error.value), str(error.value)
