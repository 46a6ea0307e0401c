"""The membrane section by finite elements (scikit-fem): a flap of silicone in plane strain, clamped
at its root, inflated by the CPAP pressure onto the skin.

- Geometrically nonlinear: total Lagrangian, a St Venant-Kirchhoff material (S = lambda tr(E) I +
  2 mu E of the Green strain E, the Lame constants of E 1 MPa and nu 0.49), right for the flap's
  small strains and large rotations; quadratic triangles.
- The CPAP pressure is a follower load on the flap's air side: -P cof(F) N per unit of reference
  length (in 2-D the cofactor is linear in F, so its tangent is constant).
- The skin is a level line under the root, frictionless and one-sided: a penalty pressure k d on
  the flap's skin side wherever it sinks d below the line (eased in over the first micrometre),
  integrated at the quadrature points (a stiff k for a rigid skin, a region's tissue spring for a
  soft one: a Winkler layer).
- Newton iterations (exact tangent, the active set at the quadrature points) under load steps of
  the pressure, then of the opening (the skin moved away step by step, each solution, with the
  part lying on the skin moved along, the next one's start).

Units: mm, kPa; forces per unit depth in kPa mm. The flap lies along +x from its root, its skin side
at y = 0 at the root, the skin below it at y = -(opening + its stand-off).
"""

from dataclasses import dataclass

import numpy as np
from skfem import BilinearForm, FacetBasis, LinearForm, MeshTri, asm, condense, solve
from skfem.helpers import ddot, dot, grad, identity, mul, trace, transpose
from skfem.models.elasticity import lame_parameters

from .fe import Material, dofs_where, vector_basis

RIGID_KPA_PER_MM = 2.0e3  # the penalty of a rigid skin: at 2 kPa it sinks 1 um
SMOOTH_MM = 1e-3  # the skin's push eases in over this much sink
NEWTON_TOL_MM, NEWTON_MAX = 1e-8, 60
STEP_SHARE = 0.25  # a Newton step moves the flap at most this share of its width
RAMP = (0.01, 0.03, 0.1, 0.3, 1.0)  # the pressure's load steps, shares of it


class NotConverged(RuntimeError):
    """Newton's iterations did not converge within NEWTON_MAX."""


@dataclass(frozen=True)
class Flap:
    """A membrane section: width (root to free edge) and thickness, mm; its skin side at the root
    stands `standoff_mm` off the skin when the wall touches it, and the flap rises away from the
    skin by the slope `lift` at rest; `cells` (along, across) of the mesh."""

    width_mm: float
    thickness_mm: float
    standoff_mm: float = 0.0
    lift: float = 0.0
    cells: tuple[int, int] = (24, 2)


@dataclass(frozen=True)
class Pressed:
    """A solved flap: its displacement (dofs, mm), its free edge's middle's displacement `tip` (2,) mm, the contact pressure (Q,) kPa at the skin side's
    quadrature points lying at `along` (Q,) mm from the root, their weights (Q,) mm, and the root's
    reaction (x, y) kPa mm."""

    displacement: np.ndarray
    tip: np.ndarray
    along: np.ndarray
    contact_kpa: np.ndarray
    weights: np.ndarray
    root_reaction: tuple[float, float]

    def lying_mm(self, cpap_kpa: float) -> float:
        """mm of the flap's skin side that the skin pushes back with at least half the air pressure
        `cpap_kpa` (the flap laid on it; not the penalty's sliver past where it touches down)."""
        return float(self.weights[self.contact_kpa >= 0.5 * cpap_kpa].sum())

    @property
    def contact_force(self) -> float:
        """kPa mm: the skin's push on the flap per unit depth."""
        return float(self.weights @ self.contact_kpa)


def flap_mesh(flap: Flap) -> tuple[MeshTri, MeshTri]:
    """(the flap's mesh, the same mesh in (along, across) reference coordinates): dofs number alike."""
    along, across = flap.cells
    param = MeshTri.init_tensor(np.linspace(0.0, flap.width_mm, along + 1), np.linspace(0.0, flap.thickness_mm, across + 1))
    angle = np.arctan(flap.lift)
    turn = np.array([[np.cos(angle), -np.sin(angle)], [np.sin(angle), np.cos(angle)]])
    return MeshTri(turn @ param.p, param.t), param


