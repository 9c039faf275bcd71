"""Issue 31, defect 5: a replay stopped by SIGINT or SIGTERM at any moment (still importing,
opening the bag or playing) exits 0 without a traceback, also one started with SIGINT ignored
(as a shell's background job is)."""

import os
import signal
import subprocess
import time

import pytest
from rclpy.serialization import serialize_message
from std_msgs.msg import Float64

from ato_bringup.stack import executable_path
from ato_ros.middleware import with_middleware_defaults
from recorder.bag import BagWriter


@pytest.fixture(scope='module')
def bag(tmp_path_factory):
    folder = tmp_path_factory.mktemp('replayed') / 'bag'
    writer = BagWriter(folder)
    writer.add_topic('/numbers', 'std_msgs/msg/Float64')
    for k in range(100):
        writer.write('/numbers', k * 100_000_000, serialize_message(Float64(data=float(k))))
    writer.close()
    return folder


def replay(bag, domain_id, ignore_sigint=False) -> subprocess.Popen:
    env = with_middleware_defaults(dict(os.environ, ROS_DOMAIN_ID=str(domain_id)))

    def before():
        if ignore_sigint:
            signal.signal(signal.SIGINT, signal.SIG_IGN)
    return subprocess.Popen([executable_path('recorder', 'replay'), str(bag), '--loop'],
                            env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            preexec_fn=before)


def stopped(process: subprocess.Popen, sent: int, after_s: float) -> tuple[int, str]:
    time.sleep(after_s)
    process.send_signal(sent)
    try:
        out, err = process.communicate(timeout=30)  # --loop: a replay not stopped goes on
    except subprocess.TimeoutExpired:
        process.kill()
        out, err = process.communicate()
        return None, f'still playing 30 s after the signal\n{out}{err}'
    return process.returncode, out + err


@pytest.mark.parametrize('sent', [signal.SIGINT, signal.SIGTERM], ids=['SIGINT', 'SIGTERM'])
@pytest.mark.parametrize('after_s', [1.0, 2.0, 4.0])
def test_a_replay_stopped_at_any_moment_exits_0(bag, domain_id, sent, after_s):
    code, printed = stopped(replay(bag, domain_id), sent, after_s)
    assert code == 0, printed
    assert 'Traceback' not in printed and 'KeyboardInterrupt' not in printed, printed


@pytest.mark.parametrize('after_s', [1.5, 4.0])
def test_a_replay_started_with_sigint_ignored_stops_on_sigint(bag, domain_id, after_s):
    # the first while it imports (an ignored SIGINT then would be lost), the second playing
    code, printed = stopped(replay(bag, domain_id, ignore_sigint=True), signal.SIGINT, after_s)
    assert code == 0, printed
    assert 'Traceback' not in printed, printed
