"""The loop nodes' runtime: what sim_node, estimator_node, controller_node and the container run
on (the scene parameters, ``/diagnostics``, timing statistics, waiting for peers, the real-time
practices)."""
