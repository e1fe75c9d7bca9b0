"""A test-side ROS participant for managed nodes: subscribes to topics, keeps the latest
/diagnostics status of one node, publishes, and drives the node's lifecycle services."""
import time

import rclpy
from diagnostic_msgs.msg import DiagnosticArray
from lifecycle_msgs.msg import Transition
from lifecycle_msgs.srv import ChangeState, GetState

from softcath_ros import topics


class LifecycleListener:
    def __init__(self, domain: int, node_name: str, subscriptions: dict):
        """``subscriptions``: topic -> message type; what arrives is in ``self.got[topic]``."""
        self.node_name = node_name
        self.context = rclpy.context.Context()
        rclpy.init(context=self.context, domain_id=domain)
        self.node = rclpy.create_node(f"{node_name}_test_listener", context=self.context)
        self.executor = rclpy.executors.SingleThreadedExecutor(context=self.context)
        self.executor.add_node(self.node)
        self.got = {topic: [] for topic in subscriptions}
        for topic, msg_type in subscriptions.items():
            self.node.create_subscription(msg_type, topic, self.got[topic].append, 100)
        self.status, self.statuses = None, []
        self.node.create_subscription(DiagnosticArray, topics.DIAGNOSTICS, self._on_diag, 10)

    def _on_diag(self, msg):
        for s in msg.status:
            if s.name == self.node_name:
                self.status = {"level": s.level, "message": s.message, **{kv.key: kv.value for kv in s.values}}
                self.statuses.append(self.status)

    def spin(self, seconds, until=None):
        end = time.monotonic() + seconds
        while time.monotonic() < end:
            self.executor.spin_once(timeout_sec=0.02)
            if until is not None and until():
                return True
        return False

    def call(self, srv_type, name, request, timeout=20.0):
        client = self.node.create_client(srv_type, name)
        assert client.wait_for_service(timeout_sec=timeout), f"no service {name}"
        future = client.call_async(request)
        end = time.monotonic() + timeout
        while not future.done() and time.monotonic() < end:
            self.executor.spin_once(timeout_sec=0.05)
        assert future.done(), f"{name}: no answer"
        return future.result()

    def transition(self, transition_id) -> bool:
        return self.call(ChangeState, f"/{self.node_name}/change_state",
                         ChangeState.Request(transition=Transition(id=transition_id))).success

    def state(self) -> str:
        return self.call(GetState, f"/{self.node_name}/get_state", GetState.Request()).current_state.label

    def close(self):
        self.node.destroy_node()
        rclpy.shutdown(context=self.context)
