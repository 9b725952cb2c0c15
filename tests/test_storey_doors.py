"""Door hand-over on storeys built directly with trimesh (not by our floor-plan extruder): a door
whose point straight in front is blocked is still crossed; an exterior door is recorded, not crossed."""

from __future__ import annotations

import numpy as np
import pytest

from nbs_env.config import make_config
from nbs_env.env import NBSEnv
from policies import make_policy
from tests.helpers import boxed_storey
from train.episode import run_episode

OUTLINE = [((0, 0), (9, 0)), ((9, 0), (9, 4)), ((9, 4), (0, 4)), ((0, 4), (0, 0))]
#: The door between room A (x < 5) and room B, 0.9 m wide, 2.0 m high, centred at (5, 2).
PARTITION = ((5, 0), (5, 4), [(1.55, 2.45, 2.0)])
BUILDING = (-0.1, -0.1, 9.1, 4.1)


def _episode(scene) -> NBSEnv:
    env = NBSEnv(make_config("fast", max_scans=40))
    run_episode(env, make_policy("greedy", 0), seed=0, options={"scene": scene})
    return env


def _events(env: NBSEnv, kind: str) -> list[dict]:
    return [e for e in env.storey.door_events if e["event"] == kind]


def test_a_door_whose_point_in_front_is_blocked_is_still_crossed():
    # A box 0.65 m in front of the door's face: the point 0.5 m in front of the frame has 0.15 m of
    # clearance, less than the robot's radius; the strip between box and wall is free.
    box = (4.25 - 0.3, 1.8, 4.25, 2.2, 1.0)
    walls = [(a, b, []) for a, b in OUTLINE] + [PARTITION]
    scene = boxed_storey(walls, [BUILDING], [BUILDING], clutter=[box], start=(1.5, 2.0), name="blocked")
    env = _episode(scene)
    crossed = _events(env, "crossed")
    assert any(np.linalg.norm(np.subtract(e["centre"], (4.9, 2.0))) < 0.3 for e in crossed), env.storey.door_events
    assert not _events(env, "abandoned"), env.storey.door_events
    # Room B was scanned: some scan stands at x > 5.2.
    assert any(s.true_position[0] > 5.2 for s in env.storey.scans)


@pytest.mark.parametrize("roofed", [False, True], ids=["terrace", "carport"])
def test_an_exterior_door_is_recorded_and_not_crossed(roofed):
    # Room A has a 1.0 m door in its south wall onto a terrace: floor outside and no ceiling over
    # it; or onto a carport, a roof 7 m deep and 7 m wide on no walls, from which most rising rays
    # through the door return: the level ones leave under its edge.
    south = ((0, 0), (9, 0), [(2.0, 3.0, 2.05)])
    walls = [south, *[(a, b, []) for a, b in OUTLINE[1:]], PARTITION]
    outside = (-1.0, -7.1, 6.0, -0.1) if roofed else (1.0, -3.5, 4.0, -0.1)
    ceilings = [BUILDING, outside] if roofed else [BUILDING]
    scene = boxed_storey(walls, [BUILDING, outside], ceilings, start=(1.5, 2.0), name="exterior")
    env = _episode(scene)
    detected = _events(env, "detected")
    outside = [e for e in detected if abs(e["centre"][1]) < 0.4 and 1.8 < e["centre"][0] < 3.2]
    assert outside and all(e["exterior"] for e in outside), detected
    inside = [e for e in detected if abs(e["centre"][0] - 4.9) < 0.4]
    assert inside and not any(e["exterior"] for e in inside), detected
    # The interior door is crossed, the exterior one never; no scan is taken outside the building.
    crossed = [tuple(e["centre"]) for e in _events(env, "crossed")]
    assert any(abs(c[0] - 4.9) < 0.4 for c in crossed) and not any(c[1] < 0.4 for c in crossed), crossed
    assert all(s.true_position[1] > 0.1 for s in env.storey.scans)


def test_a_door_with_no_room_measured_beyond_it_is_given_up_and_the_storey_goes_on(monkeypatch):
    """A door-frame scan whose RoI has nothing to stand on (RoIError: no floor or ceiling beyond the
    frame) once ended the episode with an exception; the door is abandoned with its reason and the
    storey session finishes its run."""
    import nbs_env.belief as belief_module
    from nbs_env.perception.roi import RoIError

    original = belief_module.compute_roi

    def no_room_behind_doors(scans, *args, **kwargs):
        if len(scans) == 1 and scans[0].keep_direction is not None:  # a door-frame scan
            raise RoIError("the top projection is empty")
        return original(scans, *args, **kwargs)

    monkeypatch.setattr(belief_module, "compute_roi", no_room_behind_doors)
    walls = [(a, b, []) for a, b in OUTLINE] + [PARTITION]
    scene = boxed_storey(walls, [BUILDING], [BUILDING], start=(1.5, 2.0), name="no room behind")
    env = _episode(scene)
    abandoned = _events(env, "abandoned")
    assert abandoned and "no room measured beyond it" in abandoned[0]["reason"], env.storey.door_events
    assert not _events(env, "crossed") and env.storey.complete
    assert all(s.room == 0 for s in env.storey.scans)  # room B was never scanned
    # The drive to the door given up took no scan: it is the paths' last entry, and the paths add
    # up to the travel counted.
    storey = env.storey
    assert len(storey.paths) == len(storey.scans)
    np.testing.assert_allclose(storey.paths[-1][-1], abandoned[0]["centre"], atol=2e-3)
    driven = sum(float(np.linalg.norm(np.diff(p, axis=0), axis=1).sum()) for p in storey.paths)
    assert driven == pytest.approx(storey.path_length, abs=1e-3)


def test_a_scanner_that_sees_the_jambs_leaves_the_door_frame_it_scanned_from():
    """A 0.5 m minimum range measures the jambs beside a door-frame stop; the robot's full clearance
    (0.45 m) then closes a 0.8 m door, and room B once ended "no NVP" after its door-frame scan. The
    robot leaves the door it came in by with its radius of clearance (navigation.Passage)."""
    from dataclasses import replace

    from nbs_env.config.scanners import scanner_config

    narrow = ((5, 0), (5, 4), [(1.6, 2.4, 2.0)])
    walls = [(a, b, []) for a, b in OUTLINE] + [narrow]
    scene = boxed_storey(walls, [BUILDING], [BUILDING], start=(1.5, 2.0), name="narrow door")
    config = make_config("fast", max_scans=40)
    config = replace(config, robot=replace(config.robot, scanner=scanner_config("rtc360", simulated_step=1.0)))
    env = NBSEnv(config)
    run_episode(env, make_policy("greedy", 0), seed=0, options={"scene": scene})
    ends = env.storey.room_ends
    assert len(ends) == 2 and all(e["reason"] == "gain" for e in ends), ends
    # Room B was scanned from inside, not only from its door frame.
    assert any(s.true_position[0] > 5.6 for s in env.storey.scans)
