"""The node API (named like rclpy's) and its two backends: ``dds`` (Cyclone DDS) and ``rclpy``.

Use :func:`stillframe.middleware.api.create_node` and :func:`stillframe.middleware.api.spin`.
"""

import lazy_loader as lazy

__getattr__, __dir__, __all__ = lazy.attach(
    __name__,
    submodules=["api", "backend_choice", "clock", "cyclone_log", "cyclone_raw", "dds_backend",
                "dds_services", "dds_types", "discovery", "graph", "interface", "intra_process",
                "lifecycle", "logger", "monitor", "names", "param_messages", "params", "qos",
                "rclpy_backend", "rclpy_wait", "taps", "topic_follower"],
    submod_attrs={
        "api": ["create_node", "node_main", "spin", "spin_once", "spin_until", "Node", "Publisher",
                "Subscription", "Timer"],
    },
)
