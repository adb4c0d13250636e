import rclpy
from action_msgs.msg import GoalInfo, GoalStatus, GoalStatusArray
from unique_identifier_msgs.msg import UUID

from arm_interfaces.action import Manipulate
from arm_ros.goal_activity import GoalActivity, active_goal_ids


def status_array(*states):
    return GoalStatusArray(
        status_list=[
            GoalStatus(status=s, goal_info=GoalInfo(goal_id=UUID(uuid=[i] * 16))) for i, s in enumerate(states)
        ]
    )


def test_only_accepted_executing_and_cancelling_goals_count():
    assert active_goal_ids(status_array()) == set()
    assert active_goal_ids(status_array(GoalStatus.STATUS_SUCCEEDED, GoalStatus.STATUS_ABORTED)) == set()
    assert active_goal_ids(status_array(GoalStatus.STATUS_CANCELED, GoalStatus.STATUS_UNKNOWN)) == set()
    executing = status_array(GoalStatus.STATUS_SUCCEEDED, GoalStatus.STATUS_EXECUTING, GoalStatus.STATUS_ACCEPTED)
    assert active_goal_ids(executing) == {bytes([1] * 16), bytes([2] * 16)}
    assert len(active_goal_ids(status_array(GoalStatus.STATUS_CANCELING))) == 1


def test_the_pause_lasts_while_a_goal_plans_and_ends_once_it_reports_executing():
    rclpy.init()
    try:
        node = rclpy.create_node("goal_activity_test")
        activity = GoalActivity(node, "arm/manipulate", limit_s=60.0)
        activity._on_status(status_array(GoalStatus.STATUS_EXECUTING))
        assert activity.active_since_s is not None and activity.pauses == 1
        planning = Manipulate.Impl.FeedbackMessage(goal_id=UUID(uuid=[0] * 16))
        activity._on_feedback(planning)
        assert activity.active_since_s is not None  # still planning
        planning.feedback.executing = True
        activity._on_feedback(planning)
        assert activity.active_since_s is None  # the robot moves: frames may come again
        activity._on_status(status_array(GoalStatus.STATUS_SUCCEEDED))
        activity._on_status(status_array(GoalStatus.STATUS_SUCCEEDED, GoalStatus.STATUS_ACCEPTED))
        assert activity.active_since_s is not None and activity.pauses == 2  # the next goal plans
        node.destroy_node()
    finally:
        rclpy.shutdown()
