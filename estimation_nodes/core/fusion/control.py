"""robot_localization's control term: the commanded velocity as an acceleration.

With ``use_control`` the filter takes the robot's velocity command (``cmd_vel``) into its
prediction, as the peer's ``FilterBase::prepareControl`` and ``Ekf::predict`` do: for each
controlled velocity (vx, vy, vz, vroll, vpitch, vyaw; ``control_config``) the
acceleration toward the command is the velocity error times a gain, limited:

- the set point is the command, or 0 where the command's sign is against the velocity
  (the error then exceeds the command's size by more than 0.01): the robot brakes first;
- moving toward a set point smaller in size than the velocity is decelerating, and takes
  ``deceleration_limits`` and ``deceleration_gains``; else ``acceleration_*``;
- a command older than ``control_timeout`` counts as 0 (the robot told to stop).

Before the motion model moves the state, the linear ones become the state's acceleration
(ax, ay, az) where controlled, and the angular ones change the rates by their
acceleration times the step (the state has no angular acceleration). The covariance is
not touched by the term itself; the prediction then runs as without it.

Where this differs from the peer (``ros2`` branch), on purpose:
- the UKF takes the term too, before drawing its sigma points (the peer computes it
  there and then leaves it unused: ``use_control`` does nothing to its UKF);
- the EKF's Jacobian is taken at the state the term moved, the point the motion model
  moves (the peer's uses the velocities before the term);
- ``control_timeout`` defaults to ``sensor_timeout`` (the peer's comment and its ROS 1
  node; its ROS 2 node declares 0, with which every command has timed out).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from estimation_nodes.core.fusion.state import AX, VROLL, VX
from estimation_nodes.core.validation import FloatArray

#: The controlled velocities, in the order of ``control_config``.
CONTROL_NAMES = ("vx", "vy", "vz", "vroll", "vpitch", "vyaw")
CONTROL_SIZE = len(CONTROL_NAMES)
#: How far (m/s, rad/s) the error may exceed the command's size and still count as the
#: same sign (the peer's tolerance).
SAME_SIGN_TOLERANCE = 0.01


@dataclass(frozen=True)
class ControlSettings:
    """The peer's control parameters, one entry per controlled velocity."""

    controlled: tuple[bool, ...]
    timeout_ns: int
    acceleration_limits: tuple[float, ...]
    acceleration_gains: tuple[float, ...]
    deceleration_limits: tuple[float, ...]
    deceleration_gains: tuple[float, ...]


def control_acceleration(velocity: float, command: float, acceleration_limit: float,
                         acceleration_gain: float, deceleration_limit: float,
                         deceleration_gain: float) -> float:
    """The acceleration that takes ``velocity`` toward ``command`` (the module's rule)."""
    error = command - velocity
    same_sign = abs(error) <= abs(command) + SAME_SIGN_TOLERANCE
    set_point = command if same_sign else 0.0
    decelerating = abs(set_point) < abs(velocity)
    limit, gain = (deceleration_limit, deceleration_gain) if decelerating \
        else (acceleration_limit, acceleration_gain)
    return min(max(gain * error, -limit), limit)


def command_of(twist) -> tuple[float, ...]:
    """A Twist's velocities (a message read by field name, rclpy's or rosbags') in
    control_config's order."""
    return (twist.linear.x, twist.linear.y, twist.linear.z,
            twist.angular.x, twist.angular.y, twist.angular.z)


class DroppedCommand(ValueError):
    """A velocity command that cannot be taken; the message says why."""


def command_message(msg, stamped: bool, arrival_ns: int,
                    base_frame: str) -> tuple[tuple[float, ...], int]:
    """A velocity-command message's command and time, as the node and the offline run
    both take it: a Twist at its ``arrival_ns``; a TwistStamped (``stamped``) at its stamp,
    in ``base_frame`` or no frame. DroppedCommand for one in another frame or with a
    non-finite value."""
    if stamped:
        if msg.header.frame_id not in ("", base_frame):
            raise DroppedCommand(f"frame {msg.header.frame_id!r} is not {base_frame!r}")
        stamp_ns = msg.header.stamp.sec * 1_000_000_000 + msg.header.stamp.nanosec
        twist = msg.twist
    else:
        stamp_ns, twist = arrival_ns, msg
    command = command_of(twist)
    if not all(math.isfinite(v) for v in command):
        raise DroppedCommand("a non-finite value")
    return command, stamp_ns


class Control:
    """The latest command and what it does to a prediction."""

    def __init__(self, settings: ControlSettings) -> None:
        self.settings = settings
        self.command = np.zeros(CONTROL_SIZE)
        #: The command's time (ns); 0 before the first: timed out, a command to stop.
        self.command_ns = 0

    def set(self, command: FloatArray, stamp_ns: int) -> None:
        """The robot's newest velocity command (vx, vy, vz, vroll, vpitch, vyaw)."""
        self.command = np.asarray(command, dtype=float).copy()
        self.command_ns = stamp_ns

    def accelerations(self, x: FloatArray, reference_ns: int) -> FloatArray:
        """Per controlled velocity, the acceleration toward the command valid at
        ``reference_ns`` (0 for the others)."""
        s = self.settings
        timed_out = reference_ns - self.command_ns >= s.timeout_ns
        accelerations = np.zeros(CONTROL_SIZE)
        for i in range(CONTROL_SIZE):
            if s.controlled[i]:
                accelerations[i] = control_acceleration(
                    float(x[VX + i]), 0.0 if timed_out else float(self.command[i]),
                    s.acceleration_limits[i], s.acceleration_gains[i],
                    s.deceleration_limits[i], s.deceleration_gains[i])
        return accelerations

    def applied(self, x: FloatArray, dt: float, reference_ns: int) -> FloatArray:
        """The state with the term in, before a prediction of ``dt`` s to ``reference_ns``
        (a new array)."""
        accelerations = self.accelerations(x, reference_ns)
        moved = np.array(x, dtype=float)
        moved[VROLL:VROLL + 3] += accelerations[3:] * dt
        for i in range(3):
            if self.settings.controlled[i]:
                moved[AX + i] = accelerations[i]
        return moved
