#!/usr/bin/env python3
# Copyright 2026 The avp authors. SPDX-License-Identifier: Apache-2.0
"""Turn avp's chosen views into MoveIt 2 motions (ROS 2 Humble and Jazzy).

`avp live` publishes the camera pose it wants next on /avp/next_view
(geometry_msgs/PoseStamped: the pose of the camera's optical frame,
`camera_color_optical_frame`, in `igus_rebel_base_link`). This node sends each
one to MoveIt's move_group as a MoveGroup action goal (plan and execute) with a
pose goal for the camera link, so the arm gets there on a collision-aware path.

You do not need this script to move the arm. By default avp drives it itself:
it solves IK, publishes the joint goal as trajectory_msgs/JointTrajectory
straight to a joint trajectory controller
(/joint_trajectory_controller/joint_trajectory by default, configurable) and
waits until /joint_states (or the camera's TF) shows the arm has arrived. That
path plans nothing: it is a straight move in joint space. Use this script when
you want MoveIt to plan around the scene, and turn avp's own JointTrajectory
output off (or point it at an unused topic) so that only one of them commands
the arm. See docs/ros2.md.

Policy while moving: a new /avp/next_view that arrives while a goal is still
planning or executing is IGNORED (logged), not pre-empted: cancelling a
motion half-way would leave the arm somewhere avp did not choose. avp publishes
the next view only after the arm has arrived, so in normal use nothing is
dropped.

Parameters (all settable with --ros-args -p name:=value):
  group                  MoveIt planning group               (rebel_arm)
  link                   link to put at the pose             (camera_color_optical_frame)
  topic                  where avp publishes the chosen view (/avp/next_view)
  action                 move_group's MoveGroup action       (move_action)
  position_tolerance     m, radius of the goal sphere        (0.001)
  orientation_tolerance  rad, per axis                       (0.01)
  velocity_scaling       0..1 of the joint velocity limits   (0.5)
  acceleration_scaling   0..1 of the acceleration limits     (0.5)
  pipeline_id            planning pipeline, '' = default     ('')
  planner_id             planner in it, '' = its default     ('')
  planning_time          s allowed per attempt               (5.0)
  planning_attempts      attempts                            (5)

`rebel_arm` is the group of the ReBeL MoveIt config that avp's defaults follow
(AIRLab-POLIMI/ros2-igus-rebel, igus_rebel_moveit_config: base
`igus_rebel_base_link`); igus's own config (CommonplaceRobotics/iRC_ROS,
irc_ros_moveit_config) calls it `rebel_6dof` and its base `base_link`. The link
must exist in the URDF MoveIt loaded (the RealSense xacro adds
camera_color_optical_frame) and be rigidly attached to the group's tip.

Arrival: MoveIt may pick a different IK solution than avp's joint goal, so
avp's joint-state test can miss it; avp also accepts the camera's TF within
1 cm / 1 degree of the view. Keep the tolerances inside that: 0.01 rad is about
0.57 degrees.
"""

import rclpy
from rclpy.action import ActionClient
from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy

from action_msgs.msg import GoalStatus
from geometry_msgs.msg import PoseStamped
from moveit_msgs.action import MoveGroup
from moveit_msgs.msg import (
    BoundingVolume,
    Constraints,
    MoveItErrorCodes,
    OrientationConstraint,
    PositionConstraint,
)
from shape_msgs.msg import SolidPrimitive

# MoveItErrorCodes value -> name, for readable logs.
ERROR_NAMES = {
    getattr(MoveItErrorCodes, name): name
    for name in dir(MoveItErrorCodes)
    if name.isupper() and isinstance(getattr(MoveItErrorCodes, name), int)
}


