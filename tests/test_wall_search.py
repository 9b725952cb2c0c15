"""The wall search (nbs_env.planning.wall_search) and its place in the storey loop."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
from shapely.geometry import Polygon

from nbs_env.config import RoomRules, make_config
from nbs_env.env import NBSEnv
from nbs_env.errors import ConfigError
from nbs_env.perception.roi import RoI
from nbs_env.planning.wall_search import WallSearchConfig, approach_position, search_position, unviewed_wall

# A corridor 20 m by 2 m, floor at 0: from its middle the far ends of the long walls are seen at
# grazing incidence (a point 9 m along, 1 m across: 84° off the normal).
CORRIDOR = np.array([[0.0, 0.0], [20.0, 0.0], [20.0, 2.0], [0.0, 2.0]])


def corridor() -> RoI:
    return RoI(CORRIDOR, 0.0, 3.0, np.zeros((1, 1), dtype=bool), np.zeros(2))


def open_space(sensors: np.ndarray, targets: np.ndarray) -> np.ndarray:
    """Every line of sight is clear."""
    return np.ones((len(sensors), len(targets)), dtype=bool)


def incidence_deg(stop: np.ndarray, walls) -> np.ndarray:
    """(m,) the smallest angle off the face normal at which ``stop`` sees each column."""
    h = len(WallSearchConfig().heights)
    ray = stop[None, :] - walls.points
    cos = np.einsum("nk,nk->n", ray[:, :2], np.repeat(walls.normals, h, axis=0)) / np.linalg.norm(ray, axis=1)
    return np.degrees(np.arccos(np.clip(cos, -1, 1))).reshape(-1, h).min(axis=1)


def test_columns_seen_at_grazing_incidence_are_targets_and_the_rest_are_not():
    stop = np.array([10.0, 1.0, 1.5])
    walls = unviewed_wall(corridor(), [stop], open_space)
    config = WallSearchConfig()
    angle = incidence_deg(stop, walls)
    dist = np.linalg.norm(stop[None, :] - walls.points, axis=1).reshape(walls.columns, -1).min(axis=1)
    viewed = (angle <= config.incidence_deg) & (dist <= config.max_range)
    # Stretches of >= 0.75 m not viewed are targets; every viewed column is not.
    assert walls.target.any() and not (walls.target & viewed).any()
    long_walls = np.isin(walls.face, (0, 2))
    assert (walls.target[long_walls] == ~viewed[long_walls]).all()
    # The samples lie inside the room, 0.15 m in front of their face, at 1.0 and 1.8 m.
    assert set(np.round(walls.points[:, 2], 6)) == {1.0, 1.8}
    assert (walls.points[:, 1] > 0.1).all() and (walls.points[:, 1] < 1.9).all()


def test_stops_along_the_corridor_view_what_the_first_left():
    first = np.array([2.0, 1.0, 1.5])
    walls = unviewed_wall(corridor(), [first], open_space)
    assert walls.target[walls.points[::2, 0] > 6].all()  # all but the west end
    # 0.85 m from a long wall, a stop views 2.6 m of it either way within 72°: every 4 m is enough.
    stops = [np.array([x, 1.0, 1.5]) for x in (2.0, 6.0, 10.0, 14.0, 18.0)]
    assert not unviewed_wall(corridor(), stops, open_space).target.any()
    # One stop fewer leaves a stretch.
    assert unviewed_wall(corridor(), stops[:2] + stops[3:], open_space).target.any()


def test_the_search_picks_the_candidate_that_views_most_targets_ties_to_the_shorter_path():
    walls = unviewed_wall(corridor(), [np.array([3.0, 1.0, 1.5])], open_space)
    # From 17 m a stop views 5.2 m of each long wall's target stretch, from 19.2 m 3.4 m (the wall
    # ends); slots 1 and 3 stand at the same place: the shorter path (3) wins.
    sensors = np.array([[2.0, 1.0, 1.5], [17.0, 1.0, 1.5], [19.2, 1.0, 1.5], [17.0, 1.0, 1.5]])
    path = np.array([1.0, 14.0, 10.0, 12.0])
    assert search_position(walls, sensors, path, open_space) == 3
    # A candidate that views nothing new is no search position.
    assert search_position(walls, sensors[:1], path[:1], open_space) is None


def test_an_occluded_stretch_is_a_target_and_a_room_behind_it_is_not():
    def wall_at_12(sensors, targets):
        # A partition at x = 12 blocks every line that crosses it.
        return (sensors[:, None, 0] < 12) == (targets[None, :, 0] < 12)

    stops = [np.array([6.0, 1.0, 1.5]), np.array([8.0, 1.0, 1.5])]
    walls = unviewed_wall(corridor(), stops, wall_at_12)
    assert walls.target[walls.points[::2, 0] > 14].all()
    # The far end's wall (x = 20) has a scanned room behind it: those columns need no view.
    scanned = [Polygon([(20.2, -1), (25, -1), (25, 3), (20.2, 3)])]
    walls = unviewed_wall(corridor(), stops, wall_at_12, scanned)
    east = walls.face == 1
    assert np.isnan(walls.points[np.repeat(east, 2), 0]).all() and not walls.target[east].any()
    assert walls.target[~east & (np.nan_to_num(walls.points[::2, 0]) > 14)].all()


def test_when_no_candidate_views_the_targets_the_search_approaches_them():
    def west_of_12(sensors, targets):
        # Nothing east of x = 12 is in view (floor there never measured, say) from anywhere.
        return np.broadcast_to(targets[None, :, 0] < 12, (len(sensors), len(targets)))

    stops = np.array([[2.0, 1.0, 1.5], [6.0, 1.0, 1.5], [10.0, 1.0, 1.5]])
    walls = unviewed_wall(corridor(), stops, west_of_12)
    assert walls.target[walls.points[::2, 0] > 12].all() and not walls.target[walls.points[::2, 0] < 12].any()
    sensors = np.array([[3.0, 1.0, 1.5], [11.8, 1.0, 1.5], [9.0, 1.0, 1.5], [11.8, 1.0, 1.5]])
    path = np.array([5.0, 4.0, 2.0, 3.0])
    assert search_position(walls, sensors, path, west_of_12) is None
    # The nearest (x = 11.8, 0.91 m from the first target column against the last stop's 2.29 m)
    # wins, the shorter path of the two there.
    assert approach_position(walls, sensors, path, stops) == 3
    # Not nearer than the stops by the margin, or the margin off, or nothing to approach: none.
    assert approach_position(walls, sensors, path, stops, WallSearchConfig(approach=1.5)) is None
    assert approach_position(walls, sensors[[0]], path[[0]], stops) is None
    assert approach_position(walls, sensors, path, stops, WallSearchConfig(approach=0.0)) is None
    viewed = unviewed_wall(corridor(), [np.array([x, 1.0, 1.5]) for x in (2.0, 6.0, 10.0, 14.0, 18.0)], open_space)
    assert approach_position(viewed, sensors, path, stops) is None


def test_no_stop_no_target_and_short_faces_are_skipped():
    walls = unviewed_wall(corridor(), [np.array([10.0, 1.0, 1.5])], open_space, min_face=2.5)
    assert set(walls.face.tolist()) == {0, 2}  # the 2 m end walls are shorter than 2.5 m
    assert search_position(walls, np.zeros((0, 3)), np.zeros(0), open_space) is None


@pytest.mark.parametrize(
    "field, value",
    [
        ("step", 0.0),
        ("incidence_deg", 90.0),
        ("max_range", -1.0),
        ("heights", ()),
        ("heights", (1.0, float("nan"))),
        ("approach", -0.5),
        ("narrow", 1),
        ("doors", "yes"),
    ],
)
def test_bad_wall_search_config_raises(field, value):
    with pytest.raises(ConfigError, match=field):
        WallSearchConfig(**{field: value})


def test_the_search_is_on_by_default_and_off_at_the_paper_preset():
    assert RoomRules().wall_search.scans == 3 and make_config("fast").rooms.wall_search.scans == 3
    assert make_config("paper").rooms.wall_search.scans == 0
    # The same hardware and stages; the paper's NVPs lie on the lattice alone, and its scanner casts thin rays.
    paper, default = make_config("paper").robot, make_config("default").robot
    assert not paper.navigation.snap and default.navigation.snap
    assert paper.scanner.beam_divergence == 0.0 < default.scanner.beam_divergence
    thin = replace(default.scanner, beam_divergence=0.0)
    assert paper == replace(default, navigation=replace(default.navigation, snap=False), scanner=thin)
    with pytest.raises(ConfigError, match="scans"):
        WallSearchConfig(scans=-1)


def test_room_done_takes_one_search_scan_which_can_reopen_the_room():
    # After its first scan the L-shaped room's far arm was never faced: "room done" takes the
    # search scan, the gain rule finds the room goes on, and the agent keeps it; a second
    # declaration ends it (one search a room).
    env = NBSEnv(
        make_config("fast", scene="l_room", completion="policy", expose_belief=True, **{"rooms.wall_search.scans": 1})
    )
    _, info = env.reset(seed=0)
    _, _, terminated, _, info = env.step(env.stop_action)
    storey = env.storey
    assert not terminated and info["scans"] == 2 and storey.wall_searches == [{"scan": 1, "room": 0, "kind": "view"}]
    assert storey.room_ends == [] and info["action_mask"][env.stop_action]
    _, _, terminated, _, info = env.step(env.stop_action)
    assert terminated and info["scans"] == 2
    assert [{k: e[k] for k in ("room", "scans", "reason")} for e in storey.room_ends] == [
        {"room": 0, "scans": 2, "reason": "declared"}
    ]
    assert storey.room_ends[0]["roi_m2"] > 30.0  # the L's floor


def l_room_with_safety(safety: float, narrow: bool) -> NBSEnv:
    return NBSEnv(
        "fast",
        scene="l_room",
        completion="policy",
        safety_distance=safety,
        **{"rooms.wall_search.scans": 3, "rooms.wall_search.narrow": narrow},
    )


def test_a_gap_the_safety_distance_closes_leads_the_search_to_the_wall_keeping_the_radius_clear():
    # With a 1 m safety distance the NVPs keep 1.25 m from every obstacle, which closes the way
    # into the L-shaped room's far arm. Once the one NVP that views unviewed wall has been used,
    # the search stands where only the robot's radius is kept clear ("narrow"): not an NVP, and
    # its scan adds coverage that the search without it leaves.
    covered = {}
    for narrow in (True, False):
        env = l_room_with_safety(1.0, narrow)
        env.reset(seed=0)
        robot, rooms = env.storey.robot, env.storey.rooms
        env.step(env.stop_action)  # the first search: an NVP views the wall
        nvps = robot.plan().candidates.points.copy()
        stop = rooms.wall_search(robot)
        if not narrow:
            assert stop is None
        else:
            assert stop is not None and stop.kind == "narrow" and stop.nvp is None
            assert np.allclose(stop.path[-1], stop.point) and np.allclose(stop.path[0], robot.pose[:2, 3])
            assert stop.length >= np.linalg.norm(stop.point - robot.pose[:2, 3]) - 1e-6
            assert not len(nvps) or np.linalg.norm(nvps - stop.point, axis=1).min() > 0.1
            tmap, _ = rooms.door_routes(robot)
            clearance = float(tmap.clearance_at(stop.point[None])[0])
            nav = robot.config.navigation
            assert nav.robot_radius - 1e-9 <= clearance < nav.robot_radius + nav.safety_distance
        terminated = False
        while not terminated:
            _, _, terminated, truncated, _ = env.step(env.stop_action)
            terminated = terminated or truncated
        kinds = [search["kind"] for search in env.storey.wall_searches]
        assert ("narrow" in kinds) == narrow
        covered[narrow] = env.storey.coverage_pct()
    assert covered[True] > covered[False] + 5.0


def test_rays_through_an_opening_fall_with_range_and_incidence_and_vanish_behind_the_wall():
    from nbs_env.config import ScannerConfig
    from nbs_env.planning.wall_search import opening_rays

    scanner = ScannerConfig(angular_step=1.0)
    point, normal = np.array([[0.0, 0.0, 1.0]]), np.array([[0.0, 1.0]])

    def rays(distance, angle_deg, thickness=0.2, step=1.0):
        a = np.radians(angle_deg)
        sensor = np.array([[distance * np.sin(a), distance * np.cos(a), 1.5]])
        config = replace(scanner, angular_step=step)
        return float(opening_rays(sensor, point, normal, 0.0, config, 0.8, 2.0, thickness)[0, 0])

    assert rays(3, 0) > rays(6, 0) > rays(9, 0) > 0
    assert rays(4, 0) > rays(4, 45) > rays(4, 70) > 0
    # The far jamb of a 0.2 m wall hides a 0.8 m opening seen at 76° or more; none from behind.
    assert rays(4, 80) == 0 and rays(4, 80, thickness=0.0) > 0 and rays(-4, 0) == 0
    # Half the angular step, four times the rays.
    assert rays(5, 30, step=0.5) == pytest.approx(4 * rays(5, 30))


def test_min_rays_leaves_far_frontal_walls_unviewed():
    from nbs_env.config import ScannerConfig

    scanner = ScannerConfig(angular_step=1.0)
    roi = RoI(
        np.array([[0.0, 0.0], [6.0, 0.0], [6.0, 10.5], [0.0, 10.5]]), 0.0, 3.0, np.zeros((1, 1), bool), np.zeros(2)
    )
    stop = [np.array([3.0, 2.0, 1.5])]
    plain = unviewed_wall(roi, stop, open_space, scanner=scanner)
    strict = unviewed_wall(roi, stop, open_space, config=WallSearchConfig(min_rays=100), scanner=scanner)
    north = np.flatnonzero(plain.face == 2)  # the wall at y = 10.5, 8.5 m in front of the stop
    assert not plain.target[north].any() and strict.target[north].all()
    assert not strict.target[plain.face == 0].any()  # the wall 2 m behind the stop stays viewed


def test_a_stop_under_the_lintel_does_not_view_the_wall_above_it():
    # Door detection needs the lintel measured: 0.3 m in front of the wall the top of a 2 m opening
    # lies within the scanner's 1.5 m minimum range, so the columns in front of the stop stay
    # unviewed; a stop 3 m back views them.
    from nbs_env.config import ScannerConfig

    scanner = ScannerConfig(angular_step=1.0)
    roi = RoI(np.array([[0.0, 0.0], [6.0, 0.0], [6.0, 6.0], [0.0, 6.0]]), 0.0, 3.0, np.zeros((1, 1), bool), np.zeros(2))
    close = unviewed_wall(roi, [np.array([3.0, 0.45, 1.5])], open_space, scanner=scanner)
    south = close.face == 0
    in_front = south & (np.abs(close.points[::2, 0] - 3.0) < 0.4)
    assert close.target[in_front].all()
    assert not unviewed_wall(roi, [np.array([3.0, 0.45, 1.5])], open_space).target[in_front].any()
    back = unviewed_wall(roi, [np.array([3.0, 3.0, 1.5])], open_space, scanner=scanner)
    assert not back.target[in_front].any()


def test_a_door_no_route_reaches_gets_a_scan_toward_it_before_it_is_given_up():
    # generated:10000006, every room declared done at once (one search scan a room): the door of
    # the L-shaped room's far arm is found from its other end, behind two tables whose shadow
    # left the floor before it unmeasured. Without the door search it is given up ("cut off") and
    # the room behind it is never scanned; with it, a scan from nearer measures the way.
    results = {}
    for doors in (True, False):
        env = NBSEnv(
            "fast",
            scene="generated:10000006",
            completion="policy",
            **{"rooms.wall_search": WallSearchConfig(scans=1, doors=doors)},
        )
        env.reset(seed=0)
        terminated = False
        while not terminated:
            _, _, terminated, truncated, _ = env.step(env.stop_action)
            terminated = terminated or truncated
        storey = env.storey
        kinds = [search["kind"] for search in storey.wall_searches]
        abandoned = [event for event in storey.door_events if event["event"] == "abandoned"]
        results[doors] = (kinds, abandoned, storey.coverage_pct(), storey.rooms_done)
    kinds, abandoned, pct, rooms = results[True]
    assert "door" in kinds and not abandoned
    kinds_off, abandoned_off, pct_off, rooms_off = results[False]
    assert "door" not in kinds_off and any("cut off" in event["reason"] for event in abandoned_off)
    assert rooms > rooms_off and pct > pct_off + 5.0
