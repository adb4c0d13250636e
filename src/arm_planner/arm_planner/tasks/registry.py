"""The tasks by name: each builds its reward from the request and the planner's settings (MJPC style:
the planner asks the registry, never the name)."""

from arm_planner.tasks import TASK_GRASP, TASK_PUSH, TASK_REARRANGE
from arm_planner.tasks.grasp import grasp_task, rearrange_task
from arm_planner.tasks.push import push_task

TASK_REWARDS = {TASK_GRASP: grasp_task, TASK_PUSH: push_task, TASK_REARRANGE: rearrange_task}
