"""The closed loop in one process, its evaluation, its adaptation to a change of the structure,
and what every process of the loop agrees on (sample assembly, force matching, pacing, watchdogs,
writer and command gates, wiring)."""

import lazy_loader as lazy

__getattr__, __dir__, __all__ = lazy.attach(
    __name__,
    submodules=["adaptation", "assembly", "closed_loop", "command_gate", "decimated_taps",
                "designs", "energy_balance", "evaluation", "fast_inputs", "matching", "pacing",
                "parts", "refilter", "spec", "step", "watchdog", "wiring", "writer_gate"],
    submod_attrs={
        "spec": ["LoopSpec"],
        "step": ["LoopStep"],
        "closed_loop": ["run_closed_loop"],
        "evaluation": ["LoopHistory", "evaluate"],
        "adaptation": ["Adaptation"],
    },
)