def _strain_stress(u, lam: float, mu: float):
    """(F, S): deformation gradient and second Piola-Kirchhoff stress of a displacement field."""
    f = identity(grad(u)) + grad(u)
    e = 0.5 * (mul(transpose(f), f) - identity(grad(u)))
    return f, lam * trace(e) * identity(grad(u)) + 2.0 * mu * e


def _cofactor(a):
    """The cofactor of 2 x 2 fields (2, 2, ...): det(a) a^-T, linear in a."""
    return np.array([[a[1, 1], -a[1, 0]], [-a[0, 1], a[0, 0]]])


def skin_pressure(sink: np.ndarray, spring: float) -> tuple[np.ndarray, np.ndarray]:
    """(kPa, kPa/mm): the skin's push where the flap sinks `sink` mm into it, and its slope: `spring`
    times the sink, eased in over the first SMOOTH_MM (quadratically, so that Newton's active set
    does not flip back and forth between two quadrature points)."""
    d = np.maximum(sink, 0.0)
    eased = d < SMOOTH_MM
    return (spring * np.where(eased, 0.5 * d**2 / SMOOTH_MM, d - 0.5 * SMOOTH_MM),
            spring * np.where(eased, d / SMOOTH_MM, 1.0))


def _forms(material: Material, cpap_kpa: float, skin_y: float, spring: float):
    """The internal force and tangent of the solid, the follower pressure's load and tangent, and
    the skin's push and tangent, as scikit-fem forms over the previous displacement `w.u`."""
    lam, mu = lame_parameters(material.youngs_kpa, material.poisson)

    @LinearForm
    def internal(v, w):
        f, s = _strain_stress(w.u, lam, mu)
        return ddot(mul(f, s), grad(v))

    @BilinearForm
    def tangent(du, v, w):
        f, s = _strain_stress(w.u, lam, mu)
        de = 0.5 * (mul(transpose(f), grad(du)) + mul(transpose(grad(du)), f))
        ds = lam * trace(de) * identity(de) + 2.0 * mu * de
        return ddot(mul(grad(du), s) + mul(f, ds), grad(v))

    @LinearForm
    def pressure(v, w):
        return -cpap_kpa * dot(mul(_cofactor(identity(grad(w.u)) + grad(w.u)), w.n), v)

    @BilinearForm
    def pressure_tangent(du, v, w):
        return -cpap_kpa * dot(mul(_cofactor(grad(du)), w.n), v)

    @LinearForm
    def skin(v, w):
        return skin_pressure(skin_y - w.x[1] - w.u[1], spring)[0] * v[1]

    @BilinearForm
    def skin_tangent(du, v, w):
        return skin_pressure(skin_y - w.x[1] - w.u[1], spring)[1] * du[1] * v[1]

    return internal, tangent, pressure, pressure_tangent, skin, skin_tangent


