from action_msgs.msg import GoalStatus, GoalStatusArray

from arm_ros.goal_activity import active_goal_count


def status_array(*states):
    return GoalStatusArray(status_list=[GoalStatus(status=s) for s in states])


def test_only_accepted_executing_and_cancelling_goals_count():
    assert active_goal_count(status_array()) == 0
    assert active_goal_count(status_array(GoalStatus.STATUS_SUCCEEDED, GoalStatus.STATUS_ABORTED)) == 0
    assert active_goal_count(status_array(GoalStatus.STATUS_CANCELED, GoalStatus.STATUS_UNKNOWN)) == 0
    executing = status_array(GoalStatus.STATUS_SUCCEEDED, GoalStatus.STATUS_EXECUTING, GoalStatus.STATUS_ACCEPTED)
    assert active_goal_count(executing) == 2
    assert active_goal_count(status_array(GoalStatus.STATUS_CANCELING)) == 1
