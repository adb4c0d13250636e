import numpy as np
import trimesh
from sensor_msgs.msg import JointState

from arm_bringup.task import (
    DRY_RUNS,
    EMPTY_GRASP_M,
    SAME_OBJECT_M,
    choose_by_dry_runs,
    far_from,
    finger_opening_m,
    grasp_held,
    rank_targets,
)
from arm_interfaces.action import Manipulate
from arm_interfaces.msg import ReconstructedObject
from arm_ros.conversions.meshes import mesh_to_msg
from arm_sim.robot import GRIPPER_OPEN_M
from arm_sim.world import ROBOT_BASE_XY


def _object(object_id: int, extents_m, xy, visible_fraction: float) -> ReconstructedObject:
    box = trimesh.creation.box(extents=extents_m)
    msg = ReconstructedObject(id=object_id, mesh=mesh_to_msg(box.vertices, box.faces))
    msg.pose.position.x, msg.pose.position.y, msg.pose.position.z = float(xy[0]), float(xy[1]), 0.05
    msg.pose.orientation.w = 1.0
    msg.visible_fraction = visible_fraction
    return msg


def test_candidates_are_the_reachable_objects_most_visible_first_and_for_a_grasp_those_the_gripper_spans():
    near = np.array(ROBOT_BASE_XY) + [0.4, 0.0]
    wide = _object(1, (0.20, 0.15, 0.1), near, 1.0)
    narrow = _object(2, (0.05, 0.12, 0.1), near + [0.0, 0.1], 0.6)
    narrow_far = _object(3, (0.05, 0.05, 0.1), np.array(ROBOT_BASE_XY) + [1.5, 0.0], 0.9)
    objects = [wide, narrow, narrow_far]
    assert [o.id for o in rank_targets(objects, "grasp")[0]] == [2]
    assert [o.id for o in rank_targets(objects, "rearrange")[0]] == [2]
    assert [o.id for o in rank_targets(objects, "push")[0]] == [1, 2], "most visible first"
    candidates, why = rank_targets([wide, narrow_far], "rearrange")
    assert [o.id for o in candidates] == [1] and "pushed" in why


def test_no_target_suits_the_task_and_the_reason_says_why():
    wide = _object(1, (0.20, 0.15, 0.1), np.array(ROBOT_BASE_XY) + [0.4, 0.0], 1.0)
    far = _object(2, (0.05, 0.05, 0.1), np.array(ROBOT_BASE_XY) + [1.5, 0.0], 0.9)
    candidates, why = rank_targets([wide, far], "grasp")
    assert not candidates and "fits between the open fingers" in why
    candidates, why = rank_targets([far], "push")
    assert not candidates and "reach" in why and "1.50 m from the shoulder" in why


def test_a_new_view_leaves_out_the_objects_tried_before_and_keeps_the_others():
    tried = _object(1, (0.05, 0.05, 0.1), (0.10, 0.0), 1.0)
    nudged = _object(2, (0.05, 0.05, 0.1), (0.10 + 0.8 * SAME_OBJECT_M, 0.0), 1.0)
    other = _object(3, (0.05, 0.05, 0.1), (0.10, 2.0 * SAME_OBJECT_M), 1.0)
    tried_m = [np.array([0.10, 0.0, 0.05])]
    assert [o.id for o in far_from([tried, nudged, other], tried_m, SAME_OBJECT_M)] == [3]
    assert [o.id for o in far_from([tried, other], [], SAME_OBJECT_M)] == [1, 3]


def test_the_fingers_say_whether_a_grasp_holds_something():
    state = JointState(name=["panda_joint1", "panda_finger_joint1"], position=[0.3, 0.0016])
    assert finger_opening_m(state) > EMPTY_GRASP_M, "a lamp held by its thin stem"
    state.position = [0.3, -0.0]
    assert finger_opening_m(state) <= EMPTY_GRASP_M, "closed on nothing"
    assert finger_opening_m(JointState(name=["panda_joint1"], position=[0.3])) is None


def test_a_grasp_holds_when_the_fingers_did_not_close_on_nothing():
    assert grasp_held("grasp", 0.0016), "a thin stem between the fingers"
    assert grasp_held("grasp", 0.012)
    assert not grasp_held("grasp", 0.0), "closed on nothing"
    assert not grasp_held("grasp", GRIPPER_OPEN_M), "never closed"
    assert not grasp_held("push", 0.012)
    assert not grasp_held("grasp", None), "no finger reading"


def _result(met: bool, held: bool, perturbed_met: int = 5, perturbed: int = 5) -> Manipulate.Result:
    return Manipulate.Result(
        success=met, held_in_twin=held, perturbed_twins=perturbed, perturbed_twins_met=perturbed_met, message="dry run"
    )


