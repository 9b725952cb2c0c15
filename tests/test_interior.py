"""Inside from outside by geometry (scenes.interior): the surface the evaluation counts and the rooms
it derives never depend on a file's room annotations."""

from __future__ import annotations

import re

import numpy as np
import pytest
from shapely.geometry import Polygon

from nbs_env.config import make_config
from nbs_env.env import NBSEnv
from policies import make_policy
from scenes import SurfaceClass, load_scene
from scenes.importers import export_scene
from scenes.interior import VIEW_HEIGHTS, derive_rooms, free_positions, interior_mask, interior_samples
from scenes.model import Scene
from tests.helpers import boxed_storey
from train.episode import run_episode


@pytest.mark.parametrize("name", ["five_rooms", "office", "l_room"])
def test_plan_built_storeys_count_exactly_their_room_faces(name):
    # The extruder builds only the inner faces, each with its room: geometry must agree with it.
    scene = load_scene(name)
    every = scene.structure_samples(0.1)
    inside = interior_mask(scene, every.points, scene.mesh.face_normals[every.faces])
    assert np.array_equal(inside, every.rooms >= 0)


def test_outside_faces_and_a_terrace_do_not_count():
    outline = [((0, 0), (5, 0)), ((5, 0), (5, 4)), ((5, 4), (0, 4)), ((0, 4), (0, 0))]
    walls = [(a, b, [(2.0, 3.0, 2.05)] if k == 0 else []) for k, (a, b) in enumerate(outline)]
    building, terrace = (-0.1, -0.1, 5.1, 4.1), (1.0, -3.0, 4.0, -0.1)
    scene = boxed_storey(walls, [building, terrace], [building], start=(2.5, 2.0))
    samples = interior_samples(scene, 0.05)
    every = scene.structure_samples(0.05)
    assert 0 < len(samples) < len(every)
    p = samples.points
    # Nothing counted lies outside the walls' inner faces, above the ceiling or below the floor...
    assert p[:, 0].min() > -0.02 and p[:, 0].max() < 5.02 and p[:, 1].min() > -0.25 and p[:, 1].max() < 4.02
    assert p[:, 2].min() > -0.01 and p[:, 2].max() < 2.61
    # ...and every inner face counts: floor and ceiling of the 4.8 x 3.8 m clear inside, the walls'
    # inner faces less the door's opening; of its reveal (two jambs, the soffit and the floor under
    # it, 1.22 m²) the outer part, open to the outside on three sides, may not.
    inner_area = 2 * 4.8 * 3.8 + 2.6 * 2 * (4.8 + 3.8) - 1.0 * 2.05
    assert inner_area * 0.99 < len(samples) * 0.05**2 < (inner_area + 2 * 0.2 * 2.05 + 0.2 + 0.2) * 1.01
    labels = samples.labels[p[:, 1] < 0]  # what counts beyond the south wall's inner face: the opening
    assert set(np.unique(labels)) <= {SurfaceClass.FLOOR, SurfaceClass.WALL}


