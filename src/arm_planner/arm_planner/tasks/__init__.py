"""The planner's tasks: grasp, push and rearrange, each a stateful reward for MPPI.

A task reward scores rollouts (batched, vectorised over paths and horizon) and keeps a small state
machine that advances only on the executed trajectory, as in the paper's appendix "MPPI
Parameters": ungrasped -> grasping (gripper closes for `close_steps`) -> grasped. `base` holds what
every task shares (the target's geometry, the weights, kinematics from the state); `grasp` the grasp
and the rearrange (a grasp carried to a goal); `push` the one-finger and the caging push.

Each task builds its own reward from the request and the planner's settings (`registry.TASK_REWARDS`:
grasp_task, push_task, rearrange_task) and owns what the planning loop asks of it (TaskReward): its
step budget, the hand's speed cap at each step, whether it holds its goal (so the loop may stop early)
and whether it is met. The planner never asks for a task's name; a rearrange of a target no grasp
holds is built as a push. A new task is a module here and an entry in the registry (and a constant in
the Manipulate action for plan_node).
"""

TASK_GRASP = "grasp"
TASK_PUSH = "push"
TASK_REARRANGE = "rearrange"
TASKS = (TASK_GRASP, TASK_PUSH, TASK_REARRANGE)
GRASP_LIFT_M = 0.05
