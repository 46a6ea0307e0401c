"""The self-sealing membrane: its law, its geometry on a designed cushion, and what it seals."""

from dataclasses import replace

import numpy as np
import pytest
import trimesh

from cpapfit.cushion.envelope import twisted_columns
from cpapfit.cushion.nurbs import AROUND
from cpapfit.evaluation.fit import FitParams, fit_rim
from cpapfit.evaluation.membrane import BAND_MM, MEMBRANE_MAX_MM, bending_stiffness, reach_mm, width_for
from cpapfit.evaluation.rim import REFINE_MM, refined
from cpapfit.evaluation.states import FaceState, fit_states
from cpapfit.pipeline import evaluated_cushions, face_for

P4 = 4 * 0.0980665  # kPa: the lowest CPAP pressure


def test_a_flap_reaches_as_far_as_the_pressure_lays_it_on_the_skin():
    """The plate laid on the skin (a = w - 2 mm + t, D = 13.71 kPa mm^3 for 0.5 mm silicone, its drop
    P a^4 / 72 D short by 0.22 drop / a): at 10 cmH2O a 0.5 mm flap 10 mm wide closes
    5.19 (1 - 0.22 x 5.19 / 8.5) - 0.1 a / 3 - 0.15 = 4.06 mm, 5 mm wide nothing; at 40 cmH2O a 10 mm
    flap its whole 8 mm less the band. No flap, no reach."""
    assert bending_stiffness(0.5) == pytest.approx(1000 * 0.125 / (12 * (1 - 0.49**2)))
    p10 = 10 * 0.0980665
    drop = p10 * 8.5**4 / (72 * 13.7054)
    got = reach_mm(np.array([10.0, 5.0, 0.0]), np.array([0.5, 0.5, 0.0]), p10)
    assert got == pytest.approx([drop * (1 - 0.22 * drop / 8.5) - 0.1 * 8.5 / 3 - 0.15, 0.0, 0.0], abs=1e-3)
    assert got[0] == pytest.approx(4.06, abs=0.01)
    assert reach_mm(np.array([10.0]), np.array([0.5]), 4 * p10)[0] == 10.0 - BAND_MM
    need = np.array([0.5, 2.0, 5.0, 8.0])
    widths = width_for(need, 0.5, P4)
    assert reach_mm(widths, np.full(4, 0.5), P4) == pytest.approx(need, abs=1e-9)  # the narrowest flap that reaches
    assert reach_mm(widths - 0.05, np.full(4, 0.5), P4).max() < need.max()


@pytest.mark.parametrize("thick", [0.5, 2.2])
def test_a_sheet_is_as_thick_everywhere_once_refined_its_free_edge_too(thick):
    """A closed slab `thick` mm thick, 20 x 10 mm, in 12 long triangles, refined to 1 mm edges: every
    vertex reads the slab's thickness within 0.01 mm, the ones made on its end faces too (whose own
    rays run 10-20 mm along the slab); a 0.5 mm one is all membrane, a 2.2 mm one all wall. Read as
    wall, a flap's free edge would be taken for the rim wherever it touches the side of the nose."""
    fine, thickness = refined(trimesh.creation.box((thick, 20.0, 10.0)))
    assert len(fine.vertices) > 200 and fine.edges_unique_length.max() <= REFINE_MM
    assert thickness == pytest.approx(np.full(len(thickness), thick), abs=0.01)
    assert (thickness <= MEMBRANE_MAX_MM).all() == (thick < MEMBRANE_MAX_MM)


def test_the_designed_membrane_is_found_on_the_cushion_as_wide_and_thick_as_designed(designed):
    """The written solid's thin part, measured section by section along its rim as `evaluate` does,
    against the flap's width designed there (seal curve to free edge): within 0.5 mm in the median,
    nowhere 3 mm wider (the measure errs short where the rim turns; where flaps 10-13 mm wide meet
    at the corners beside the nose, a section there reads some of a neighbour), and as thick as
    designed there (the set 0.5 mm, thinner where a flap had to narrow) within 0.05 mm in the median."""
    _, d = designed
    rim = d.fits["custom"].rim
    seal, tip = d.cushion.grid(256, 2)[:, 0], d.cushion.membrane_grid(256, 8)[:, -1]
    near = np.argmin(np.linalg.norm(rim.points[:, None] - seal[None], axis=2), axis=1)
    error = rim.membrane_mm - np.linalg.norm(tip - seal, axis=1)[near]
    assert abs(np.median(error)) < 0.5 and error.max() < 3.0
    thick = d.cushion.membrane_thickness_at(256)[near]
    assert np.median(np.abs(rim.membrane_thickness_mm - thick)[rim.membrane_mm > 0]) < 0.05


