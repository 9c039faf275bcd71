"""The runner's `ros2 param set` survives a lost reply: it sends the request again."""

import threading
import time

import rclpy
from rcl_interfaces.msg import SetParametersResult
from rcl_interfaces.srv import SetParameters
from rclpy.executors import SingleThreadedExecutor
from rclpy.node import Node

from ato_bringup.stack import Stack, StackConfig


def test_an_unanswered_parameter_request_is_sent_again(tmp_path, domain_id):
    context = rclpy.Context()
    rclpy.init(context=context, domain_id=domain_id)
    server = Node('slow_node', context=context, start_parameter_services=False)
    requests = []

    def answer(request, response):
        requests.append(time.monotonic())
        if len(requests) == 1:  # the first reply comes too late, as if it had been lost
            time.sleep(1.5)
        response.results = [SetParametersResult(successful=True, reason=f'call {len(requests)}')]
        return response

    server.create_service(SetParameters, '/slow_node/set_parameters', answer)
    executor = SingleThreadedExecutor(context=context)
    executor.add_node(server)
    spinning = threading.Thread(target=lambda: executor.spin(), daemon=True)
    spinning.start()
    stack = Stack(StackConfig(scenario='short_line', domain_id=domain_id, log_dir=tmp_path))
    try:
        results = stack.set_parameters('slow_node', {'x': 1.0}, timeout_s=10.0, attempt_s=1.0)
        assert len(requests) >= 2
        assert results[0].successful
        # the second answer, not the late first one
        assert results[0].reason == 'call 2'
    finally:
        stack.close()
        executor.shutdown()
        server.destroy_node()
        rclpy.shutdown(context=context)
        spinning.join(timeout=5)


def test_a_node_that_never_answers_times_out_naming_it(tmp_path, domain_id):
    stack = Stack(StackConfig(scenario='short_line', domain_id=domain_id, log_dir=tmp_path))
    try:
        try:
            stack.set_parameters('absent_node', {'x': 1.0}, timeout_s=1.0)
        except TimeoutError as error:
            assert '/absent_node/set_parameters' in str(error)
        else:
            raise AssertionError('no TimeoutError')
    finally:
        stack.close()