def test_a_roofed_porch_does_not_count_and_a_raised_level_does():
    """A door onto a porch under a roof on no walls: the porch's floor, its roof's underside and the
    facade under it are open to the sides and do not count (nor does a place on it look). A
    platform 0.5 m up in the room (a split level) is the storey's free space: places stand on it."""
    import trimesh

    outline = [((0, 0), (5, 0)), ((5, 0), (5, 4)), ((5, 4), (0, 4)), ((0, 4), (0, 0))]
    walls = [(a, b, [(2.0, 3.0, 2.05)] if k == 0 else []) for k, (a, b) in enumerate(outline)]
    building, porch = (-0.1, -0.1, 5.1, 4.1), (0.5, -3.0, 4.5, -0.1)
    scene = boxed_storey(walls, [building, porch], [building, porch], start=(2.5, 2.0))
    p = interior_samples(scene, 0.05).points
    assert p[:, 1].min() > -0.25, "the porch counts"
    # The room's inner faces count as they do with no porch.
    inner_area = 2 * 4.8 * 3.8 + 2.6 * 2 * (4.8 + 3.8) - 1.0 * 2.05
    assert inner_area * 0.99 < len(p) * 0.05**2 < (inner_area + 2 * 0.2 * 2.05 + 0.2 + 0.2) * 1.01
    assert free_positions(scene)[:, 1].min() > 0.0

    platform = trimesh.creation.box(extents=(1.9, 3.8, 0.5))
    platform.apply_translation([4.0, 2.0, 0.25])
    raised = Scene(
        trimesh.util.concatenate([scene.mesh, platform]),
        np.concatenate([scene.face_labels, np.full(len(platform.faces), SurfaceClass.FLOOR)]),
        start=(1.5, 2.0),
    )
    places = free_positions(raised)
    up = places[places[:, 0] > 3.3]
    assert len(up) and np.all(np.isin(np.round(up[:, 2] - 0.5, 2), VIEW_HEIGHTS)), np.unique(up[:, 2])


def test_derived_rooms_follow_the_walls():
    scene = load_scene("five_rooms")
    derived = derive_rooms(scene)
    assert len(derived) == len(scene.rooms)
    for room in scene.rooms:
        truth = Polygon(room.polygon)
        best = max(derived, key=lambda d: Polygon(d.polygon).intersection(truth).area)
        iou = Polygon(best.polygon).intersection(truth).area / Polygon(best.polygon).union(truth).area
        assert iou > 0.95, room.name


@pytest.mark.expensive
def test_a_mesh_with_and_without_room_names_reports_the_same_coverage(tmp_path):
    named = tmp_path / "named.obj"
    export_scene(load_scene("office"), named)
    bare = tmp_path / "bare.obj"
    bare.write_text(re.sub(r"_room\d+", "", named.read_text()))
    a, b = load_scene(str(named)), load_scene(str(bare))
    assert a.metadata["rooms"] == "file" and b.metadata["rooms"] == "derived"
    assert len(b.rooms) == len(a.rooms)
    start = tuple(a.start[:2])
    coverage = []
    for scene in (a, b):
        env = NBSEnv(make_config("fast", max_scans=6))
        run_episode(env, make_policy("greedy", 0), seed=0, options={"scene": scene, "start": start})
        coverage.append([s.structure_sensed_pct for s in env.storey.scans])
    assert coverage[0] == coverage[1] and coverage[0][-1] > 20


def test_the_probe_test_casts_backward_rays_only_where_they_can_tell_a_wall():
    """The probe test skips the backward ray where the forward hit alone is too far off for a
    wall's thickness; the plain test, both rays for every probe, keeps the same probes. FZK-Haus's
    IFC walls are solids a probe may stand inside and still see the floor below: some probes are
    told from the rooms by the horizontal rays alone."""
    from scenes import interior

    def plain(caster, q, horizontal=True):
        t_down, below, _ = caster.cast(q, np.array([0.0, 0.0, -1.0]))
        ok = (below == SurfaceClass.FLOOR) & (t_down <= interior.MAX_DROP)
        ok &= np.abs(q[:, 2] - np.where(ok, t_down, 0.0) - caster.floor_z) <= interior.LEVEL_SPAN + interior.FLOOR_BAND
        up = np.array([0.0, 0.0, 1.0])
        t_up, _, _ = caster.cast(q, up)
        t_floor, _, _ = caster.cast(q, up, floors_only=True)
        ok &= ~(np.isfinite(t_floor) & (t_floor <= t_up + 1e-3)) & (np.isfinite(t_up) if caster.has_ceiling else True)
        todo = np.flatnonzero(ok)
        for d in interior._HORIZONTAL if horizontal else ():
            t_f, _, n_f = caster.cast(q[todo], d)
            t_b, _, n_b = caster.cast(q[todo], -d)
            both = np.isfinite(t_f) & np.isfinite(t_b)
            upright = (np.abs(n_f[:, 2]) < 0.3) & (np.abs(n_b[:, 2]) < 0.3)
            parallel = np.abs(np.einsum("ij,ij->i", n_f, n_b)) > 0.95
            span = np.where(both, t_f + t_b, 0.0)
            gap = np.where(both, np.abs(span * (n_f[:, :2] @ d[:2])), np.inf)
            enclosed = both & upright & parallel & (gap < interior.MIN_SPAN)
            ok[todo[enclosed]] = False
            todo = todo[~enclosed]
        if caster.has_ceiling:
            ok[todo] &= caster.escapes(q[todo]) <= interior.MAX_ESCAPES
        return ok

    scene = load_scene("corpus:fzk_haus_eg")
    lo, hi = scene.mesh.bounds
    q = np.random.default_rng(0).uniform([lo[0], lo[1], lo[2] + 0.3], [hi[0], hi[1], lo[2] + 2.0], size=(50_000, 3))
    caster = interior._Caster(scene)
    want = plain(caster, q)
    assert 0 < want.sum() < plain(caster, q, horizontal=False).sum()  # the horizontal rays reject some
    assert np.array_equal(interior._probe_is_inside(caster, q), want)