def test_each_flap_as_built_reaches_the_margin_at_the_lowest_pressure(designed):
    """Each control column's flap, as built (seal curve to free edge in a straight line, however the
    skin under it curves), at its set thickness, reaches the prediction's margin (0.75 mm) at 4
    cmH2O within 0.01 mm, unless it is already at the thinnest sheet (the flap laid along skin
    that curves under it is shorter than the width asked: its sheet is thinner to reach as far)."""
    from cpapfit.cushion.envelope import MARGIN_MM, THINNEST_MM, built_widths

    _, d = designed
    thick = d.cushion.membrane_thickness
    reach = reach_mm(built_widths(d.cushion), thick, P4)
    assert (reach[thick > THINNEST_MM + 1e-3] >= MARGIN_MM - 0.01).all()


def test_the_membrane_closes_the_opening_it_reaches_and_leaks_past_it(designed, placed_subjects):
    """The custom cushion pushed 4 mm sideways: with no membrane its wall opens; a 10 mm flap (reach
    4.06 mm at 10 cmH2O) closes each opening by its reach (what is left leaks), and lowers the leak."""
    ph, d = designed
    _, scan, _ = placed_subjects(ph.seed)
    face = face_for(scan, d.alignment, d.registration)
    pushed = fit_states(evaluated_cushions(d.alignment, d.solid, None), face, (FaceState("pushed", shift_mm=4.0),),
                        d.cushion.params.flange_mm, d.fits["custom"].force_n, d.fit_params)[0].fits["custom"]
    rim = pushed.rim
    bare = fit_rim(replace(rim, membrane_mm=np.zeros(len(rim.points))), face, 5.0, pushed.force_n, FitParams())
    flap = fit_rim(replace(rim, membrane_mm=np.full(len(rim.points), 10.0), membrane_thickness_mm=np.full(len(rim.points), 0.5)),
                   face, 5.0, pushed.force_n, FitParams())
    c = rim.covered
    reach = reach_mm(np.array([10.0]), np.array([0.5]), FitParams().cpap_kpa)[0]
    assert bare.opening_mm[c].max() > 0.5
    assert flap.opening_mm[c] == pytest.approx(np.maximum(bare.opening_mm[c] - reach, 0.0), abs=1e-9)
    assert flap.leak_l_min[c].sum() < bare.leak_l_min[c].sum()


@pytest.mark.parametrize("turn", [1, -1])
def test_flaps_pointing_at_a_circles_centre_close_by_one_over_its_radius_whichever_way_it_runs(turn):
    """A 20 mm circle on a plane, run either way round: the flaps point at its centre (fanned or
    not) and close on each other by 1/20 per mm of width."""
    from cpapfit.cushion.nurbs import flap_directions, inwards
    from cpapfit.cushion.envelope import converging

    angle = turn * np.linspace(0.0, 2 * np.pi, 32, endpoint=False)
    circle = 20.0 * np.column_stack([np.cos(angle), np.sin(angle), np.zeros(32)])
    up = np.tile([0.0, 0.0, 1.0], (32, 1))
    assert inwards(circle, up) == pytest.approx(-circle / 20.0, abs=1e-9)
    assert flap_directions(circle, up) == pytest.approx(-circle / 20.0, abs=1e-9)
    assert converging(circle, inwards(circle, up)) == pytest.approx(np.full(32, 1 / 20.0), rel=1e-9)


def test_flaps_fan_out_across_a_tight_bend():
    """A 60 x 30 mm rectangle on a plane with corners rounded to 5 mm, 32 points round it: flaps
    5.4 mm apart square to it close on each other at the corners at least 1/8 per mm of width;
    fanned, at most 0.6 times as fast, so a flap there may be 1.7 times as wide."""
    from cpapfit.cushion.nurbs import flap_directions, inwards
    from cpapfit.cushion.contact import closed_resample
    from cpapfit.cushion.envelope import converging

    corner = np.linspace(0.0, np.pi / 2, 16)
    arcs = [np.column_stack([cx + 5 * np.cos(corner + q * np.pi / 2), cy + 5 * np.sin(corner + q * np.pi / 2)])
            for q, (cx, cy) in enumerate([(25, 10), (-25, 10), (-25, -10), (25, -10)])]
    loop = closed_resample(np.column_stack([np.vstack(arcs), np.zeros(64)]), 32)
    up = np.tile([0.0, 0.0, 1.0], (32, 1))
    square = converging(loop, inwards(loop, up)).max()
    assert square >= 1 / 8.0
    assert converging(loop, flap_directions(loop, up)).max() <= 0.6 * square


