"""The loop nodes' runtime: what sim_node, estimator_node, controller_node and the container run on.

- :mod:`.base`: the declared base: ``Cycle`` (spin → process → idle → housekeeping), ``LoopNode``
  (parameters, ``/diagnostics``, writer gates, real-time practices), ``Managed`` (lifecycle),
  ``main``;
- :mod:`.declarations`: every node's parameters, declared once (``NODE_PARAMETERS``, ``MODES``);
- :mod:`.parameters`: how a parameter is declared (``param``), checked and documented;
- :mod:`.support`: the scene parameters, ``/diagnostics``, timing statistics, waiting for peers;
- :mod:`.realtime`: the real-time practices;
- :mod:`.qos_table`: the QoS each topic uses, the docs' table generated from the contract.
"""

import lazy_loader as lazy

__getattr__, __dir__, __all__ = lazy.attach(
    __name__,
    submodules=["base", "declarations", "parameters", "phase_timing", "qos_table", "realtime",
                "support"],
    submod_attrs={
        "base": ["Cycle", "LoopNode", "Managed"],
        "parameters": ["NodeParameters", "param"],
        "declarations": ["NODE_PARAMETERS"],
    },
)
