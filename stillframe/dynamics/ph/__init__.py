"""Port-Hamiltonian flexible multibody dynamics (seed 000): blocks, connections, the pHDAE, its
structure-preserving integrator and the validation cases; see docs/port-hamiltonian.md."""

import lazy_loader as lazy

__getattr__, __dir__, __all__ = lazy.attach(
    __name__,
    submodules=["body", "classical_fe", "crank_slider", "energy_drift", "fem1d", "fourbar",
                "frame", "frame_step", "integrator", "joints", "linear", "manufactured",
                "reference", "scene_model", "system"],
    submod_attrs={
        "system": ["PHSystem"],
        "integrator": ["MidpointDAE"],
    },
)
