"""``python -m estimator_node``: the node executable, Ctrl-C answered from its first line
on, before the imports of estimator_node.node (:func:`stillframe.interrupts.run_module`)."""

from stillframe.interrupts import run_module

run_module("estimator_node.node", "estimator_node")
