"""pH building blocks (seed 000 §3–5) against a classical FE, closed forms and their structure."""

import numpy as np
import pytest

from stillframe.dynamics.ph.body import BeamSection, floating_beam, rigid_body
from stillframe.dynamics.ph.classical_fe import FrameModel, fix
from stillframe.dynamics.ph.joints import Link, Support, fixed
from stillframe.dynamics.ph.linear import natural_frequencies, pencil_eigenvalues
from stillframe.dynamics.ph.system import PHSystem, RotaryDamper
from stillframe.errors import InputError

SECTION = BeamSection(rho_a=2714.0 * 4.0645e-5, ea=7.1e10 * 4.0645e-5, ei=0.616)
L = 0.2794


def grounded_beam(condition: str, elements: int) -> tuple[PHSystem, np.ndarray]:
    beam = floating_beam("b", L, SECTION, elements, condition)
    if condition == "cantilever":
        links = [Support(("b", "P"), (0, 1, 2), fixed([0, 0, 0]))]
    else:
        links = [Support(("b", "P"), (0, 1), fixed([0, 0])), Support(("b", "C"), (1,), fixed([0]))]
    system = PHSystem([beam], links)
    return system, np.zeros(system.n_q)


def classical_beam(condition: str, elements: int, count: int) -> np.ndarray:
    model = FrameModel()
    start = model.node()
    end = model.link(start, L, 0.0, elements, SECTION.rho_a, SECTION.ea, SECTION.ei)
    if condition == "cantilever":
        fix(model, start, (0, 1, 2))
    else:
        fix(model, start, (0, 1))
        fix(model, end, (1,))
    return model.pulsations(count)


@pytest.mark.parametrize("condition", ["cantilever", "simply_supported"])
def test_ph_eigenvalues_equal_classical_fe_on_the_same_mesh(condition):
    system, q = grounded_beam(condition, 6)
    ph = natural_frequencies(system, q, 8)[0]
    ref = classical_beam(condition, 6, 8)
    np.testing.assert_allclose(ph, ref, rtol=1e-8)
    # the pencil E Φ s = J Φ of the DAE itself: s = ±jω, real parts at round-off
    s = pencil_eigenvalues(system, q)
    s = s[np.abs(s) > 1e-6]
    assert np.max(np.abs(s.real)) < 1e-6 * np.max(np.abs(s))
    np.testing.assert_allclose(np.sort(np.abs(s.imag))[:16:2], ref, rtol=1e-8)


def test_frequencies_converge_to_the_closed_forms():
    bl = np.array([1.875104069, 4.694091133, 7.854757438])
    scale = np.sqrt(SECTION.ei / SECTION.rho_a) / L**2
    cantilever = natural_frequencies(*grounded_beam("cantilever", 16), 3)[0]
    np.testing.assert_allclose(cantilever, bl**2 * scale, rtol=1e-4)  # O(h⁴) at 16 el.
    supported = natural_frequencies(*grounded_beam("simply_supported", 16), 3)[0]
    np.testing.assert_allclose(supported, (np.arange(1, 4) * np.pi) ** 2 * scale, rtol=1e-4)


def two_link_system(gravity: float = 9.81, damping: float = 0.0) -> PHSystem:
    """A flexible beam on a revolute joint to ground, a rigid body pinned to its tip."""
    beam = floating_beam("beam", L, SECTION, 3, "cantilever", lumped_mass=0.01, gravity=gravity)
    tip = rigid_body("tip", 0.05, 2e-4, 0.05, {"P": 0.0}, gravity=gravity)
    links = [Support(("beam", "P"), (0, 1), fixed([0, 0])),
             Link(("beam", "C"), ("tip", "P"), (0, 1))]
    dampers = [RotaryDamper(("tip", "P"), ("beam", "C"), damping)] if damping else []
    return PHSystem([beam, tip], links, dampers=dampers)


def test_interconnection_matrix_is_skew_for_random_states():
    system = two_link_system()
    rng = np.random.default_rng(1)
    for _ in range(5):
        e = rng.normal(size=system.n) * 3.0
        J = system.interconnection(e)
        assert np.max(np.abs(J + J.T)) == 0.0
        assert np.max(np.abs(J)) > 1.0  # gyroscopic blocks are populated


def test_hamiltonian_gradient_is_e_transpose_z():
    system = two_link_system()
    rng = np.random.default_rng(2)
    e = rng.normal(size=system.n) * 0.3
    grad = np.array([(system.hamiltonian(e + d) - system.hamiltonian(e - d)) / 2e-6
                     for d in np.eye(system.n) * 1e-6])
    np.testing.assert_allclose(grad, system.descriptor.T @ system.z(e), rtol=1e-6, atol=1e-8)


def test_centrifugal_term_keeps_the_deformation():
    """The ω column of the deformation rows is ∫φ·(−ẑ×π), π containing ρA ω (x + u_f): doubling
    a transverse deformation at fixed ω changes the transverse centrifugal load by ρA ω² ∫φ u_y."""
    beam = floating_beam("b", L, SECTION, 2, "cantilever")
    q, nu = np.zeros(beam.n_q), np.zeros(beam.n_q)
    nu[2] = 10.0
    q[3 + beam.n_axial:] = 1e-3
    load = beam.gyroscopic(q, nu)[:, 2] * nu[2]
    load0 = beam.gyroscopic(q * 0, nu)[:, 2] * nu[2]
    x, w = beam.mesh.quadrature()
    phi = beam.mesh.hermite(x)
    expected = SECTION.rho_a * 100.0 * (w * (phi @ q[3 + beam.n_axial:])) @ phi
    np.testing.assert_allclose(-(load - load0)[3 + beam.n_axial:], -expected, rtol=1e-12)


def test_bad_blocks_are_rejected():
    with pytest.raises(InputError, match="condition"):
        floating_beam("b", 1.0, SECTION, 2, "free")
    with pytest.raises(InputError, match="no port"):
        two_link_system().port_position(np.zeros(12), ("tip", "C"))
