"""The rig's dynamics: models (lumped, FE, Craig–Bampton, identified, port-Hamiltonian),
descriptor systems, integrators and compiled kernels, open-loop simulation."""
