"""A small test robot: a 4-DoF gantry (x, y, z slides + yaw) with a parallel gripper over a table."""

import mujoco

from arm_planner.robot_spec import RobotSpec

GANTRY_XML = """
<mujoco>
  <option timestep="0.002" integrator="implicitfast"/>
  <default>
    <geom friction="1 0.01 0.001" solref="0.01 1"/>
  </default>
  <worldbody>
    <geom name="table" type="box" size="0.6 0.6 0.02" pos="0 0 -0.02"/>
    <body name="carriage" pos="0 0 0.3">
      <joint name="gx" type="slide" axis="1 0 0" range="-0.5 0.5" damping="20"/>
      <joint name="gy" type="slide" axis="0 1 0" range="-0.5 0.5" damping="20"/>
      <joint name="gz" type="slide" axis="0 0 1" range="-0.29 0.3" damping="20"/>
      <joint name="gyaw" type="hinge" axis="0 0 1" range="-3 3" damping="2"/>
      <geom type="sphere" size="0.005" mass="1" contype="0" conaffinity="0"/>
      <body name="hand" quat="0 1 0 0">
        <geom type="box" size="0.02 0.05 0.01" mass="0.5"/>
        <body name="left_finger" pos="0 0.03 0.04">
          <joint name="finger_l" type="slide" axis="0 -1 0" range="0 0.04" damping="5"/>
          <geom type="box" size="0.008 0.005 0.03" mass="0.05" friction="2 0.01 0.001"/>
        </body>
        <body name="right_finger" pos="0 -0.03 0.04">
          <joint name="finger_r" type="slide" axis="0 1 0" range="0 0.04" damping="5"/>
          <geom type="box" size="0.008 0.005 0.03" mass="0.05" friction="2 0.01 0.001"/>
        </body>
      </body>
    </body>
    <body name="object_0" pos="0.15 0.0 0.03">
      <freejoint/>
      <geom name="object_0_part_0" type="box" size="0.025 0.02 0.03" mass="0.1"/>
    </body>
  </worldbody>
  <equality>
    <joint joint1="finger_l" joint2="finger_r"/>
  </equality>
  <actuator>
    <position name="ax" joint="gx" kp="800" ctrlrange="-0.5 0.5"/>
    <position name="ay" joint="gy" kp="800" ctrlrange="-0.5 0.5"/>
    <position name="az" joint="gz" kp="800" ctrlrange="-0.29 0.3"/>
    <position name="ayaw" joint="gyaw" kp="50" ctrlrange="-3 3"/>
    <position name="gripper" joint="finger_l" kp="300" ctrlrange="0 0.04"/>
  </actuator>
</mujoco>
"""

GANTRY_SPEC = RobotSpec(
    arm_joints=("gx", "gy", "gz", "gyaw"),
    gripper_actuator="gripper",
    gripper_open=0.0,
    gripper_closed=0.04,
    tcp_body="hand",
    tcp_offset_m=(0.0, 0.0, 0.06),
    max_joint_rate_rad_s=0.5,
    max_gripper_rate=0.2,
    trajectory_joint_names=("gx", "gy", "gz", "gyaw", "finger_l"),
)


def gantry_model() -> mujoco.MjModel:
    return mujoco.MjModel.from_xml_string(GANTRY_XML)
