"""estimation_replay over a recording with none of the outputs it compares (a landmarks run
without a pose, an imported log) says there is nothing to compare instead of EQUAL."""

import pytest

from estimation_nodes.tools.recording.mcap import McapRunWriter
from estimation_nodes.tools.replay import estimator as replay_cli
from tests.conftest import REPO


def test_a_landmarks_recording_is_refused_not_found_equal(tmp_path, capsys):
    path = tmp_path / "landmarks.mcap"
    text = (REPO / "msgs_config" / "landmarks.yaml").read_text(encoding="utf-8")
    writer = McapRunWriter(path, {"/odom": "nav_msgs/msg/Odometry"},
                           {"kind": "landmarks", "parameters_yaml": text})
    writer.close()
    with pytest.raises(SystemExit) as exit_info:
        replay_cli.main([str(path)])
    assert exit_info.value.code == 2
    out, err = capsys.readouterr()
    assert "EQUAL" not in out
    assert "nothing to compare" in err
