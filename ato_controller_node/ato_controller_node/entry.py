"""The ``ato_controller_node`` executable: a stop while the node is still importing ends it cleanly
(``ato_ros.interrupts``), then the node runs (``ato_controller_node.node``)."""

from ato_ros.interrupts import quiet_until_running


def main() -> int:
    quiet_until_running()
    from ato_controller_node.node import main as run_node_main
    return run_node_main()