def _with_suspended_ceiling(scene, height: float, thickness: float):
    """``scene`` with a covering of ``thickness`` metres hung at ``height`` over its whole floor."""
    import trimesh

    from scenes import Scene

    lo, hi = scene.bounds
    plate = trimesh.creation.box(extents=(hi[0] - lo[0] - 0.4, hi[1] - lo[1] - 0.4, thickness))
    plate.apply_translation([(lo[0] + hi[0]) / 2, (lo[1] + hi[1]) / 2, height + thickness / 2])
    mesh = trimesh.util.concatenate([scene.mesh, plate])
    labels = np.concatenate([scene.face_labels, np.full(len(plate.faces), SurfaceClass.CEILING.value)])
    return Scene(mesh, labels, start=tuple(scene.start[:2]), name="suspended")


@pytest.mark.parametrize("thickness", [0.012, 0.05])
def test_the_top_of_a_suspended_ceiling_and_the_plenum_do_not_count(thickness):
    """A covering hung 0.4 m under the slab (as Revit's IfcCovering): what a scan inside can see is
    the covering's underside, not its top, the plenum's walls or the slab's underside above it, even
    where the covering is thinner than the interior probe."""
    outline = [((0, 0), (5, 0)), ((5, 0), (5, 4)), ((5, 4), (0, 4)), ((0, 4), (0, 0))]
    box = (-0.1, -0.1, 5.1, 4.1)
    bare = boxed_storey([(a, b, []) for a, b in outline], [box], [box], start=(2.5, 2.0))
    scene = _with_suspended_ceiling(bare, 2.2, thickness)
    samples = interior_samples(scene, 0.05)
    p = samples.points
    assert p[:, 2].max() < 2.2 + 1e-6, "something above the covering's underside counts"
    # The floor, the covering's underside and the walls up to it: 4.8 x 3.8 m clear inside.
    inner_area = 2 * 4.8 * 3.8 + 2.2 * 2 * (4.8 + 3.8)
    assert len(samples) * 0.05**2 == pytest.approx(inner_area, rel=0.01)


