"""What the fast fit model's springs stand for, measured by the finite-element reference (`fe.py`):
per unit of contact area, how hard the skin and the cushion press back per mm they are pushed.

- The skin: a layer of soft tissue (Young's modulus E, Poisson 0.49, thickness h) bonded to bone,
  pressed by a rigid flat strip as wide as the seal flange (plane strain: the rim is long beside
  its width). A Winkler foundation says E / h; a thin, nearly incompressible layer under a strip
  wider than it is deep is much stiffer (it cannot squeeze out), a deep one under a narrow strip
  softer at the edges and stiffer in the middle. `strip_stiffness` is the mean pressure over the
  strip per mm of indentation.
- The cushion: a slice of its wall across the rim (`cushion_section`: the designed surface's
  profile from the seal to the frame ring, thickened as the solid is), its frame end held, pressed
  along the mask axis by the skin as a rigid flat body parallel to the flange. `section_stiffness`
  is the force per unit rim length per mm of travel over the contact width.
"""

import numpy as np
from skfem import MeshTri

from .fe import Material, dofs_where, graded, rigid_contact, solve_section, vector_basis
from .fe_membrane import RAMP, RIGID_KPA_PER_MM, Flap, FlapModel, inflate

TISSUE_POISSON = 0.49
OPENING_STEP_MM, OPENING_GROWTH = 0.02, 0.2  # the skin moves away by the larger of these (mm, share of the opening) a step
SIDE_WIDTHS = 8.0  # the tissue slab reaches this many strip widths (or layer depths) beside the strip


def strip_stiffness(youngs_kpa: float, thickness_mm: float, width_mm: float, cells: int = 24,
                    poisson: float = TISSUE_POISSON) -> float:
    """kPa/mm: mean pressure under a rigid frictionless strip `width_mm` wide pressed into a tissue layer
    (E `youngs_kpa`, `poisson`, `thickness_mm` deep, bonded to bone), per mm of indentation. Half the
    strip by symmetry; `cells` across the layer's depth (and across the half strip)."""
    half = 0.5 * width_mm
    side = SIDE_WIDTHS * max(width_mm, thickness_mm)
    xs = np.unique(np.concatenate([graded(0.0, half, cells, towards=half, ratio=8.0),
                                   graded(half, half + side, 2 * cells, towards=half, ratio=40.0)]))
    mesh = MeshTri.init_tensor(xs, graded(0.0, thickness_mm, cells, towards=thickness_mm, ratio=4.0))
    material = Material(youngs_kpa, poisson)
    basis = vector_basis(mesh)
    fixed = np.concatenate([dofs_where(basis, lambda x: x[1] == 0.0), dofs_where(basis, lambda x: x[0] == 0.0, "u^1")])
    under = dofs_where(basis, lambda x: (x[1] == thickness_mm) & (x[0] <= half + 1e-9), "u^2")
    section = solve_section(mesh, material, fixed, (under, -np.ones(len(under))))
    return float(-section.reaction[under].sum() / half)


def cushion_section(profile: np.ndarray, thickness_mm: float, cells_along: int = 80, cells_across: int = 4) -> tuple[MeshTri, MeshTri]:
    """A plane-strain mesh of a cushion's wall, and the same mesh in (fraction of the way from seal to
    frame, fraction of the way through the wall) (its dofs number alike). `profile` (P, 2) mm: the
    face-side surface from the seal (first point) to the frame (last) in (across the rim, along the
    mask axis away from the face) coordinates; the mesh is turned so the face lies up (y = minus the
    axial coordinate) and thickened by `thickness_mm` away from the face."""
    arc = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(profile, axis=0), axis=1))])
    param = MeshTri.init_tensor(graded(0.0, 1.0, cells_along, towards=0.0, ratio=4.0), np.linspace(0.0, 1.0, cells_across + 1))
    along, through = param.p
    at = along * arc[-1]
    point = np.column_stack([np.interp(at, arc, profile[:, k]) for k in range(2)])
    tangent = np.column_stack([np.interp(at, arc, np.gradient(profile[:, k], arc)) for k in range(2)])
    normal = np.column_stack([tangent[:, 1], -tangent[:, 0]]) / np.linalg.norm(tangent, axis=1, keepdims=True)
    normal *= np.sign(normal[:, 1].mean())  # away from the face: +axial
    xy = point + thickness_mm * through[:, None] * normal
    return MeshTri(np.vstack([xy[:, 0], -xy[:, 1]]), param.t), param