class FlapModel:
    """A flap's mesh, bases and clamped root, reused across load steps."""

    def __init__(self, flap: Flap, material: Material = Material()):
        self.flap, self.material = flap, material
        self.mesh, param = flap_mesh(flap)
        self.basis = vector_basis(self.mesh)
        on_param = vector_basis(param)
        self.root_x, self.root_y = (dofs_where(on_param, lambda x: x[0] == 0.0, c) for c in ("u^1", "u^2"))
        self.root = np.concatenate([self.root_x, self.root_y])
        top = param.facets_satisfying(lambda x: x[1] == flap.thickness_mm)
        bottom = param.facets_satisfying(lambda x: x[1] == 0.0)
        self.air = FacetBasis(self.mesh, self.basis.elem, facets=top, intorder=4)
        self.skin = FacetBasis(self.mesh, self.basis.elem, facets=bottom, intorder=4)
        middle = np.argmin(np.linalg.norm(param.p - np.array([[flap.width_mm], [0.5 * flap.thickness_mm]]), axis=0))
        self.tip = self.basis.nodal_dofs[:, middle]
        self.along = FacetBasis(param, self.basis.elem, facets=bottom, intorder=4).global_coordinates()[0].ravel()
        self.y_dofs = np.concatenate([self.basis.nodal_dofs[1], self.basis.facet_dofs[1]])
        self.y_along = on_param.doflocs[0, self.y_dofs]

    def residual_and_tangent(self, x: np.ndarray, cpap_kpa: float, skin_y: float, spring: float):
        """(R, K): the out-of-balance force (dofs,) kPa mm at displacement `x` and its tangent."""
        internal, tangent, pressure, pressure_tangent, skin, skin_tangent = _forms(self.material, cpap_kpa, skin_y, spring)
        u, ua, us = self.basis.interpolate(x), self.air.interpolate(x), self.skin.interpolate(x)
        r = asm(internal, self.basis, u=u) - asm(pressure, self.air, u=ua) - asm(skin, self.skin, u=us)
        k = asm(tangent, self.basis, u=u) - asm(pressure_tangent, self.air, u=ua) + asm(skin_tangent, self.skin, u=us)
        return r, k

    def equilibrium(self, x: np.ndarray, cpap_kpa: float, skin_y: float, spring: float) -> np.ndarray:
        """(dofs,) mm: the displacement in equilibrium, by Newton iterations from `x`."""
        x = x.copy()
        for _ in range(NEWTON_MAX):
            r, k = self.residual_and_tangent(x, cpap_kpa, skin_y, spring)
            step = solve(*condense(k, -r, D=self.root))
            x += step * min(1.0, STEP_SHARE * self.flap.width_mm / np.abs(step).max())  # no step past the skin from afar
            if np.abs(step).max() < NEWTON_TOL_MM:
                return x
        raise NotConverged("the flap's Newton iterations did not converge")

    def lowered(self, x: np.ndarray, cpap_kpa: float, skin_from: float, skin_to: float, spring: float, splits: int = 4) -> np.ndarray:
        """(dofs,) mm: the equilibrium once the skin moves from `skin_from` to `skin_to` (y, mm), from
        the solution `x` at `skin_from` with the part lying on the skin moved with it (so that Newton
        starts with it in contact); where Newton fails, the move is made in halves (`splits` times)."""
        lying = self.pressed(x, cpap_kpa, skin_from, spring).contact_kpa > 0
        start = x.copy()
        if lying.any():
            start[self.y_dofs[self.y_along >= self.along[lying].min()]] += skin_to - skin_from
        try:
            return self.equilibrium(start, cpap_kpa, skin_to, spring)
        except NotConverged:
            if splits == 0:
                raise
        middle = 0.5 * (skin_from + skin_to)
        x = self.lowered(x, cpap_kpa, skin_from, middle, spring, splits - 1)
        return self.lowered(x, cpap_kpa, middle, skin_to, spring, splits - 1)

    def pressed(self, x: np.ndarray, cpap_kpa: float, skin_y: float, spring: float) -> Pressed:
        """The solved flap at displacement `x`: its contact pressure and the root's reaction (the
        out-of-balance force at the held dofs)."""
        sink = skin_y - self.skin.global_coordinates()[1] - self.skin.interpolate(x)[1]
        r, _ = self.residual_and_tangent(x, cpap_kpa, skin_y, spring)
        return Pressed(x, x[self.tip], self.along, skin_pressure(sink, spring)[0].ravel(), self.skin.dx.ravel(),
                       (float(r[self.root_x].sum()), float(r[self.root_y].sum())))


def inflate(model: FlapModel, cpap_kpa: float, skin_y: float, spring: float, ramp: tuple = RAMP) -> np.ndarray:
    """(dofs,) mm: the flap's displacement under `cpap_kpa`, the pressure raised by the shares `ramp`
    from the flap at rest, the skin at `skin_y` mm with the push `spring` kPa/mm (0: no skin)."""
    x = np.zeros(model.basis.N)
    for share in ramp:
        x = model.equilibrium(x, share * cpap_kpa, skin_y, spring)
    return x
