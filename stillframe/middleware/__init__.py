"""The node API (named like rclpy's) and its two backends: ``dds`` (Cyclone DDS) and ``rclpy``.

Use :func:`stillframe.middleware.api.create_node` and :func:`stillframe.middleware.api.spin`.
"""
