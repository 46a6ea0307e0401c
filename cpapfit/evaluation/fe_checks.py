"""Cases with known answers for the finite-element reference (`fe.py`): each solved at a mesh fineness
and set beside its closed-form value. The tests run them coarse, `bench/fe_calibration.py` fine.

- a cantilever plate and a strip held at both edges under pressure (plate theory, plane strain:
  q L^4 / (8 D) at the tip, q L^4 / (384 D) in the middle; D = E t^3 / (12 (1 - nu^2)));
- a rigid cylinder pressed into a block (Hertz, plane strain: half-width b = sqrt(4 F R / (pi E*)),
  and the elliptic pressure's share of the load inside b / 2, 2 / pi (pi / 6 + sqrt(3) / 4));
- a wide strip pressed into a thin bonded layer (the confined, oedometric modulus per mm of depth);
- the membrane section (`fe_membrane.py`, geometrically nonlinear): a flap under a small pressure
  (the cantilever, q L^4 / (8 D)); under a large one (the elastica of a cantilever under a uniform
  follower pressure: D theta'' = q (cos theta (x_L - x) + sin theta (y_L - y)), clamped at the root,
  no moment at the tip, solved by `scipy.integrate.solve_bvp`); laid by the pressure on a rigid
  plane, its root raised h (the plate on a rigid foundation: it touches down tangent with no
  moment, a = (72 D h / q)^(1/4) from the root, and lies on the plane under the pressure q).
"""

from dataclasses import dataclass

import numpy as np
from scipy.integrate import solve_bvp
from skfem import MeshTri

from .calibration import strip_stiffness
from .fe import Material, dofs_where, graded, pressure_load, rigid_contact, solve_section, vector_basis
from .fe_membrane import RIGID_KPA_PER_MM, Flap, FlapModel, Pressed, inflate
from .membrane import bending_stiffness

SILICONE = Material()


@dataclass(frozen=True)
class Check:
    """A computed value beside the closed-form one (same unit)."""

    name: str
    unit: str
    computed: float
    expected: float

    @property
    def error(self) -> float:
        """Relative error of the computed value."""
        return self.computed / self.expected - 1.0


def plate_checks(cells: int = 40, length_mm: float = 20.0, pressure_kpa: float = 0.01) -> tuple[Check, Check]:
    """A 1 mm silicone plate `length_mm` long under `pressure_kpa`, `cells` along it: held at one end
    (tip deflection), held at both (middle deflection), mm."""
    mesh = MeshTri.init_tensor(np.linspace(0.0, length_mm, cells + 1), np.linspace(0.0, 1.0, 5))
    basis = vector_basis(mesh)
    load = pressure_load(basis, mesh.facets_satisfying(lambda x: x[1] == 1.0), pressure_kpa)
    rigidity = SILICONE.plane_strain_kpa / 12.0  # D of a 1 mm plate, kPa mm^3

    def bends(held, at: float) -> float:
        return float(-solve_section(mesh, SILICONE, dofs_where(basis, held), load=load).at(np.array([[at, 0.5]]))[0, 1])

    end = lambda x: x[0] == 0.0  # noqa: E731
    both = lambda x: (x[0] == 0.0) | (x[0] == length_mm)  # noqa: E731
    q4 = pressure_kpa * length_mm**4 / rigidity
    return (Check("cantilever plate under pressure: tip deflection", "mm", bends(end, length_mm), q4 / 8.0),
            Check("strip held at both edges under pressure: middle deflection", "mm", bends(both, 0.5 * length_mm), q4 / 384.0))


