"""The matrix Kalman filter in the plane through topics: demo, recording, replay, filterpy."""

import numpy as np
from filterpy.kalman import KalmanFilter as FilterpyKalman

from estimation_nodes.params.estimator import build_kalman_settings
from estimation_nodes.tools.recording.mcap import read_recording
from estimation_nodes.tools.replay.estimator import estimator_values
from tests.graph.graph_tools import settled
from tests.graph.test_recording import decoded_by_topic, record_run


def test_tracking_2d_through_topics_equals_filterpy_offline(ros_env, tmp_path):
    mcap_path, png_path = record_run(ros_env, tmp_path, "tracking_2d")
    recording = read_recording(mcap_path)
    run = recording.record
    assert len(run.kalman_inputs) == 40 and len(run.kalman_measurements) == 40
    # At least one estimate per event: one that arrived before the input that caused it
    # was applied, published, and published again once that input came (causal order).
    assert len(run.states) >= 40 and len(run.states_predicted) >= 40
    assert len(run.true_states) == 40

    # filterpy, run on the recorded inputs in the order they were published. Its names:
    # F the transition (the book's A), H the measurement matrix (C), Q the process noise
    # already in state space (the book's F Q F').
    settings = build_kalman_settings(estimator_values(recording.metadata["parameters_yaml"]))
    model = settings.model
    kf = FilterpyKalman(dim_x=4, dim_z=2, dim_u=2)
    kf.F, kf.B, kf.H = model.A, model.B, model.C
    kf.Q, kf.R = model.F @ model.Q @ model.F.T, model.R
    kf.x, kf.P = settings.initial.x.copy(), settings.initial.P.copy()
    offline: dict[str, list] = {"kalman_input": [], "kalman_measurement": []}
    for topic, value in run.events:
        if topic == "kalman_input":
            kf.predict(u=np.array(value))
        else:
            kf.update(np.array(value))
        offline[topic].append(np.concatenate([kf.x, kf.P.ravel()]))
    # Each filterpy estimate against the published one that settled it, in order.
    for published, expected in ((run.states_predicted, offline["kalman_input"]),
                                (run.states, offline["kalman_measurement"])):
        flat = [np.concatenate([x, P.ravel()]) for x, P in published]
        assert len(settled(flat, expected, atol=1e-9)) == 40

    # The pose carries x and y and their block of P, so RViz draws the ellipse.
    _, by_topic, _ = decoded_by_topic(mcap_path)
    pose = by_topic["/kalman_estimate"][-1]
    x, P = run.states[-1]
    assert (pose.pose.position.x, pose.pose.position.y) == (x[0], x[1])
    np.testing.assert_array_equal(np.array(pose.covariance).reshape(6, 6)[:2, :2], P[:2, :2])
    assert png_path.stat().st_size > 10_000


def test_tracking_2d_replays_equal(ros_env, tmp_path):
    import subprocess

    from tests.graph.graph_tools import executable

    mcap_path, _ = record_run(ros_env, tmp_path, "tracking_2d")
    replay = subprocess.run([executable("estimation_replay"), str(mcap_path)], env=ros_env,
                            capture_output=True, text=True, timeout=60)
    assert replay.returncode == 0, replay.stdout + replay.stderr
    assert "kalman_state: 40 estimates compared, largest difference 0" in replay.stdout
    assert "online vs offline to 1e-09: EQUAL" in replay.stdout