def test_structure_no_free_place_sees_does_not_count():
    """A wardrobe flush against a wall and a low chest on the floor: the floor under both and the
    wall behind the wardrobe are seen from nowhere in the room and leave the denominator; the wall
    above the chest and the floor beside it stay."""
    outline = [((0, 0), (5, 0)), ((5, 0), (5, 4)), ((5, 4), (0, 4)), ((0, 4), (0, 0))]
    box = (-0.1, -0.1, 5.1, 4.1)
    wardrobe = (0.1, 1.0, 0.7, 2.5, 2.2)  # against the west wall's inner face (x = 0.1)
    chest = (3.0, 1.5, 4.0, 2.5, 0.6)
    scene = boxed_storey([(a, b, []) for a, b in outline], [box], [box], clutter=[wardrobe, chest], start=(2.0, 3.2))
    p = interior_samples(scene, 0.05).points

    def under(x0, y0, x1, y1):
        return (p[:, 0] > x0 + 0.02) & (p[:, 0] < x1 - 0.02) & (p[:, 1] > y0 + 0.02) & (p[:, 1] < y1 - 0.02)

    floor = np.abs(p[:, 2]) < 0.01
    assert not np.any(floor & under(0.1, 1.0, 0.7, 2.5)) and not np.any(floor & under(3.0, 1.5, 4.0, 2.5))
    behind = (np.abs(p[:, 0] - 0.1) < 0.01) & (p[:, 1] > 1.05) & (p[:, 1] < 2.45) & (p[:, 2] < 2.15)
    assert not np.any(behind)
    above_wardrobe = (np.abs(p[:, 0] - 0.1) < 0.01) & (p[:, 1] > 1.05) & (p[:, 1] < 2.45) & (p[:, 2] > 2.25)
    # 2.25-2.6 m stays, less a grazing strip over the wardrobe's front edge (the farthest places
    # stand 4 m off, 0.25 m clear of the east wall, at 1.8 m: they see over the edge from ~2.27 m).
    assert 1.5 * 0.25 <= above_wardrobe.sum() * 0.05**2 <= 1.5 * 0.36
    assert np.sum(floor & under(3.0, 0.3, 4.0, 1.4)) * 0.05**2 == pytest.approx(1.1, rel=0.1)  # beside the chest


def test_the_same_cloud_gives_the_same_coverage_at_every_preset():
    """Coverage is a property of the evaluation: the meters of the fast and the default preset give
    one cloud the same figure."""
    from nbs_env.evaluation import CoverageMeter

    scene = load_scene("l_room")
    env = NBSEnv(make_config("fast", scene="l_room"))
    env.reset(seed=0)
    cloud = np.concatenate([points for points, _ in env.storey.step_scans])
    figures = []
    for preset in ("fast", "default", "paper"):
        config = make_config(preset)
        meter = CoverageMeter(scene, config.coverage_spacing, config.coverage_radius)
        meter.add(cloud)
        figures.append(meter.percent())
    assert 20.0 < figures[0] < 100.0 and max(figures) - min(figures) < 1.0


def test_the_project_and_an_independent_count_agree_on_a_run():
    """A storey with a suspended ceiling and furniture: the coverage the project prints and the
    count of :mod:`tests.independent_coverage` (its own samples, free positions and visibility, none
    of the project's code) agree within 2 points after a short greedy run."""
    from tests.independent_coverage import count

    outline = [((0, 0), (6, 0)), ((6, 0), (6, 4)), ((6, 4), (0, 4)), ((0, 4), (0, 0))]
    box = (-0.1, -0.1, 6.1, 4.1)
    bare = boxed_storey(
        [(a, b, []) for a, b in outline], [box], [box], clutter=[(0.1, 1.0, 0.7, 2.5, 2.0), (3.0, 1.5, 4.0, 2.5, 0.6)]
    )
    scene = _with_suspended_ceiling(bare, 2.3, 0.02)
    env = NBSEnv(make_config("fast", max_scans=3))
    env.reset(seed=0, options={"scene": scene})
    clouds = [points for points, _ in env.storey.step_scans]
    while env.storey.open:
        env.step(env.storey.plan.best())
        clouds += [points for points, _ in env.storey.step_scans]
    ours = env.storey.meter.percent()
    theirs = count(scene.mesh.vertices, scene.mesh.faces, scene.face_labels, np.concatenate(clouds))
    # The two agree on what counts: the floor, the covering's underside and the walls below it, less
    # what the furniture hides (the independent samples are random: 2% apart).
    assert theirs.visible * 0.05**2 == pytest.approx(len(env.storey.meter.samples) * 0.05**2, rel=0.02)
    assert 50.0 < ours < 100.0 and abs(ours - theirs.percent) < 2.0, (ours, theirs.percent)
