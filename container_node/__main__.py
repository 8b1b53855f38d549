"""``python -m container_node``: the node executable, Ctrl-C answered from its first line
on, before the imports of container_node.node (:func:`stillframe.interrupts.run_module`)."""

from stillframe.interrupts import run_module

run_module("container_node.node", "container_node")