def hertz_checks(cells: int = 30, radius_mm: float = 30.0, depth_mm: float = 1.0, block_mm: float = 40.0) -> tuple[Check, Check]:
    """A rigid cylinder of `radius_mm` pushed `depth_mm` into a silicone block (half of it, by symmetry,
    `cells` across and half as many down, finer towards the contact): the contact half-width (mm) and
    the share of the load inside half of it."""
    mesh = MeshTri.init_tensor(graded(0.0, block_mm, cells, towards=0.0, ratio=30.0),
                               graded(0.0, block_mm, cells // 2, towards=block_mm, ratio=30.0))
    basis = vector_basis(mesh)
    fixed = np.concatenate([dofs_where(basis, lambda x: x[1] == 0.0), dofs_where(basis, lambda x: x[0] == 0.0, "u^1")])
    top = dofs_where(basis, lambda x: x[1] == block_mm, "u^2")
    x = basis.doflocs[0, top]
    force = -rigid_contact(mesh, SILICONE, fixed, top, x**2 / (2.0 * radius_mm) - depth_mm).reaction[top]
    total = 2.0 * force.sum()
    half_width = np.sqrt(4.0 * total * radius_mm / (np.pi * SILICONE.plane_strain_kpa))
    edge = x[force > 1e-9 * total].max()
    return (Check("Hertz cylinder: contact half-width", "mm", 0.5 * (edge + x[x > edge].min()), half_width),
            Check("Hertz cylinder: share of the load inside half the width", "", 2.0 * force[x <= 0.5 * half_width].sum() / total,
                  2.0 / np.pi * (np.pi / 6.0 + np.sqrt(3.0) / 4.0)))


def confined_layer_check(cells: int = 8, youngs_kpa: float = 100.0, poisson: float = 0.3) -> Check:
    """A strip 40 times as wide as a 1 mm bonded layer is deep: kPa per mm, the oedometric modulus."""
    oedometric = youngs_kpa * (1 - poisson) / ((1 + poisson) * (1 - 2 * poisson))
    return Check("wide strip on a thin bonded layer: stiffness", "kPa/mm", strip_stiffness(youngs_kpa, 1.0, 40.0, cells, poisson), oedometric)


def elastica_tip(length_mm: float, rigidity: float, pressure_kpa: float) -> np.ndarray:
    """(2,) mm: the tip's displacement of an inextensible cantilever (`rigidity` D kPa mm^3 per unit
    depth) under a uniform follower pressure on its upper side (module docstring)."""
    load = pressure_kpa / rigidity

    def bends(s, y, p):
        theta, curvature, x, z = y
        return np.vstack([curvature, load * (np.cos(theta) * (p[0] - x) + np.sin(theta) * (p[1] - z)), np.cos(theta), np.sin(theta)])

    def ends(start, end, p):
        return np.array([start[0], start[2], start[3], end[1], end[2] - p[0], end[3] - p[1]])

    s = np.linspace(0.0, length_mm, 101)
    linear = -load * (length_mm**3 - (length_mm - s) ** 3) / 6.0
    guess = np.vstack([linear, -load * (length_mm - s) ** 2 / 2.0, s, np.zeros_like(s)])
    solved = solve_bvp(bends, ends, s, guess, p=[length_mm, -load * length_mm**4 / 8.0], tol=1e-8)
    return solved.p - [length_mm, 0.0]


def flap_checks(cells: int = 48, width_mm: float = 6.0, thickness_mm: float = 0.5, bent: float = 4.0) -> tuple[Check, Check]:
    """A flap (no skin) under a small pressure and under one of `bent` D / L^3 (a large deflection):
    its tip's deflection, mm, against the plate's and the elastica's."""
    model = FlapModel(Flap(width_mm, thickness_mm, cells=(cells, 2)))
    rigidity = bending_stiffness(thickness_mm)
    small, large = 1e-4, bent * rigidity / width_mm**3

    def tip(pressure: float) -> float:
        return float(-model.pressed(inflate(model, pressure, 0.0, 0.0, ramp=(1.0,)), pressure, 0.0, 0.0).tip[1])

    return (Check("flap under a small pressure: tip deflection", "mm", tip(small), small * width_mm**4 / (8.0 * rigidity)),
            Check("flap under a large pressure: tip deflection (elastica)", "mm", tip(large), float(-elastica_tip(width_mm, rigidity, large)[1])))


def laid_flap(cells: int = 24, width_mm: float = 8.0, thickness_mm: float = 0.5, pressure_kpa: float = 1.96,
              raised_mm: float = 0.2, steps: int = 4) -> tuple[Pressed, float]:
    """(the solved flap, the plate's touch-down distance from the root, mm): a flap laid by
    `pressure_kpa` on a rigid plane, the plane moved from the root's level (where the flap rests on
    it) to `raised_mm` below it in `steps`."""
    model = FlapModel(Flap(width_mm, thickness_mm, cells=(cells, 2)))
    x = inflate(model, pressure_kpa, 0.0, RIGID_KPA_PER_MM, ramp=(1.0,))
    levels = np.linspace(0.0, -raised_mm, steps + 1)
    for before, level in zip(levels[:-1], levels[1:]):
        x = model.lowered(x, pressure_kpa, before, level, RIGID_KPA_PER_MM)
    touchdown = (72.0 * bending_stiffness(thickness_mm) * raised_mm / pressure_kpa) ** 0.25
    return model.pressed(x, pressure_kpa, -raised_mm, RIGID_KPA_PER_MM), touchdown


def all_checks(fine: bool = False) -> tuple[Check, ...]:
    """Every case, coarse (the tests') or fine (the bench's)."""
    scale = 2 if fine else 1
    return (*plate_checks(40 * scale), *hertz_checks(30 * scale), confined_layer_check(8 * scale), *flap_checks(48 * scale))

