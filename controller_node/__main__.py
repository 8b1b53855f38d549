"""``python -m controller_node``: the node executable, Ctrl-C answered from its first line
on, before the imports of controller_node.node (:func:`stillframe.interrupts.run_module`)."""

from stillframe.interrupts import run_module

run_module("controller_node.node", "controller_node")
