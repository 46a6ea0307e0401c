"""The finite-element reference (scikit-fem): linear elasticity in plane strain on quadratic
triangles, with frictionless contact against a rigid body. It is checked on cases with known
answers (`fe_checks.py`), and measures what the fast fit model's springs (`mechanics.py`,
`tissue.py`) stand for (`calibration.py`; both run by `bench/fe_calibration.py`).

Units: mm, kPa (so forces per unit depth come out in kPa mm = mN/mm, and energy densities in kPa).
A section is a plane-strain slice of unit depth: what a long straight piece of wall or skin does.
"""

from dataclasses import dataclass

import numpy as np
from scipy.optimize import nnls
from scipy.sparse.linalg import splu
from skfem import Basis, ElementTriP2, ElementVector, FacetBasis, LinearForm, MeshTri, asm, condense, solve
from skfem.helpers import dot
from skfem.models.elasticity import lame_parameters, linear_elasticity

SILICONE_KPA, SILICONE_POISSON = 1000.0, 0.49  # a Shore A 30-40 silicone (E about 1 MPa), nearly incompressible


@dataclass(frozen=True)
class Material:
    """Young's modulus (kPa) and Poisson's ratio of a linear elastic solid."""

    youngs_kpa: float = SILICONE_KPA
    poisson: float = SILICONE_POISSON

    @property
    def plane_strain_kpa(self) -> float:
        """E / (1 - nu^2): the modulus of a plate or half-space in plane strain."""
        return self.youngs_kpa / (1.0 - self.poisson**2)


@dataclass(frozen=True)
class Section:
    """A solved section: mesh (scikit-fem MeshTri), basis, displacement (dofs, mm), reaction (dofs, kPa mm)."""

    mesh: MeshTri
    basis: Basis
    displacement: np.ndarray
    reaction: np.ndarray

    def at(self, points: np.ndarray) -> np.ndarray:
        """(P, 2) mm displacement at the mesh nodes nearest each of (P, 2) points."""
        nodes = self.mesh.p.T
        near = np.argmin(np.linalg.norm(nodes[None] - points[:, None], axis=2), axis=1)
        return self.displacement[self.basis.nodal_dofs].T[near]


def graded(lo: float, hi: float, n: int, towards: float | None = None, ratio: float = 1.0) -> np.ndarray:
    """(n + 1,) mm node coordinates over [lo, hi], finer towards `towards` (one end, or None: even)
    by a geometric `ratio` between the largest and smallest step."""
    if towards is None or ratio == 1.0:
        return np.linspace(lo, hi, n + 1)
    steps = ratio ** (np.arange(n) / max(n - 1, 1))
    x = np.concatenate([[0.0], np.cumsum(steps)]) / steps.sum()
    x = lo + (hi - lo) * (x if towards == lo else 1.0 - x[::-1])
    x[[0, -1]] = lo, hi  # exactly: boundaries are found by their coordinates
    return x


def vector_basis(mesh: MeshTri) -> Basis:
    """The quadratic vector basis of a 2-D mesh (its dofs number alike on any mesh of the same triangles)."""
    return Basis(mesh, ElementVector(ElementTriP2()))


def stiffness(mesh: MeshTri, material: Material):
    """(basis, K): the quadratic vector basis of a 2-D mesh (mm) and its plane-strain stiffness matrix."""
    basis = vector_basis(mesh)
    return basis, asm(linear_elasticity(*lame_parameters(material.youngs_kpa, material.poisson)), basis)


def pressure_load(basis: Basis, facets: np.ndarray, pressure_kpa: float) -> np.ndarray:
    """(dofs,) the load of `pressure_kpa` pushing on the boundary `facets` (into the solid)."""
    @LinearForm
    def push(v, w):
        return -pressure_kpa * dot(w.n, v)

    return asm(push, FacetBasis(basis.mesh, basis.elem, facets=facets))


def solve_section(mesh: MeshTri, material: Material, fixed: np.ndarray, moved: tuple = ((), ()),
                  load: np.ndarray | None = None) -> Section:
    """Displacements of a section with the dofs `fixed` held at zero, the dofs of `moved` (dofs,
    values mm) moved as given, under `load` (dofs,) (None: none)."""
    basis, k = stiffness(mesh, material)
    x = np.zeros(basis.N)
    dofs = np.asarray(moved[0], dtype=int)
    x[dofs] = moved[1]
    f = np.zeros(basis.N) if load is None else load
    x = solve(*condense(k, f, x=x, D=np.unique(np.concatenate([np.asarray(fixed, dtype=int), dofs]))))
    return Section(mesh, basis, x, k @ x - f)


def dofs_where(basis: Basis, where, component: str | None = None) -> np.ndarray:
    """The dofs of the boundary facets whose midpoints satisfy `where((2, P) mm) -> (P,) bool`, with
    their end nodes (scikit-fem's `get_dofs`), of one displacement component ("u^1": x, "u^2": y)
    or of both (None)."""
    dofs = basis.get_dofs(where)
    return dofs.all(component) if component else dofs.all()


def rigid_contact(mesh: MeshTri, material: Material, fixed: np.ndarray, surface: np.ndarray, gap_mm: np.ndarray) -> Section:
    """Frictionless contact of a rigid body pushed down (-y) onto a section: each y-dof of `surface`
    may not rise above its gap to the body (`gap_mm`, mm; negative where the body, moved, overlaps
    the unloaded surface). The contact forces p >= 0 (pushing the surface down) solve the linear
    complementarity problem of the surface's compliance C (the section condensed onto those dofs):
    gap + C p >= 0, p >= 0, p . (gap + C p) = 0, i.e. the least squares min |L^T p + L^-1 gap| over
    p >= 0 with C = L L^T (`scipy.optimize.nnls`). `fixed`: dofs held at zero. The reaction on a
    touching dof is its contact force (negative: down)."""
    basis, k = stiffness(mesh, material)
    surface, gap = np.asarray(surface), np.asarray(gap_mm, dtype=float)
    free = np.setdiff1d(np.arange(basis.N), fixed)
    if not np.isin(surface, free).all():
        raise ValueError("a contact dof is also held fixed")
    solve_free = splu(k.tocsc()[free][:, free]).solve
    where = np.searchsorted(free, surface)
    unit = np.zeros((len(free), len(surface)))
    unit[where, np.arange(len(surface))] = 1.0
    response = solve_free(unit)  # (free, S): displacements under a unit upward force at each surface dof
    lower = np.linalg.cholesky(response[where])
    push = nnls(lower.T, -np.linalg.solve(lower, gap))[0]
    x = np.zeros(basis.N)
    x[free] = -response @ push
    reaction = np.zeros(basis.N)
    reaction[surface] = -push
    return Section(mesh, basis, x, reaction)
