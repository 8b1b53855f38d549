"""The backend-neutral node API, named like rclpy's.

```python
from stillframe.middleware.api import create_node, spin

node = create_node("sim_node", namespace="/frame")          # reads --ros-args from sys.argv
pub = node.create_publisher("sensor_msgs/msg/Imu", "floor1/imu", "sensor_data")
node.create_subscription("geometry_msgs/msg/WrenchStamped", "pendulum/torque_cmd", on_cmd, 10)
node.create_timer(0.01, step)
spin(node)            # returns on SIGINT / SIGTERM
node.destroy_node()
```

Messages are ``rosbags`` message instances (see :mod:`stillframe.contract.messages`); ``publish``
also takes CDR bytes, and ``create_subscription(..., raw=True)`` hands the callback
``(cdr_bytes, MessageInfo)``. The backend is ``rclpy`` when ``import rclpy`` works and ``dds``
otherwise; the environment variable ``STILLFRAME_RMW=dds|rclpy`` overrides the choice.
"""

from __future__ import annotations

import functools
import sys
import threading
from collections.abc import Callable
from pathlib import Path

from stillframe import interrupts
from stillframe.config.environment import check_environment
from stillframe.errors import StillframeError
from stillframe.middleware.backend_choice import (
    BACKEND_ENV,
    BACKENDS,
    backend_name,
    check_backend,
    has_rclpy,
)
from stillframe.middleware.clock import Clock, Time
from stillframe.middleware.cyclone_log import DROPPED as CYCLONE_DROPPED
from stillframe.middleware.cyclone_log import count_deserialization_failures
from stillframe.middleware.interface import (
    ManagedNode,
    MessageInfo,
    Node,
    Publisher,
    Subscription,
    Timer,
    TopicEndpointInfo,
    deliver,
    freeze_setup_objects,
    install_signal_handlers,
    node_created,
    ok,
    shutdown,
)
from stillframe.middleware.params import Parameter, SetParametersResult

__all__ = ["BACKENDS", "BACKEND_ENV", "CYCLONE_DROPPED", "ManagedNode", "MessageInfo", "Node",
           "Parameter", "Publisher", "SetParametersResult", "Subscription", "Timer",
           "TopicEndpointInfo", "backend_name",
           "check_backend", "create_node", "deliver", "freeze_setup_objects", "has_rclpy",
           "install_signal_handlers", "node_main", "ok", "shutdown", "spin", "spin_once",
           "spin_until"]


def create_node(name: str, namespace: str | None = None, argv: list[str] | None = None,
                backend: str | None = None, *, managed: bool = False) -> Node:
    """A node on ``backend`` (default :func:`backend_name`); ``argv`` (default ``sys.argv``)
    may carry ``--ros-args``. ``managed``: a lifecycle node (:class:`.interface.ManagedNode`:
    rclpy's ``LifecycleNode``, or the ``dds`` backend's same services), made so by its
    ``manage(on_transition)``.

    ``namespace`` is the default namespace (``-r __ns:=`` overrides it, as does ``__node``
    the name). Logs the backend in use.
    """
    backend = check_backend(backend, "backend") if backend else backend_name()
    args = list(sys.argv if argv is None else argv)[1:]
    if backend == "dds":
        from stillframe.middleware.dds_services import ServiceNode as NodeClass
    else:
        from stillframe.middleware.rclpy_backend import RclpyNode as NodeClass
    node = NodeClass(name, namespace or "/", args, **(
        {"managed": True} if managed and backend == "rclpy" else {}))
    node_created(node)
    install_signal_handlers()
    node.get_logger().info(f"middleware backend: {backend}", once=True)
    return node


def node_main(main: Callable[[], int | None]) -> Callable[[], int]:
    """Wrap a node executable's ``main`` (a ``console_scripts`` entry point): a
    :class:`~stillframe.errors.StillframeError` (e.g. a wrong parameter, exit code 2) prints one
    line and exits with its code; so does an interruption the node's own handlers did not turn
    into a clean stop (a second Ctrl-C, one before the node exists: 130, 143), and a signal
    after the node's work ends it at once (:mod:`stillframe.interrupts`)."""

    @functools.wraps(main)
    def wrapped() -> int:
        prog = Path(sys.argv[0]).name

        def work() -> int:
            try:
                check_environment()
                if backend_name() == "dds":     # Cyclone's dropped samples counted
                    count_deserialization_failures()
                return int(main() or 0)
            except StillframeError as exc:
                if interrupts.received():
                    raise
                print(f"{prog}: error: {exc}", file=sys.stderr)
                return exc.exit_code

        code = interrupts.run_work(prog, work)
        sys.stdout.flush()
        if threading.current_thread() is threading.main_thread():
            interrupts.ending(prog)
        return code

    return wrapped


def spin_once(node: Node, timeout_sec: float | None = None) -> None:
    """Wait up to ``timeout_sec`` (None: until something happens) and run ready callbacks."""
    node.spin_once(timeout_sec)


def spin(node: Node) -> None:
    """Run the node's callbacks until SIGINT, SIGTERM or :func:`shutdown`."""
    while ok():
        node.spin_once(None)


def spin_until(node: Node, condition: Callable[[], bool], timeout_sec: float) -> bool:
    """Spin until ``condition()`` is true (returns True), the timeout passes or shutdown."""
    deadline = Time(Clock().now().nanoseconds + int(timeout_sec * 1e9))
    while ok() and not condition():
        remaining = (deadline.nanoseconds - Clock().now().nanoseconds) * 1e-9
        if remaining <= 0:
            return False
        node.spin_once(min(remaining, 0.05))
    return condition()
