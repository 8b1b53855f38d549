"""Port-Hamiltonian flexible multibody dynamics (seed 000): blocks, connections, the pHDAE, its
structure-preserving integrator and the validation cases; see docs/port-hamiltonian.md."""