def test_a_flap_too_narrow_for_its_need_is_thinner_just_enough_to_reach_it():
    """Flaps 12, 10, 9 and 3 mm wide that must reach 2 mm at 4 cmH2O: the 12 mm one reaches it at the
    set 0.5 mm (it stays 0.5), the 10 and 9 mm ones are thinned to where they reach 2 mm within
    0.01 mm and no thicker sheet would, the 3 mm one (reach at most 1 mm, width less the band)
    is as thin as allowed."""
    from cpapfit.cushion.envelope import THINNEST_MM, flap_thickness
    from cpapfit.evaluation.fit import KPA_PER_CMH2O

    widths, need, p = np.array([12.0, 10.0, 9.0, 3.0]), np.full(4, 2.0), 4.0 * KPA_PER_CMH2O
    t = flap_thickness({p: need}, widths, 0.5)
    assert t[0] == 0.5 and t[3] == THINNEST_MM
    assert THINNEST_MM < t[2] < t[1] < 0.5
    assert reach_mm(widths[1:3], t[1:3], p) == pytest.approx([2.0, 2.0], abs=0.01)
    assert (reach_mm(widths[1:3], t[1:3] + 0.01, p) < 2.0).all()


def test_a_membrane_needs_to_reach_each_opening_at_the_pressure_it_opens_at():
    """Openings of 2 mm in a pillow state (pressed at the awake 10 cmH2O) and 1 mm at CPAP 4
    cmH2O, 6 mm in a state that lifts the mask off: the membrane must reach 2 x 1.25 + 0.75 = 3.25
    mm at 10 cmH2O over the sectors beside the pillow's opening, 1 x 1.25 + 0.75 = 2.0 mm at 4 cmH2O
    beside the other and 0.75 mm (the margin) elsewhere, and nothing for the lifted state (with the
    4 cmH2O state lifted off too, the 0.75 mm margin alone there); the flap that
    reaches 3.25 mm at 10 cmH2O is narrower than one reaching it at 4."""
    from types import SimpleNamespace

    from cpapfit.cushion.envelope import LOWEST_CPAP_KPA, MARGIN_MM, WINDOW, needed_reach
    from cpapfit.evaluation.fit import KPA_PER_CMH2O
    from cpapfit.evaluation.rim import SECTORS

    def state(cmh2o, at, mm, lifted=False):
        opening = np.zeros(SECTORS)
        opening[at] = mm
        return SimpleNamespace(state=SimpleNamespace(cpap_cmh2o=cmh2o),
                               fits={"custom": SimpleNamespace(opening_mm=opening, pressed=SimpleNamespace(lifted=lifted))})

    awake_kpa = 10.0 * KPA_PER_CMH2O
    awake = state(None, 0, 0.0).fits["custom"]
    need = needed_reach((state(None, 40, 2.0), state(4.0, 90, 1.0), state(20.0, 60, 6.0, lifted=True)), awake, awake_kpa)
    assert sorted(need) == sorted([awake_kpa, LOWEST_CPAP_KPA])
    assert need[awake_kpa][40 - WINDOW: 41 + WINDOW] == pytest.approx(np.full(2 * WINDOW + 1, 3.25))
    assert need[awake_kpa][41 + WINDOW:].max() == pytest.approx(0.75)
    beside = np.zeros(SECTORS, dtype=bool)
    beside[90 - WINDOW: 91 + WINDOW] = True
    assert need[LOWEST_CPAP_KPA][beside] == pytest.approx(np.full(beside.sum(), 2.0))
    assert need[LOWEST_CPAP_KPA][~beside] == pytest.approx(np.full(SECTORS - beside.sum(), 0.75))
    lifted = needed_reach((state(None, 40, 2.0), state(4.0, 90, 1.0, lifted=True)), awake, awake_kpa)
    assert MARGIN_MM == 0.75 and lifted[LOWEST_CPAP_KPA] == pytest.approx(np.full(SECTORS, MARGIN_MM))
    assert width_for(np.array([3.25]), 0.5, awake_kpa)[0] < width_for(np.array([3.25]), 0.5, LOWEST_CPAP_KPA)[0] - 2.0


