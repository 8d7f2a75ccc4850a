"""use_control: the velocity command as an acceleration in the prediction (robot_localization's
control term), in the core, the configuration and the offline run."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest

from estimation_nodes.core.fusion import state, steps
from estimation_nodes.core.fusion.control import (Control, ControlSettings, DroppedCommand,
                                                  command_message, control_acceleration)
from estimation_nodes.core.fusion.filter import FusionFilter
from estimation_nodes.core.fusion.steps import Measurement
from estimation_nodes.params.fusion import FusionConfigError, fusion_config
from estimation_nodes.tools.fusion import offline

#: The peer's example (params/ekf.yaml): vx and vyaw controlled.
EXAMPLE = {"use_control": True, "control_timeout": 0.2,
           "control_config": [True, False, False, False, False, True],
           "acceleration_limits": [1.3, 0.0, 0.0, 0.0, 0.0, 3.4],
           "deceleration_limits": [1.3, 0.0, 0.0, 0.0, 0.0, 4.5],
           "acceleration_gains": [0.8, 0.0, 0.0, 0.0, 0.0, 0.9],
           "deceleration_gains": [1.0, 0.0, 0.0, 0.0, 0.0, 1.0]}


@pytest.mark.parametrize("velocity, command, expected", [
    (0.0, 1.0, 0.8),        # speeding up: the acceleration gain times the error
    (0.0, 3.0, 1.3),        # ... limited by the acceleration limit
    (1.0, 0.5, -0.5),       # slowing down toward a smaller command: the deceleration gain
    (2.0, 0.0, -1.3),       # ... limited by the deceleration limit
    (1.0, -1.0, -1.3),      # a command against the motion: braking to 0 first
    (-0.5, -1.0, -0.4),     # backwards, speeding up
])
def test_the_acceleration_toward_the_command(velocity, command, expected):
    assert control_acceleration(velocity, command, 1.3, 0.8, 1.3, 1.0) == pytest.approx(expected)


def settings(**overrides) -> ControlSettings:
    return fusion_config({**EXAMPLE, **overrides}).settings.control


def test_the_term_sets_the_acceleration_and_turns_the_rate_before_the_motion():
    control = Control(settings())
    control.set((1.0, 0.0, 0.0, 0.0, 0.0, 2.0), stamp_ns=1_000_000_000)
    x = np.zeros(15)
    x[state.VX], x[state.VYAW], x[state.AY] = 0.2, 0.5, 0.3
    moved = control.applied(x, 0.1, reference_ns=1_100_000_000)
    expected = x.copy()
    expected[state.AX] = 0.8 * (1.0 - 0.2)                 # vx's term is ax
    expected[state.VYAW] = 0.5 + min(0.9 * 1.5, 3.4) * 0.1  # vyaw's turns the rate
    np.testing.assert_allclose(moved, expected, rtol=0, atol=1e-15)


def test_a_command_older_than_the_timeout_is_a_command_to_stop():
    control = Control(settings())
    control.set((1.0, 0.0, 0.0, 0.0, 0.0, 0.0), stamp_ns=0)
    x = np.zeros(15)
    x[state.VX] = 1.0
    assert control.accelerations(x, 199_999_999)[0] == 0.0       # at the command
    assert control.accelerations(x, 200_000_000)[0] == pytest.approx(-1.0)   # timed out


def odometry_at(stamp_ns: int, velocity: float) -> Measurement:
    z = np.zeros(15)
    z[state.VX] = velocity
    return Measurement(stamp_ns, z, np.eye(15) * 1e-4, (state.VX,), source="odom0_twist")


@pytest.mark.parametrize("kind", ["ekf", "ukf"])
def test_a_prediction_with_the_term_is_the_one_from_the_moved_state(kind):
    """The filter's prediction with control equals the plain step (steps.py, itself equal
    to the direct computation) from the state the term moved."""
    config = fusion_config({**EXAMPLE, "filter_type": kind})
    fusion = FusionFilter(config.settings)
    fusion.process(odometry_at(0, 0.2))
    fusion.control.set((1.0, 0.0, 0.0, 0.0, 0.0, 0.5), stamp_ns=0)
    x, p = fusion.x.copy(), fusion.p.copy()
    fusion.predict(50_000_000)
    moved = x.copy()
    moved[state.AX] = 0.8 * (1.0 - 0.2)
    moved[state.VYAW] += 0.9 * 0.5 * 0.05
    q = config.settings.process_noise
    expected = steps.ekf_predict(moved, p, q, 0.05) if kind == "ekf" else \
        steps.ukf_predict(moved, p, q, 0.05, config.settings.weights)[:2]
    np.testing.assert_allclose(fusion.x, expected[0], rtol=0, atol=1e-12)
    np.testing.assert_allclose(fusion.p, expected[1], rtol=0, atol=1e-12)
    assert fusion.x[state.VX] == pytest.approx(0.2 + 0.8 * 0.8 * 0.05)


def test_the_estimate_follows_the_command_between_measurements():
    """A robot told 1 m/s with no measurement after its first: the estimate speeds up at
    the gain and the limits, and brakes once the command has timed out."""
    config = fusion_config({**EXAMPLE, "sensor_timeout": 0.05})
    fusion = FusionFilter(config.settings)
    fusion.process(odometry_at(0, 0.0))
    period = 20_000_000
    speeds = []
    for k in range(1, 101):
        if k <= 50:
            fusion.control.set((1.0, 0.0, 0.0, 0.0, 0.0, 0.0), stamp_ns=k * period)
        fusion.update(k * period)
        speeds.append(fusion.x[state.VX])
    # dv/dt = 0.8 (1 - v) from rest: 1 - exp(-0.8) = 0.55 after 1 s, in 60 ms steps here
    # (a prediction each sensor_timeout)
    assert speeds[49] == pytest.approx(1 - np.exp(-0.8), abs=0.02)
    assert np.all(np.diff(speeds[:50]) >= 0)
    # The last command (1.0 s) times out at 1.2 s: the estimate brakes from then on.
    top = int(np.argmax(speeds))
    assert (top + 1) * period / 1e9 == pytest.approx(1.2, abs=0.061)
    assert np.all(np.diff(speeds[top:]) <= 0) and speeds[-1] < speeds[top] - 0.25


def test_the_configuration_takes_the_peers_names_and_refuses_a_malformed_one():
    config = fusion_config(EXAMPLE)
    control = config.settings.control
    assert control.controlled == (True, False, False, False, False, True)
    assert control.timeout_ns == 200_000_000
    assert control.deceleration_limits[5] == 4.5 and control.acceleration_gains[0] == 0.8
    assert config.unsupported == ()
    assert fusion_config({"use_control": False, "control_config": [True] * 6}
                         ).settings.control is None
    # Missing: the limits and gains default to 1, the deceleration ones to the acceleration
    # ones, the timeout to sensor_timeout.
    bare = fusion_config({"use_control": True, "control_config": [True] + [False] * 5,
                          "sensor_timeout": 0.1}).settings.control
    assert bare.acceleration_limits == bare.deceleration_limits == (1.0,) * 6
    assert bare.timeout_ns == 100_000_000
    for bad, message in (({"control_config": [True] * 5}, "control_config: expected 6"),
                         ({"acceleration_limits": [1.0] * 3}, "acceleration_limits"),
                         ({"deceleration_gains": [-1.0] * 6}, "deceleration_gains"),
                         ({"control_timeout": 0.0}, "control_timeout")):
        with pytest.raises(FusionConfigError, match=message):
            fusion_config({**EXAMPLE, **bad})
    with pytest.raises(FusionConfigError, match="control_config"):
        fusion_config({"use_control": True})


def test_an_acceleration_the_imu_measures_is_not_also_commanded():
    config = fusion_config({**EXAMPLE, "imu0": "imu",
                            "imu0_config": [False] * 12 + [True, False, False]})
    assert config.settings.control.controlled == (False,) * 5 + (True,)
    assert config.notes == ("X acceleration is being measured from IMU; X velocity control "
                            "input is disabled",)


def twist(vx: float, vyaw: float) -> SimpleNamespace:
    return SimpleNamespace(linear=SimpleNamespace(x=vx, y=0.0, z=0.0),
                           angular=SimpleNamespace(x=0.0, y=0.0, z=vyaw))


def test_the_offline_run_takes_recorded_commands_as_the_node_does():
    """cmd_vel in a bag reaches the filter at its arrival (Twist) between the odometry."""
    config = fusion_config({**EXAMPLE, "odom0": "odom",
                            "odom0_config": [False] * 6 + [True] + [False] * 8})
    odometry = SimpleNamespace(
        header=SimpleNamespace(stamp=SimpleNamespace(sec=0, nanosec=0), frame_id="odom"),
        child_frame_id="base_link",
        pose=SimpleNamespace(pose=SimpleNamespace(
            position=SimpleNamespace(x=0.0, y=0.0, z=0.0),
            orientation=SimpleNamespace(x=0.0, y=0.0, z=0.0, w=1.0)),
            covariance=[0.0] * 36),
        twist=SimpleNamespace(twist=twist(0.0, 0.0), covariance=list(np.eye(6).ravel() * 1e-3)))
    messages = [(0, "odom", odometry)] + [
        (k * 10_000_000, "/cmd_vel", twist(1.0, 0.0)) for k in range(1, 100)]
    with_commands = offline.run(config, messages)
    without = offline.run(config, messages[:1] + [(990_000_000, "/other", None)])
    assert with_commands.fusion.x[state.VX] > 0.5
    assert without.fusion.x[state.VX] == pytest.approx(0.0, abs=1e-12)


def stamped(frame: str, vx: float) -> SimpleNamespace:
    return SimpleNamespace(header=SimpleNamespace(frame_id=frame,
                                                  stamp=SimpleNamespace(sec=3, nanosec=5)),
                           twist=twist(vx, 0.0))


def test_a_command_message_is_taken_at_its_arrival_or_its_stamp_in_the_robots_frame():
    """The node and the offline run take a command alike (control.command_message): a
    Twist at its arrival, a TwistStamped at its stamp in the robot's frame or none; one in
    another frame or with a non-finite value is dropped, saying why."""
    assert command_message(twist(1.0, 0.5), False, 7, "base_link") == \
        ((1.0, 0.0, 0.0, 0.0, 0.0, 0.5), 7)
    for frame in ("", "base_link"):
        assert command_message(stamped(frame, 2.0), True, 7, "base_link") == \
            ((2.0, 0.0, 0.0, 0.0, 0.0, 0.0), 3_000_000_005)
    with pytest.raises(DroppedCommand, match="frame 'odom' is not 'base_link'"):
        command_message(stamped("odom", 2.0), True, 7, "base_link")
    with pytest.raises(DroppedCommand, match="non-finite"):
        command_message(twist(float("nan"), 0.0), False, 7, "base_link")
