"""A node that cannot finish tearing down must still end, and say where it hung."""

import os
import subprocess
import sys
import textwrap
from pathlib import Path

from ato_bringup.stack import Stack, StackConfig

HANGING_TEARDOWN = textwrap.dedent('''
    import sys, time
    from rclpy.node import Node
    from ato_ros import lifecycle as ros

    ros.TEARDOWN_LIMIT_S = 0.5

    class NodeWhoseTeardownHangs(ros.RunNodeHooks, Node):
        def __init__(self):
            super().__init__('teardown_hangs')
            self.finished = True  # stop spinning at once

        def close_outputs(self):
            open(sys.argv[1], 'w').write('closed')

        def destroy_node(self):
            time.sleep(60)  # stands for a middleware that never returns

    sys.exit(ros.run_node(NodeWhoseTeardownHangs))
''')

IGNORES_SIGINT = textwrap.dedent('''
    import faulthandler, signal, time
    faulthandler.enable()
    signal.signal(signal.SIGINT, signal.SIG_IGN)

    def wait_forever():
        print('ready', flush=True)
        time.sleep(60)

    wait_forever()
''')


def test_a_node_whose_teardown_hangs_ends_with_its_stack_after_closing_its_outputs(tmp_path,
                                                                                   domain_id):
    marker = tmp_path / 'outputs'
    env = dict(os.environ, ROS_DOMAIN_ID=str(domain_id))
    done = subprocess.run([sys.executable, '-c', HANGING_TEARDOWN, str(marker)], env=env,
                          capture_output=True, text=True, timeout=30)
    assert done.returncode == 1, done.stderr
    assert marker.read_text() == 'closed'  # the node's own outputs were closed before the limit
    assert 'Timeout' in done.stderr and 'in destroy_node' in done.stderr, done.stderr


def test_stop_aborts_a_process_that_ignores_sigint_and_its_log_shows_where(tmp_path, domain_id):
    log = tmp_path / 'hang.log'
    with Stack(StackConfig('short_line', domain_id=domain_id, log_dir=tmp_path)) as stack:
        with open(log, 'wb') as out:
            stack.processes['hang'] = subprocess.Popen(
                [sys.executable, '-c', IGNORES_SIGINT], stdout=out, stderr=subprocess.STDOUT)
        assert stack.spin_until(lambda: 'ready' in log.read_text(), 20.0)
        codes = stack.stop(['hang'], timeout_s=0.5)
    assert codes == {'hang': -6}  # SIGABRT, not SIGKILL: faulthandler had its say
    assert 'in wait_forever' in Path(log).read_text()
