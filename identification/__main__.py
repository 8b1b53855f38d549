"""``python -m identification``: the modal tracker node (``modal_tracker``), Ctrl-C answered
from its first line on, before the imports of identification.node
(:func:`stillframe.interrupts.run_module`)."""

from stillframe.interrupts import run_module

run_module("identification.node", "modal_tracker")