def test_a_membrane_is_as_thick_column_by_column_as_it_is_set():
    """A flat ring of membrane (seal circle of 20 mm, flaps 8 mm inwards) set 0.3 mm thick on half
    its control columns and 0.5 mm on the other half, thickened and joined to a wall: the solid's
    thickness, measured across it, is 0.3 and 0.5 mm within 0.02 mm in the median over each half
    (away from the two columns where it changes), the thinner half not grown with the thicker, and
    the columns either side of each change are nearer their own thickness than their neighbour's."""
    from cpapfit.cushion.nurbs import AROUND, MEMBRANE_ROWS, Cushion, CushionParams, periodic_interpolation
    from cpapfit.cushion.solid import with_membrane
    from cpapfit.evaluation.membrane import face_thickness_mm, vertex_thickness_mm

    angle = np.linspace(0.0, 2 * np.pi, AROUND, endpoint=False)
    ring = np.column_stack([np.cos(angle), np.sin(angle), np.zeros(AROUND)])
    rows = np.stack([ring * (20.0 - 8.0 * j / (MEMBRANE_ROWS - 1)) for j in range(MEMBRANE_ROWS)], axis=1)
    net = np.stack([periodic_interpolation(rows[:, j]) for j in range(MEMBRANE_ROWS)], axis=1)
    set_mm = np.where(np.arange(AROUND) < AROUND // 2, 0.3, 0.5)
    cushion = Cushion("nasal", net, np.array([0.0, 0.0, 1.0]), np.array([0.0, 1.0, 0.0]), CushionParams(), net, set_mm)
    wall = trimesh.creation.box((4.0, 4.0, 4.0), trimesh.transformations.translation_matrix([0.0, 0.0, 20.0]))
    solid, (thinnest, share), crossings = with_membrane(cushion, wall, np.tile([0.0, 0.0, 1.0], (AROUND, 1)))
    assert crossings == 0
    assert thinnest == pytest.approx(0.3, abs=0.01) and share >= 0.99
    thick = vertex_thickness_mm(solid, face_thickness_mm(solid))
    flap = (solid.vertices[:, 2] < 1.0) & np.isfinite(thick)
    column = np.round(np.arctan2(solid.vertices[:, 1], solid.vertices[:, 0]) % (2 * np.pi) / (2 * np.pi) * AROUND).astype(int) % AROUND
    for half, mm in ((np.arange(2, AROUND // 2 - 2), 0.3), (np.arange(AROUND // 2 + 2, AROUND - 2), 0.5)):
        assert np.median(thick[flap & np.isin(column, half)]) == pytest.approx(mm, abs=0.02)
    edges = [np.median(thick[flap & (column == c)]) for c in (0, AROUND // 2 - 1, AROUND // 2, AROUND - 1)]
    assert max(edges[0], edges[1]) < 0.4 < min(edges[2], edges[3])  # each column as set, not its neighbour's


def test_a_flap_as_built_reaches_from_the_seal_to_its_free_edge_column_by_column():
    """Flaps from a 20 mm seal circle inwards, 6 and 9 mm wide on alternate control columns:
    laid flat, `built_widths` reads each column's own width within 0.01 mm; bent down over a
    rounded edge of 6 mm radius (the same lengths along the sheet), their chord 2 r sin(w / 2 r),
    5.75 and 8.18 mm, within 0.01 mm: shorter than asked, as the evaluation reads them."""
    from cpapfit.cushion.envelope import built_widths
    from cpapfit.cushion.nurbs import AROUND, MEMBRANE_ROWS, Cushion, CushionParams, periodic_interpolation

    angle = np.linspace(0.0, 2 * np.pi, AROUND, endpoint=False)
    out = np.column_stack([np.cos(angle), np.sin(angle), np.zeros(AROUND)])
    width = np.where(np.arange(AROUND) % 2 == 0, 6.0, 9.0)
    along = width[:, None] * np.arange(MEMBRANE_ROWS) / (MEMBRANE_ROWS - 1)  # (AROUND, rows) mm along the sheet

    def net(rows):
        return np.stack([periodic_interpolation(rows[:, j]) for j in range(rows.shape[1])], axis=1)

    wall = net(np.stack([20.0 * out + [0.0, 0.0, z] for z in (0.0, 5.0, 10.0, 15.0)], axis=1))
    flat = net(out[:, None] * (20.0 - along)[..., None])
    radius = 6.0
    inward, down = radius * np.sin(along / radius), radius * (1.0 - np.cos(along / radius))
    bent = net(out[:, None] * (20.0 - inward)[..., None] - down[..., None] * [0.0, 0.0, 1.0])
    z, y = np.array([0.0, 0.0, 1.0]), np.array([0.0, 1.0, 0.0])
    assert built_widths(Cushion("nasal", wall, z, y, CushionParams(), flat)) == pytest.approx(width, abs=0.01)
    chord = 2 * radius * np.sin(width / (2 * radius))
    assert built_widths(Cushion("nasal", wall, z, y, CushionParams(), bent)) == pytest.approx(chord, abs=0.01)


def test_the_membrane_joined_with_its_slivers_collapsed_is_the_same_cushion_to_a_print_resolution(designed, monkeypatch):
    """A designed cushion's membrane joined to its wall, the union taken for one that crosses
    itself (its crossing count read as 1), comes back with its features finer than
    PRINT_RESOLUTION_MM (0.05 mm) collapsed: watertight, crossing itself nowhere (the count
    returned is the collapsed solid's, 0), each of its vertices within twice PRINT_RESOLUTION_MM of
    the plain union's surface and the plain union's within twice PRINT_RESOLUTION_MM of it (the
    collapse moves the surface by up to 0.085 mm here), its volume within 0.2 %."""
    import cpapfit.cushion.solid as solid_module
    from cpapfit.cushion.solid import cushion_solid, with_membrane
    from cpapfit.solids import PRINT_RESOLUTION_MM, self_intersecting_edges

    _, d = designed
    wall = cushion_solid(d.cushion, d.contact.normals)[0]
    plain, _, crossings = with_membrane(d.cushion, wall, d.contact.normals)
    assert crossings == 0 == self_intersecting_edges(plain)
    union = len(plain.vertices)  # the plain union, made again, is taken for one crossing itself at an edge
    monkeypatch.setattr(solid_module, "self_intersecting_edges", lambda mesh: 1 if len(mesh.vertices) == union else self_intersecting_edges(mesh))
    simple, _, crossings = with_membrane(d.cushion, wall, d.contact.normals)
    assert crossings == 0 and simple.is_watertight and self_intersecting_edges(simple) == 0
    assert np.abs(trimesh.proximity.signed_distance(plain, simple.vertices)).max() <= 2 * PRINT_RESOLUTION_MM
    assert np.abs(trimesh.proximity.signed_distance(simple, plain.vertices)).max() <= 2 * PRINT_RESOLUTION_MM
    assert simple.volume == pytest.approx(plain.volume, rel=2e-3)


@pytest.mark.parametrize("k0", [12, 13, 127])
def test_a_sheet_closing_up_narrows_the_columns_that_shape_where_it_closes(k0):
    """A flat annular sheet whose rows close up between grid rows k0 and k0 + 1 of 128: that step
    lies between columns j + 1 and j + 2 (j = k0 AROUND // 128, `Cushion.membrane_thickness_at`),
    so the cubic's columns j..j + 3 are flagged (around the seal's end too), and none elsewhere."""
    n_u = 128
    angle = 2 * np.pi * np.arange(n_u) / n_u
    radius = np.array([30.0, 27.0, 24.0])
    grid = np.stack([np.outer(np.cos(angle), radius), np.outer(np.sin(angle), radius), np.zeros((n_u, 3))], axis=-1)
    assert not twisted_columns(grid).any()
    after = (k0 + 1) % n_u
    grid[after, 1:] = grid[k0, 1:] + 0.01 * (grid[after, 1:] - grid[k0, 1:])  # the inner rows stop moving around there
    j = k0 * AROUND // n_u
    assert set(np.flatnonzero(twisted_columns(grid))) == {(j + d) % AROUND for d in range(4)}


def test_flaps_narrowed_where_the_sheet_twists_step_down_over_their_neighbours():
    """Flaps 10.5 mm wide, narrowed to 7.9 mm on columns 12-21 and to 5 mm on column 0: each
    neighbour of a narrowed stretch comes down to within TAPER_MM per column of it (9.9, 8.9 beside
    the stretch, 6, 7, ... either side of column 0, round the seal's end), no flap widens, and
    columns beyond the taper keep their 10.5 mm."""
    from cpapfit.cushion.envelope import TAPER_MM, tapered

    widths = np.full(AROUND, 10.5)
    widths[12:22], widths[0] = 7.9, 5.0
    out = tapered(widths)
    assert (out <= widths).all() and np.abs(out - np.roll(out, 1)).max() <= TAPER_MM + 1e-12
    assert out[[10, 11, 22, 23]] == pytest.approx([7.9 + 2 * TAPER_MM, 7.9 + TAPER_MM, 7.9 + TAPER_MM, 7.9 + 2 * TAPER_MM])
    assert out[[AROUND - 2, AROUND - 1, 1, 2]] == pytest.approx([5.0 + 2 * TAPER_MM, 5.0 + TAPER_MM, 5.0 + TAPER_MM, 5.0 + 2 * TAPER_MM])
    assert out[12:22] == pytest.approx(np.full(10, 7.9)) and out[6] == 10.5