def section_stiffness(profile: np.ndarray, thickness_mm: float, contact_mm: float, travel_mm: float = 0.5,
                      bonded: bool = False, material: Material = Material()) -> float:
    """kPa/mm: the force along the mask axis per unit rim length that pushes the skin `travel_mm`
    along the axis into a cushion's wall (`profile` (P, 2) mm as for `cushion_section`, its frame
    end held), per mm of travel and mm of `contact_mm`, the flange width the fast model spreads it
    over. The skin is a rigid flat body along the flange's first `contact_mm` of profile: frictionless
    (the flange slides on it, touching where it may; the section is turned so the body lies level,
    its push along the axis an approach of travel x cos(tilt) along its normal, whose force has the
    part cos(tilt) along the axis), or `bonded` there (the flange's face side over `contact_mm` moves
    with the skin: no slip, no lift). The two bound a real flange's, which grips the skin."""
    mesh, param = cushion_section(profile, thickness_mm)
    on_param = vector_basis(param)
    fixed = dofs_where(on_param, lambda x: x[0] == 1.0)
    arc = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(profile, axis=0), axis=1))])
    flange = profile[arc <= contact_mm] * [1.0, -1.0]
    if np.ptp(flange[:, 0]) < np.ptp(flange[:, 1]):
        raise ValueError("the flange runs along the mask axis: the skin cannot push it along the axis")
    slope, level = np.polyfit(flange[:, 0], flange[:, 1], 1)
    if bonded:
        band = lambda x: (x[1] == 0.0) & (x[0] <= contact_mm / arc[-1] + 1e-9)  # noqa: E731
        ys, xs = dofs_where(on_param, band, "u^2"), dofs_where(on_param, band, "u^1")
        section = solve_section(mesh, material, fixed, (np.concatenate([ys, xs]), np.concatenate([np.full(len(ys), -travel_mm), np.zeros(len(xs))])))
        return float(-section.reaction[ys].sum() / (contact_mm * travel_mm))
    tilt = np.arctan(slope)
    level_turn = np.array([[np.cos(tilt), np.sin(tilt)], [-np.sin(tilt), np.cos(tilt)]])  # turns the skin line level
    turned = MeshTri(level_turn @ mesh.p, mesh.t)
    face = np.setdiff1d(dofs_where(on_param, lambda x: x[1] == 0.0, "u^2"), fixed)
    y = vector_basis(turned).doflocs[1, face]
    approach = travel_mm * np.cos(tilt)
    section = rigid_contact(turned, material, fixed, face, level * np.cos(tilt) - y - approach)
    return float(-section.reaction[face].sum() * np.cos(tilt) / (contact_mm * travel_mm))


def sealed_opening(flap: Flap, cpap_kpa: float, band_mm: float, spring: float = RIGID_KPA_PER_MM) -> tuple[float, float]:
    """(mm, mm): the largest seal opening at which the `flap`, inflated by `cpap_kpa`, still lies
    `band_mm` on the skin (`spring` kPa/mm: rigid, or a tissue region's), and how far it lies with
    no opening. The pressure is raised at no opening, then the skin moved away step by step (the
    last solution the next one's start) until less lies; the opening is interpolated between the
    last two steps (0 where it lies less than the band already; its width less the band, the most an
    inextensible flap reaches, where it still lies that far)."""
    model = FlapModel(flap)
    opening, skin_y = 0.0, -flap.standoff_mm
    resting = flap.standoff_mm == 0.0 and flap.lift == 0.0  # on the skin already: it takes the pressure at once
    x = inflate(model, cpap_kpa, skin_y, spring, (1.0,) if resting else RAMP)
    lying = closed = model.pressed(x, cpap_kpa, skin_y, spring).lying_mm(cpap_kpa)
    if closed < band_mm:
        return 0.0, closed
    while lying >= band_mm:
        if opening >= flap.width_mm - band_mm:
            return flap.width_mm - band_mm, closed  # it hangs to the skin: no flap reaches further
        before = (opening, lying)
        opening += max(OPENING_STEP_MM, OPENING_GROWTH * opening)
        x = model.lowered(x, cpap_kpa, skin_y - before[0], skin_y - opening, spring)
        lying = model.pressed(x, cpap_kpa, skin_y - opening, spring).lying_mm(cpap_kpa)
    return float(np.interp(band_mm, [lying, before[1]], [opening, before[0]])), closed


def root_pull(flap: Flap, cpap_kpa: float, spring: float = RIGID_KPA_PER_MM) -> tuple[float, float]:
    """(kPa mm, mm): how hard the `flap`'s root holds it off the skin per unit depth (its share of the
    air's push, which pulls the wall towards the skin) with its wall at the skin, inflated by
    `cpap_kpa`, and how far it lies on the skin then."""
    model = FlapModel(flap)
    skin_y = -flap.standoff_mm
    solved = model.pressed(inflate(model, cpap_kpa, skin_y, spring), cpap_kpa, skin_y, spring)
    return solved.root_reaction[1], solved.lying_mm(cpap_kpa)
