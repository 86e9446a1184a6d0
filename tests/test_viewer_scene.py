"""The viewer's scene geometry (mocaplab.widgets.scene) without any 3D stack: hand-computed answers.

The module must import without pyvista or VTK (checked in a fresh
interpreter); the tubes, spheres, overlay cells, ground grid and camera
framing are checked against answers worked out by hand.
"""

from __future__ import annotations

import subprocess
import sys
import textwrap

import numpy as np
import pytest
from mocaplab.widgets.scene import (
    SphereSet,
    box_corners,
    character_geometry,
    fit_view,
    ground_grid,
    overlay_cells,
    tube_faces,
    tube_points,
)


def test_the_scene_imports_without_pyvista_or_vtk():
    code = textwrap.dedent(
        """
        import sys
        import mocaplab.widgets.scene
        heavy = sorted(m for m in sys.modules if m.split(".")[0] in ("pyvista", "vtk", "vtkmodules", "trame", "ipywidgets"))
        print(heavy)
        """
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert out.returncode == 0, out.stderr
    assert out.stdout.strip() == "[]", f"the scene module loaded a 3D or UI package: {out.stdout}"


def test_a_tube_has_its_rings_at_the_radius_around_its_bone():
    a = np.array([[0.0, 0.0, 0.0], [1.0, 1.0, 1.0]])
    b = np.array([[0.0, 2.0, 0.0], [1.0, 1.0, 4.0]])  # along y, along z
    pts, normals = tube_points(a, b, 0.1, 8)
    assert pts.shape == normals.shape == (2 * 2 * 8, 3)
    rings = pts.reshape(2, 2, 8, 3)
    # first bone: the y axis; its rings lie at y = 0 and y = 2, 0.1 m from the axis
    assert np.allclose(rings[0, 0, :, 1], 0.0) and np.allclose(rings[0, 1, :, 1], 2.0)
    assert np.allclose(np.hypot(rings[0, ..., 0], rings[0, ..., 2]), 0.1)
    # second bone: parallel to z through (1, 1); rings at z = 1 and z = 4
    assert np.allclose(rings[1, 0, :, 2], 1.0) and np.allclose(rings[1, 1, :, 2], 4.0)
    assert np.allclose(np.hypot(rings[1, ..., 0] - 1.0, rings[1, ..., 1] - 1.0), 0.1)
    # the ring's points are evenly spread (a regular octagon: neighbours 2 r sin(pi / 8) apart)
    side = np.linalg.norm(np.diff(rings[0, 0], axis=0, append=rings[0, 0, :1]), axis=-1)
    assert np.allclose(side, 2 * 0.1 * np.sin(np.pi / 8))
    # normals: unit, radial (from the axis to the point), perpendicular to the bone
    n = normals.reshape(2, 2, 8, 3)
    assert np.allclose(np.linalg.norm(normals, axis=-1), 1.0)
    assert np.allclose(n[0, ..., 1], 0.0) and np.allclose(n[1, ..., 2], 0.0)
    assert np.allclose(rings[0, 0] - a[0], 0.1 * n[0, 0])


def test_a_zero_length_bone_is_a_flat_ring_not_nan():
    p = np.array([[0.5, 0.5, 0.5]])
    pts, normals = tube_points(p, p, 0.2, 6)
    assert np.all(np.isfinite(pts)) and np.all(np.isfinite(normals))
    assert np.allclose(np.linalg.norm(pts - p, axis=-1), 0.2)


def test_tube_faces_are_quads_between_each_bones_two_rings():
    faces = tube_faces(2, 4).reshape(2, 4, 5)
    assert np.all(faces[..., 0] == 4)
    # first bone's first quad: ring a points 0, 1, then ring b points 5, 4 (4 points per ring)
    assert faces[0, 0, 1:].tolist() == [0, 1, 5, 4]
    assert faces[0, 3, 1:].tolist() == [3, 0, 4, 7], "the last quad closes the ring"
    assert faces[1, 0, 1:].tolist() == [8, 9, 13, 12], "the second bone starts after the first's 8 points"


def test_a_sphere_set_translates_copies_of_its_template():
    octahedron = np.array([[1, 0, 0], [-1, 0, 0], [0, 1, 0], [0, -1, 0], [0, 0, 1], [0, 0, -1]], dtype=float)
    tris = np.array([[0, 2, 4], [2, 1, 4], [1, 3, 4], [3, 0, 4], [2, 0, 5], [1, 2, 5], [3, 1, 5], [0, 3, 5]])
    spheres = SphereSet.from_unit(octahedron, tris, 0.5)
    centres = np.array([[0.0, 0.0, 0.0], [10.0, 0.0, 0.0]])
    pts = spheres.points(centres)
    assert pts.shape == (12, 3)
    assert np.allclose(pts[:6], 0.5 * octahedron) and np.allclose(pts[6:], 0.5 * octahedron + [10.0, 0.0, 0.0])
    faces = spheres.faces(2).reshape(2, 8, 4)
    assert np.all(faces[..., 0] == 3) and np.array_equal(faces[1, :, 1:], tris + 6)
    assert np.allclose(spheres.normals(2), np.tile(octahedron, (2, 1)))


def test_fit_view_puts_a_cubes_front_face_on_the_pictures_edges():
    """A cube of side 2 at the origin seen along -z with a 90 degree view: the camera stands at z = 2.

    The front face (z = 1) spans x, y in [-1, 1]; at depth 1 a 90 degree view
    sees exactly that.  Keeping the top quarter free (top_band 0.25) the
    picture's y range at depth z is [-z, z / 2]: with the focal point raised
    by c, the front face needs 1 - c <= (d - 1) / 2 and -1 - c >= -(d - 1),
    so d = 7 / 3 and c = 1 / 3 (x then fits: 1 <= d - 1).
    """
    cube = [[x, y, z] for x in (-1.0, 1.0) for y in (-1.0, 1.0) for z in (-1.0, 1.0)]
    focal, position = fit_view(cube, [0.0, 0.0, 3.0], [0.0, 1.0, 0.0], view_angle=90.0, aspect=1.0, fill=1.0)
    assert np.allclose(focal, 0.0, atol=1e-9) and np.allclose(position, [0.0, 0.0, 2.0], atol=1e-9)
    focal, position = fit_view(cube, [0, 0, 1], [0, 1, 0], view_angle=90.0, aspect=1.0, fill=1.0, top_band=0.25)
    assert np.allclose(focal, [0.0, 1 / 3, 0.0], atol=1e-9)
    assert np.allclose(position, [0.0, 1 / 3, 7 / 3], atol=1e-9)
    # a wide picture changes nothing here (the height binds); a narrow one moves the camera back
    _, wide = fit_view(cube, [0, 0, 1], [0, 1, 0], view_angle=90.0, aspect=2.0, fill=1.0)
    _, narrow = fit_view(cube, [0, 0, 1], [0, 1, 0], view_angle=90.0, aspect=0.5, fill=1.0)
    assert np.allclose(wide, [0.0, 0.0, 2.0], atol=1e-9) and np.allclose(narrow, [0.0, 0.0, 3.0], atol=1e-9)


def test_box_corners():
    corners = box_corners([0.0, 5.0, 1.0], [2.0, 9.0, 3.0], -0.5, 1.8)
    assert corners.shape == (8, 3)
    assert {tuple(c) for c in corners} == {(x, y, z) for x in (0.0, 2.0) for y in (-0.5, 1.8) for z in (1.0, 3.0)}


def test_overlay_cells_close_the_outline_and_fan_the_inside():
    lines, faces = overlay_cells(4, closed=True, fill=True)
    assert lines.tolist() == [5, 0, 1, 2, 3, 0]
    assert faces is not None and faces.tolist() == [3, 0, 1, 2, 3, 0, 2, 3]
    lines, faces = overlay_cells(4, closed=False, fill=False)
    assert lines.tolist() == [4, 0, 1, 2, 3] and faces is None
    lines, faces = overlay_cells(2, closed=True, fill=True)
    assert lines.tolist() == [2, 0, 1] and faces is None, "two points: a segment, nothing to close or fill"


def test_ground_grid_covers_the_box_with_a_metre_of_margin_in_half_metre_squares():
    lo, hi = np.array([0.2, 0.0, 0.3]), np.array([1.4, 2.0, 0.9])
    xs, zs, extent = ground_grid(lo, hi)
    assert extent == (-1.0, 3.0, -1.0, 2.0)  # floor(0.2 - 1), ceil(1.4 + 1), floor(0.3 - 1), ceil(0.9 + 1)
    assert np.allclose(xs, np.arange(-1.0, 3.01, 0.5)) and np.allclose(zs, np.arange(-1.0, 2.01, 0.5))
    assert ground_grid(lo, hi, extent) is None, "a grid that covers the box stays"
    grown = ground_grid(lo, hi + [2.0, 0.0, 0.0], extent)
    assert grown is not None and grown[2] == (-1.0, 5.0, -1.0, 2.0)


@pytest.mark.filterwarnings("ignore:The motion path follows joint")
def test_character_geometry_leaves_out_a_static_joint_above_the_pelvis(cmu):
    pytest.importorskip("test_editing_conventions")
    from test_editing_conventions import static_root

    walk = cmu("16_15")[:20]
    pos, segs, path_joint = character_geometry(walk)
    n_ends = len(walk.skeleton.end_site_parents)
    assert pos.shape == (20, walk.n_joints + n_ends, 3) and path_joint == walk.path_joint == 0
    assert np.allclose(pos[:, : walk.n_joints], walk.global_positions())
    assert np.allclose(pos[:, walk.n_joints :], walk.end_site_positions())
    assert len(segs) == walk.n_joints - 1 + n_ends, "one bone per joint but the root, one per end site"
    lengths = np.linalg.norm(pos[:, segs[:, 0]] - pos[:, segs[:, 1]], axis=-1)
    assert np.allclose(lengths, lengths[0]), "bones keep their lengths over the clip"
    pos2, segs2, path_joint2 = character_geometry(static_root(walk))
    assert np.allclose(pos2, pos) and np.array_equal(segs2, segs) and path_joint2 == 0
    _, segs3, _ = character_geometry(walk, end_sites=False)
    assert len(segs3) == walk.n_joints - 1