class NextViewToMoveIt(Node):
    def __init__(self):
        super().__init__("avp_next_view_to_moveit")
        self.group = self.declare_parameter("group", "rebel_arm").value
        self.link = self.declare_parameter("link", "camera_color_optical_frame").value
        topic = self.declare_parameter("topic", "/avp/next_view").value
        action = self.declare_parameter("action", "move_action").value
        self.position_tolerance = self.declare_parameter("position_tolerance", 0.001).value
        self.orientation_tolerance = self.declare_parameter("orientation_tolerance", 0.01).value
        self.velocity_scaling = self.declare_parameter("velocity_scaling", 0.5).value
        self.acceleration_scaling = self.declare_parameter("acceleration_scaling", 0.5).value
        self.pipeline_id = self.declare_parameter("pipeline_id", "").value
        self.planner_id = self.declare_parameter("planner_id", "").value
        self.planning_time = self.declare_parameter("planning_time", 5.0).value
        self.planning_attempts = self.declare_parameter("planning_attempts", 5).value

        self.busy = False  # a goal is planning or executing
        self.client = ActionClient(self, MoveGroup, action)

        # avp publishes reliable and volatile (keep last 10); this reader keeps only the newest view.
        qos = QoSProfile(
            history=HistoryPolicy.KEEP_LAST,
            depth=1,
            reliability=ReliabilityPolicy.RELIABLE,
            durability=DurabilityPolicy.VOLATILE,
        )
        self.create_subscription(PoseStamped, topic, self.on_next_view, qos)
        self.get_logger().info(
            f"waiting for {topic}; goals go to '{action}' for group '{self.group}', "
            f"link '{self.link}'"
        )

    def on_next_view(self, view: PoseStamped):
        p = view.pose.position
        if self.busy:
            self.get_logger().warn(
                f"ignoring view ({p.x:.3f}, {p.y:.3f}, {p.z:.3f}): the previous goal is still running"
            )
            return
        if not self.client.server_is_ready():
            self.get_logger().error("move_group's MoveGroup action server is not available; view dropped")
            return
        self.busy = True
        self.get_logger().info(
            f"view ({p.x:.3f}, {p.y:.3f}, {p.z:.3f}) in '{view.header.frame_id}': planning"
        )
        future = self.client.send_goal_async(
            self.make_goal(view), feedback_callback=self.on_feedback
        )
        future.add_done_callback(self.on_goal_response)

    def make_goal(self, view: PoseStamped) -> MoveGroup.Goal:
        frame = view.header.frame_id or "igus_rebel_base_link"

        # Position: the link's origin inside a small sphere around the target.
        sphere = SolidPrimitive(type=SolidPrimitive.SPHERE, dimensions=[self.position_tolerance])
        position = PositionConstraint(link_name=self.link, weight=1.0)
        position.header.frame_id = frame
        position.constraint_region = BoundingVolume(
            primitives=[sphere], primitive_poses=[view.pose]
        )

        # Orientation: the link's axes within the tolerance of the target's.
        orientation = OrientationConstraint(
            link_name=self.link,
            orientation=view.pose.orientation,
            absolute_x_axis_tolerance=self.orientation_tolerance,
            absolute_y_axis_tolerance=self.orientation_tolerance,
            absolute_z_axis_tolerance=self.orientation_tolerance,
            weight=1.0,
        )
        orientation.header.frame_id = frame

        goal = MoveGroup.Goal()
        request = goal.request
        request.group_name = self.group
        request.goal_constraints = [
            Constraints(position_constraints=[position], orientation_constraints=[orientation])
        ]
        request.pipeline_id = self.pipeline_id
        request.planner_id = self.planner_id
        request.num_planning_attempts = self.planning_attempts
        request.allowed_planning_time = self.planning_time
        request.max_velocity_scaling_factor = self.velocity_scaling
        request.max_acceleration_scaling_factor = self.acceleration_scaling
        request.start_state.is_diff = True  # start from the robot's current state

        goal.planning_options.plan_only = False  # plan and execute
        goal.planning_options.planning_scene_diff.is_diff = True
        goal.planning_options.planning_scene_diff.robot_state.is_diff = True
        return goal

    def on_feedback(self, feedback_msg):
        self.get_logger().debug(f"move_group: {feedback_msg.feedback.state}")

    def on_goal_response(self, future):
        handle = future.result()
        if handle is None or not handle.accepted:
            self.get_logger().error("move_group rejected the goal")
            self.busy = False
            return
        handle.get_result_async().add_done_callback(self.on_result)

    def on_result(self, future):
        self.busy = False
        response = future.result()
        code = response.result.error_code.val
        name = ERROR_NAMES.get(code, str(code))
        if response.status == GoalStatus.STATUS_SUCCEEDED and code == MoveItErrorCodes.SUCCESS:
            self.get_logger().info(
                f"arrived (planning took {response.result.planning_time:.2f} s)"
            )
        else:
            self.get_logger().error(
                f"motion failed: {name} (action status {response.status}); "
                "avp will report a robot fault if the arm never arrives"
            )


def main():
    rclpy.init()
    node = NextViewToMoveIt()
    try:
        rclpy.spin(node)
    except KeyboardInterrupt:
        pass
    finally:
        node.destroy_node()
        if rclpy.ok():
            rclpy.shutdown()


if __name__ == "__main__":
    main()
