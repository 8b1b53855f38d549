"""The rig's dynamics: models (lumped, FE, Craig–Bampton, identified, port-Hamiltonian),
descriptor systems, integrators and compiled kernels, open-loop simulation."""

import lazy_loader as lazy

__getattr__, __dir__, __all__ = lazy.attach(
    __name__,
    submodules=["excitation", "integrators", "kernels", "modal_analysis", "models", "ph",
                "simulation", "stability", "systems"],
    submod_attrs={
        "integrators": ["ImplicitMidpoint", "Integrator", "RK4", "integrate", "make_integrator"],
        "systems": ["LinearSystem", "MechanicalSystem"],
        "simulation": ["initial_state", "simulate"],
        "models": ["FrameModel", "build_model"],
    },
)
