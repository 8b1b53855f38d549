"""Planar floating bodies in pH form: rigid bodies and thin Euler–Bernoulli beams (seed 000).

A body's state is e = [q, ν, σ]: generalised coordinates q = [x_P, y_P, θ, u_f] (the reference
point P in the inertial frame, the frame's angle, the deformation DOFs), velocities
ν = [v_P^x, v_P^y, ω, v_f] with v_P in the body frame (eq. 32), and stresses σ = [n_x, m_x].

    [I 0 0] [q̇]   [ 0    A(q)   0  ] [∂_q H]
    [0 M 0] [ν̇] = [−Aᵀ  J_g(e) −Dᵀ ] [  ν  ]          (eq. 36, with z = [∂_q V, ν, σ])
    [0 0 C] [σ̇]   [ 0    D      0  ] [  σ  ]

M is the constant mass operator of eq. 33 (momenta independent of the deformation, §4.3),
C the compliance (DG0 axial, DG1 bending), D the weak ∂_x / ∂_xx of J_Grad, A(q) = diag(R(θ), 1,
I) maps ν to q̇, and J_g(e) is the gyroscopic block of eq. 34, skew by construction: every
rigid–flexible entry J_rf is written as −J_frᵀ. Gyroscopic momentum density (the modified
momentum of eq. 13):

    π(x) = ρA [v_P + ω ẑ×(x + u_f) + 2 v_f]

so the deformation equation carries ω ẑ×π: the Coriolis term 2ρA ω×v_f and the centrifugal
term ρA ω² (x + u_f), i.e. the ω² u_f effect is kept through the deformed position in J_g (J may
depend on the state; energy stays exact because J_g is skew). Rigid rows use Π = ∫π dx.

Gravity (Remark 1) is the potential V = g ∫ρA y dx along inertial −y. Ports are points of the
body: their inertial position and angle p(q) and Jacobian ∂p/∂q give the port velocity
y = (∂p/∂q) A ν and the force map B = Aᵀ (∂p/∂q)ᵀ (efforts in the inertial frame).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from stillframe.dynamics.ph.fem1d import BeamMesh
from stillframe.errors import InputError


def rotation(theta: float) -> np.ndarray:
    """The 2 × 2 rotation matrix of angle ``theta`` [rad]."""
    c, s = np.cos(theta), np.sin(theta)
    return np.array([[c, -s], [s, c]])


@dataclass(frozen=True)
class BeamSection:
    """Uniform section: density × area, axial and bending rigidity."""

    rho_a: float
    ea: float
    ei: float


@dataclass
class FloatingBody:
    """A rigid frame (m, s = static moment about P along local x, J_P) with an optional flexible
    thin beam along its local x axis; ``ports`` name local points (a, 0) on that axis."""

    name: str
    mass: float
    static_moment: float
    inertia: float
    ports: dict[str, float]
    mesh: BeamMesh | None = None
    section: BeamSection | None = None
    gravity: float = 0.0
    _flex: dict[str, np.ndarray] = field(init=False, repr=False)
    _port_shapes: dict[str, tuple[np.ndarray, ...]] = field(init=False, repr=False)
    n_axial: int = field(init=False)
    n_flex: int = field(init=False)

    def __post_init__(self) -> None:
        if self.mass <= 0 or self.inertia <= 0:
            raise InputError(f"body {self.name}: mass and inertia must be > 0")
        self.n_axial = 0 if self.mesh is None else self.mesh.axial_dofs().size
        self.n_flex = 0 if self.mesh is None else (self.n_axial
                                                    + self.mesh.transverse_dofs().size)
        self._flex = self._flexible_tables() if self.mesh is not None else {}
        self._port_shapes = {
            name: (self.mesh.p1([a])[0], self.mesh.hermite([a])[0], self.mesh.hermite([a], 1)[0])
            for name, a in self.ports.items()} if self.mesh is not None else {}

    # sizes -----------------------------------------------------------------------------
    @property
    def n_q(self) -> int:
        """Generalized coordinates of the body: x, y, θ of its floating frame, then its flexible
        ones."""
        return 3 + self.n_flex

    @property
    def n_stress(self) -> int:
        """Stress variables of the body: three per element of its mesh (none for a rigid body)."""
        return 0 if self.mesh is None else 3 * self.mesh.elements

    # constant operators --------------------------------------------------------------------
    def _flexible_tables(self) -> dict[str, np.ndarray]:
        mesh, sec = self.mesh, self.section
        if sec is None:
            raise InputError(f"body {self.name}: a flexible body needs a section")
        x, w = mesh.quadrature()
        px, py = mesh.p1(x), mesh.hermite(x)
        return {
            "x": x, "w": w, "px": px, "py": py,
            "px_x": mesh.p1(x, 1), "py_xx": mesh.hermite(x, 2),
            "n": mesh.dg0(x), "m": mesh.dg1(x),
        }

    def mass_matrix(self) -> np.ndarray:
        """Eq. 33 (eq. 48: a lumped mass is already in m, s, J): rigid, coupling, flexible."""
        n = self.n_q
        M = np.zeros((n, n))
        M[0, 0] = M[1, 1] = self.mass
        M[1, 2] = M[2, 1] = self.static_moment
        M[2, 2] = self.inertia
        if self.mesh is None:
            return M
        t, rho_a, na = self._flex, self.section.rho_a, self.n_axial
        w = t["w"] * rho_a
        fx, fy = slice(3, 3 + na), slice(3 + na, n)
        M[fx, fx] = t["px"].T @ (w[:, None] * t["px"])
        M[fy, fy] = t["py"].T @ (w[:, None] * t["py"])
        M[0, fx] = M[fx, 0] = w @ t["px"]
        M[1, fy] = M[fy, 1] = w @ t["py"]
        M[2, fy] = M[fy, 2] = (w * t["x"]) @ t["py"]
        return M

    def compliance(self) -> np.ndarray:
        """DG0 axial and DG1 bending compliance: ∫ψψ/EA, ∫ψψ/EI."""
        if self.mesh is None:
            return np.zeros((0, 0))
        t, sec = self._flex, self.section
        n_el = self.mesh.elements
        C = np.zeros((3 * n_el, 3 * n_el))
        C[:n_el, :n_el] = t["n"].T @ (t["w"][:, None] * t["n"]) / sec.ea
        C[n_el:, n_el:] = t["m"].T @ (t["w"][:, None] * t["m"]) / sec.ei
        return C

    def stress_coupling(self) -> np.ndarray:
        """D (stresses × ν): ∫ψ_n ∂_x φ_x and ∫ψ_m ∂_xx φ_y, the discrete J_Grad."""
        D = np.zeros((self.n_stress, self.n_q))
        if self.mesh is None:
            return D
        t, n_el, na = self._flex, self.mesh.elements, self.n_axial
        D[:n_el, 3:3 + na] = t["n"].T @ (t["w"][:, None] * t["px_x"])
        D[n_el:, 3 + na:] = t["m"].T @ (t["w"][:, None] * t["py_xx"])
        return D

    def distributed_load(self, shape_x: np.ndarray | None, shape_y: np.ndarray | None,
                         ) -> np.ndarray:
        """Distributed port B_d: ν-space column of ∫φ·f for a body force with the given
        values (per unit length, body frame) at the quadrature points."""
        b = np.zeros(self.n_q)
        t, na = self._flex, self.n_axial
        if shape_x is not None:
            b[3:3 + na] = (t["w"] * shape_x) @ t["px"]
        if shape_y is not None:
            b[3 + na:] = (t["w"] * shape_y) @ t["py"]
        return b

    # state-dependent operators -------------------------------------------------------------
    def kinematics(self, q: np.ndarray) -> np.ndarray:
        """A(q) = diag(R(θ), 1, I): q̇ = A ν."""
        A = np.eye(self.n_q)
        A[:2, :2] = rotation(q[2])
        return A

    def gyroscopic(self, q: np.ndarray, nu: np.ndarray) -> np.ndarray:
        """J_g(e) of eq. 34, skew-symmetric by construction (J_rf = −J_frᵀ)."""
        n = self.n_q
        J = np.zeros((n, n))
        vx, vy, om = nu[0], nu[1], nu[2]
        Pi = np.array([self.mass * vx, self.mass * vy + self.static_moment * om])
        if self.mesh is not None:
            t, na, rho_a = self._flex, self.n_axial, self.section.rho_a
            ux, uy = t["px"] @ q[3:3 + na], t["py"] @ q[3 + na:]
            vfx, vfy = t["px"] @ nu[3:3 + na], t["py"] @ nu[3 + na:]
            # flexible part of π beyond the rigid momentum already in Π: ρA(ω ẑ×u_f + 2v_f)
            pix = rho_a * (vx - om * uy + 2 * vfx)
            piy = rho_a * (vy + om * (t["x"] + ux) + 2 * vfy)
            w = t["w"]
            lumped = self.mass - rho_a * self.mesh.length
            Pi = np.array([w @ pix + lumped * vx, w @ piy + lumped * vy])
            col = np.concatenate([(w * piy) @ t["px"], -(w * pix) @ t["py"]])
            J[3:, 2] = col
            J[2, 3:] = -col
        J[0, 2], J[1, 2] = Pi[1], -Pi[0]
        J[2, 0], J[2, 1] = -Pi[1], Pi[0]
        return J

    def potential(self, q: np.ndarray) -> float:
        """Gravity potential (Remark 1): g[m y_P + sinθ(s + ∫ρA u_x) + cosθ ∫ρA u_y]."""
        if self.gravity == 0.0:
            return 0.0
        sx, sy = self._deformed_static_moments(q)
        return self.gravity * (self.mass * q[1] + np.sin(q[2]) * (self.static_moment + sx)
                               + np.cos(q[2]) * sy)

    def potential_gradient(self, q: np.ndarray) -> np.ndarray:
        """∂V/∂q of gravity on the body (zero without gravity), its flexible coordinates
        included."""
        grad = np.zeros(self.n_q)
        if self.gravity == 0.0:
            return grad
        g, th = self.gravity, q[2]
        sx, sy = self._deformed_static_moments(q)
        grad[1] = g * self.mass
        grad[2] = g * (np.cos(th) * (self.static_moment + sx) - np.sin(th) * sy)
        if self.mesh is not None:
            t, na, rho_a = self._flex, self.n_axial, self.section.rho_a
            grad[3:3 + na] = g * np.sin(th) * rho_a * (t["w"] @ t["px"])
            grad[3 + na:] = g * np.cos(th) * rho_a * (t["w"] @ t["py"])
        return grad

    def _deformed_static_moments(self, q: np.ndarray) -> tuple[float, float]:
        if self.mesh is None:
            return 0.0, 0.0
        t, na, rho_a = self._flex, self.n_axial, self.section.rho_a
        return (rho_a * (t["w"] @ (t["px"] @ q[3:3 + na])),
                rho_a * (t["w"] @ (t["py"] @ q[3 + na:])))

    def port(self, q: np.ndarray, name: str) -> tuple[np.ndarray, np.ndarray]:
        """Inertial position and angle p = [x, y, φ] of port ``name`` and ∂p/∂q (3 × n_q)."""
        if name not in self.ports:
            raise InputError(f"body {self.name} has no port {name!r} (has {sorted(self.ports)})")
        a = self.ports[name]
        jac = np.zeros((3, self.n_q))
        c, s = np.cos(q[2]), np.sin(q[2])
        lx, ly, angle = a, 0.0, q[2]
        if self.mesh is not None:
            na = self.n_axial
            phx, phy, slope = self._port_shapes[name]
            ux, uy = phx @ q[3:3 + na], phy @ q[3 + na:]
            lx, ly = lx + ux, uy
            angle = angle + slope @ q[3 + na:]
            jac[0, 3:3 + na], jac[1, 3:3 + na] = c * phx, s * phx
            jac[0, 3 + na:], jac[1, 3 + na:] = -s * phy, c * phy
            jac[2, 3 + na:] = slope
        jac[0, 0] = jac[1, 1] = jac[2, 2] = 1.0
        jac[0, 2], jac[1, 2] = -s * lx - c * ly, c * lx - s * ly
        position = np.array([q[0] + c * lx - s * ly, q[1] + s * lx + c * ly, angle])
        return position, jac


def rigid_body(name: str, mass: float, inertia_about_com: float, com: float,
               ports: dict[str, float], gravity: float = 0.0) -> FloatingBody:
    """A rigid body with its centre of mass at local (com, 0)."""
    return FloatingBody(name, mass, mass * com, inertia_about_com + mass * com**2,
                        ports, gravity=gravity)


def floating_beam(name: str, length: float, section: BeamSection, elements: int,
                  condition: str, lumped_mass: float = 0.0, gravity: float = 0.0,
                  ) -> FloatingBody:
    """The floating thin Euler–Bernoulli beam of eq. 32–37 with ports P (x=0) and C (x=L);
    ``lumped_mass`` sits at P (eq. 48)."""
    if length <= 0 or min(section.rho_a, section.ea, section.ei) <= 0:
        raise InputError(f"beam {name}: length and section values must be > 0")
    m = section.rho_a * length
    return FloatingBody(name, m + lumped_mass, m * length / 2, m * length**2 / 3,
                        {"P": 0.0, "C": length}, BeamMesh(length, elements, condition),
                        section, gravity)