def _dry_runs(outcomes: dict):
    """A dry run per candidate id: outcomes[id] = (met, held) or (met, held, perturbed twins met of 5),
    a missing id: no result."""
    asked = []

    def dry_run(candidate):
        asked.append(candidate.id)
        if candidate.id not in outcomes:
            return None
        return _result(*outcomes[candidate.id])

    return dry_run, asked


def test_the_target_is_the_first_candidate_whose_dry_run_met_the_task_and_held_it():
    candidates = [_object(i, (0.05, 0.05, 0.1), (0.1 * i, 0.0), 1.0) for i in range(1, 5)]
    dry_run, asked = _dry_runs({1: (False, False), 2: (True, False), 3: (True, True), 4: (True, True)})
    target, why, runs = choose_by_dry_runs(candidates, dry_run)
    assert target.id == 3 and asked == [1, 2, 3], "held at the third: the fourth is not planned"
    assert "held it" in why and [r["held_in_twin"] for r in runs] == [False, False, True]


def test_where_no_dry_run_held_the_task_the_first_that_met_it_is_the_target():
    candidates = [_object(i, (0.05, 0.05, 0.1), (0.1 * i, 0.0), 1.0) for i in range(1, DRY_RUNS + 3)]
    dry_run, asked = _dry_runs({2: (True, False), 5: (True, False)})
    target, why, runs = choose_by_dry_runs(candidates, dry_run)
    assert target.id == 2 and asked == list(range(1, DRY_RUNS + 1)) and "none held it" in why
    assert [r["met_in_twin"] for r in runs].count(True) == 2
    dry_run, _ = _dry_runs({})
    target, why, runs = choose_by_dry_runs(candidates, dry_run)
    assert target is None and f"no dry run of the {DRY_RUNS} tried" in why


def test_fewer_candidates_than_dry_runs_are_planned_again_in_turn():
    candidates = [_object(i, (0.05, 0.05, 0.1), (0.1 * i, 0.0), 1.0) for i in (1, 2)]
    outcomes = iter([(False, False), (True, False), (False, False), (True, True)])

    def dry_run(candidate):
        return _result(*next(outcomes))

    target, why, runs = choose_by_dry_runs(candidates, dry_run)
    assert target.id == 2 and [r["id"] for r in runs] == [1, 2, 1, 2], "held at its second dry run"
    assert "held it" in why
    dry_run, asked = _dry_runs({1: (False, False)})
    target, why, runs = choose_by_dry_runs(candidates, dry_run)
    assert target is None and asked == [1, 2] * (DRY_RUNS // 2), "every dry run is spent"


def test_the_fallback_is_a_candidate_whose_latest_dry_run_met_the_task():
    candidates = [_object(i, (0.05, 0.05, 0.1), (0.1 * i, 0.0), 1.0) for i in (1, 2)]
    calls = {1: 0, 2: 0}

    def dry_run(candidate):
        calls[candidate.id] += 1
        # object 1 met the task only at its first dry run: plan_node no longer keeps that plan
        met = candidate.id == 2 or calls[1] == 1
        return _result(met, False)

    target, why, _ = choose_by_dry_runs(candidates, dry_run)
    assert target.id == 2 and "none held it" in why


def test_dry_runs_go_on_past_a_held_plan_that_fails_in_its_perturbed_twins():
    candidates = [_object(i, (0.05, 0.05, 0.1), (0.1 * i, 0.0), 1.0) for i in range(1, 5)]
    dry_run, asked = _dry_runs({1: (True, True, 2), 2: (True, True, 3), 3: (True, True, 4), 4: (True, True, 5)})
    target, why, runs = choose_by_dry_runs(candidates, dry_run)
    assert target.id == 3 and asked == [1, 2, 3], "4 of 5 perturbed twins is enough: the fourth is not planned"
    assert "4 of 5 perturbed twins" in why and runs[0]["perturbed_twins"] == (2, 5)


def test_where_no_held_plan_is_robust_the_one_met_in_most_perturbed_twins_is_the_target():
    candidates = [_object(i, (0.05, 0.05, 0.1), (0.1 * i, 0.0), 1.0) for i in range(1, 4)]
    dry_run, asked = _dry_runs({1: (True, True, 1), 2: (True, False, 5), 3: (True, True, 3)})
    target, why, runs = choose_by_dry_runs(candidates, dry_run)
    assert len(asked) == DRY_RUNS, "every dry run is spent looking for a robust plan"
    assert target.id == 3 and "3 of 5 perturbed twins" in why, "held plans first, then the most perturbed twins"
    dry_run, _ = _dry_runs({1: (True, True, 2), 2: (True, True, 2)})
    target, _, _ = choose_by_dry_runs(candidates, dry_run)
    assert target.id == 1, "the first of equals"
