"""``python -m sim_node``: the node executable, Ctrl-C answered from its first line
on, before the imports of sim_node.node (:func:`stillframe.interrupts.run_module`)."""

from stillframe.interrupts import run_module

run_module("sim_node.node", "sim_node")
