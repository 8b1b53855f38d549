"""The simulated rig one sample period at a time: model, excitation, actuators, sensors and the
command gate (what sim_node runs)."""

import lazy_loader as lazy

__getattr__, __dir__, __all__ = lazy.attach(
    __name__,
    submodules=["actuation_delay", "actuators", "frame_plant", "linear_period", "ph_plant",
                "protocol", "sensors"],
    submod_attrs={
        "frame_plant": ["FramePlant", "make_plant"],
        "protocol": ["Plant"],
    },
)
