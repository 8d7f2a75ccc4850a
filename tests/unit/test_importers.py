"""estimation_import: CARMEN logs and the UTIAS dataset read as published, and written as
MCAP recordings that decode to the log's values; bad input counted or refused in one line."""

from __future__ import annotations

import gzip
import math
from pathlib import Path

import numpy as np
import pytest

from estimation_nodes.tools.importers import carmen, cli, utias

SHARED = Path(__file__).resolve().parents[3] / "shared" / "data"
needs_shared = pytest.mark.skipif(not (SHARED / "carmen").is_dir(),
                                  reason=f"no CARMEN logs at {SHARED}")


def decoded(path: Path) -> dict[str, list]:
    from mcap.reader import make_reader
    from mcap_ros2.decoder import DecoderFactory

    topics: dict[str, list] = {}
    with path.open("rb") as stream:
        reader = make_reader(stream, decoder_factories=[DecoderFactory()])
        for _schema, channel, message, msg in reader.iter_decoded_messages(log_time_order=True):
            topics.setdefault(channel.topic, []).append((message.log_time, msg))
    return topics


def stamp(msg) -> float:
    return msg.header.stamp.sec + msg.header.stamp.nanosec * 1e-9


# --- CARMEN ------------------------------------------------------------------------------

#: The raw odometry a robot measured (x, y, theta) at 0, 1, 2, 3 s, and the corrected
#: poses of its scans at 1 s and 3 s: the corrected log restarts the odometry at each.
RAW = [(0.0, 0.0, 0.0), (1.0, 0.0, 0.1), (2.0, 0.2, 0.3), (2.5, 1.0, 0.8)]
CORRECTED = {1.0: (1.1, 0.05, 0.12), 3.0: (2.7, 1.2, 0.85)}


def corrected_log() -> str:
    """A corrected CARMEN log of RAW and CORRECTED, as a SLAM run writes one."""
    lines = ["# message formats defined: PARAM SYNC ODOM FLASER", "PARAM robot_x 0 nohost 0"]
    restart_raw, restart_pose = None, None
    for t, raw in zip((0.0, 1.0, 2.0, 3.0), RAW):
        pose = raw if restart_raw is None else carmen.compose(
            restart_pose, carmen.relative(restart_raw, raw))
        lines.append(f"ODOM {pose[0]!r} {pose[1]!r} {pose[2]!r} 0.5 0.1 0 {t + 0.01} h {t}")
        if t in CORRECTED:
            x, y, th = CORRECTED[t]
            ranges = " ".join(["1.5", "2.0", "81.83", "0.7"])
            lines.append(f"FLASER 4 {ranges} {x} {y} {th} {x} {y} {th} {t + 0.02} h {t}")
            lines.append(f"ODOM {x} {y} {th} 0 0 0 0 h 0")
            lines.append("NEFF 12.5")
            restart_raw, restart_pose = raw, (x, y, th)
    return "\n".join(lines) + "\n"


def test_the_raw_odometry_is_rebuilt_from_a_corrected_log(tmp_path):
    path = tmp_path / "run.log"
    path.write_text(corrected_log())
    log = carmen.read_log(path)
    assert [s.t for s in log.scans] == [1.02, 3.02]
    assert [s.pose for s in log.scans] == [CORRECTED[1.0], CORRECTED[3.0]]
    np.testing.assert_allclose(log.scans[0].ranges, [1.5, 2.0, 81.83, 0.7], rtol=1e-6)
    rebuilt = [o.pose for o in log.odometry if o.t in (0.01, 1.01, 2.01, 3.01)]
    np.testing.assert_allclose(rebuilt, RAW, atol=1e-12)
    # the restart lines (t = 0) take their scan's time and its raw odometry
    restarts = [o for o in log.odometry if o.t in (1.02, 3.02)]
    np.testing.assert_allclose([o.pose for o in restarts], [RAW[1], RAW[3]], atol=1e-12)
    assert log.left_out == {}


def test_malformed_lines_are_counted_and_a_time_running_back_is_sorted_in(tmp_path):
    text = corrected_log().replace("NEFF 12.5\n", "NEFF 12.5\nFLASER 3 1 2\nODOM 1 x 2\n", 1)
    text += "ODOM 2.8 1.3 0.85 0.2 0 0 2.5 h 2.5\nRLASER 1 1\n"
    path = tmp_path / "run.log.gz"
    path.write_bytes(gzip.compress(text.encode()))
    log = carmen.read_log(path)
    assert log.left_out == {"malformed FLASER lines": 1, "malformed ODOM lines": 1,
                            "RLASER lines (not used)": 1}
    # every line kept: the late one at its own time, between 2.01 and 3.01
    assert log.odometry_reordered == 1
    assert [o.t for o in log.odometry] == [0.01, 1.01, 1.02, 2.01, 2.5, 3.01, 3.02]
    late = log.odometry[4]
    assert late.tv == 0.2
    # rebuilt, as the lines before it, from the last scan's restart
    expected = carmen.compose(RAW[3], carmen.relative(CORRECTED[3.0], (2.8, 1.3, 0.85)))
    np.testing.assert_allclose(late.pose, expected, atol=1e-12)


def test_a_restart_line_with_a_leftover_time_still_takes_its_scans_time(tmp_path):
    # Some corrected logs write 1e-42 or 1.13 rather than 0 on the restart line.
    text = corrected_log().replace(" 0 h 0\n", " 1.08499e-42 h 0\n", 1)
    text = text.replace(" 0 h 0\n", " 1.13 h 0\n", 1)
    assert text.count("1.08499e-42") == text.count(" 1.13 h") == 1
    path = tmp_path / "run.log"
    path.write_text(text)
    log = carmen.read_log(path)
    assert log.odometry_reordered == 0
    restarts = [o for o in log.odometry if o.t in (1.02, 3.02)]
    np.testing.assert_allclose([o.pose for o in restarts], [RAW[1], RAW[3]], atol=1e-12)


def test_a_carmen_log_becomes_a_recording_of_scans_odometry_and_truth(tmp_path, capsys):
    log_path = tmp_path / "run.log"
    log_path.write_text(corrected_log())
    out = tmp_path / "run.mcap"
    cli.main(["carmen", str(log_path), "-o", str(out)])
    assert "range_max 81.83 m" in capsys.readouterr().out
    topics = decoded(out)
    assert {t: len(m) for t, m in topics.items()} == {"/scan": 2, "/ground_truth": 2,
                                                      "/odom": 6, "/tf": 6, "/tf_static": 1}
    scan = topics["/scan"][0][1]
    assert scan.angle_min == pytest.approx(-math.pi / 2)
    assert scan.angle_increment == pytest.approx(math.pi / 4)
    assert scan.range_max == pytest.approx(81.83) and scan.header.frame_id == "laser"
    assert stamp(scan) == pytest.approx(1.02)
    truth = topics["/ground_truth"][1][1]
    assert truth.header.frame_id == "map" and truth.pose.position.x == pytest.approx(2.7)
    assert 2 * math.atan2(truth.pose.orientation.z, truth.pose.orientation.w) \
        == pytest.approx(0.85)
    odom = [m for _, m in topics["/odom"]]
    assert odom[0].header.frame_id == "odom" and odom[0].child_frame_id == "base_link"
    assert [stamp(m) for m in odom] == sorted(stamp(m) for m in odom)
    assert odom[-1].pose.pose.position.x == pytest.approx(RAW[3][0])
    assert odom[0].twist.twist.linear.x == pytest.approx(0.5)
    # The tree a robot records: odom -> base_link at every odometry line, the laser's mount.
    tree = [m.transforms[0] for _, m in topics["/tf"]]
    assert [(t.header.frame_id, t.child_frame_id) for t in tree] == [("odom", "base_link")] * 6
    assert [t.transform.translation.x for t in tree] == \
        [o.pose.pose.position.x for o in odom]
    mount = topics["/tf_static"][0][1].transforms[0]
    assert (mount.header.frame_id, mount.child_frame_id) == ("base_link", "laser")
    assert mount.transform.translation.x == 0.0


def test_laser_ahead_puts_base_link_behind_the_laser(tmp_path):
    """--laser-ahead 0.25: the mount 0.25 m forward; odometry, tree and truth are then
    base_link's, 0.25 m behind the laser's poses along its heading; the scans unchanged."""
    log_path = tmp_path / "run.log"
    log_path.write_text(corrected_log())
    plain, ahead = tmp_path / "plain.mcap", tmp_path / "ahead.mcap"
    cli.main(["carmen", str(log_path), "-o", str(plain)])
    cli.main(["carmen", str(log_path), "-o", str(ahead), "--laser-ahead", "0.25"])
    before, after = decoded(plain), decoded(ahead)
    assert after["/tf_static"][0][1].transforms[0].transform.translation.x == 0.25
    for topic, pose_of in (("/odom", lambda m: m.pose.pose), ("/ground_truth",
                                                               lambda m: m.pose)):
        for (_, laser), (_, base) in zip(before[topic], after[topic]):
            p, q = pose_of(laser), pose_of(base)
            yaw = 2 * math.atan2(p.orientation.z, p.orientation.w)
            assert q.position.x == pytest.approx(p.position.x - 0.25 * math.cos(yaw))
            assert q.position.y == pytest.approx(p.position.y - 0.25 * math.sin(yaw))
    assert [m.ranges for _, m in before["/scan"]] == [m.ranges for _, m in after["/scan"]]


@pytest.mark.parametrize("content", [None, b"not a log\n", b"\x1f\x8b broken gzip"])
def test_a_log_that_cannot_be_read_is_one_line_and_exit_2(tmp_path, capsys, content):
    path = tmp_path / "run.log"
    if content is not None:
        path.write_bytes(content)
    with pytest.raises(SystemExit) as ended:
        cli.main(["carmen", str(path), "-o", str(tmp_path / "run.mcap")])
    assert ended.value.code == 2
    err = capsys.readouterr().err
    assert err.startswith("estimation_import: ") and err.count("\n") == 1


@needs_shared
def test_the_intel_log_keeps_its_real_drift():
    log = carmen.read_log(SHARED / "carmen" / "intel-corrected.log.gz")
    assert len(log.scans) == 910 and log.left_out == {}
    # every ODOM line kept, in time order; the restart lines with a leftover time (1e-42,
    # 1.13) stay at their scans rather than going to the log's start
    assert len(log.odometry) == 14541 and log.odometry_reordered == 840
    times = np.array([o.t for o in log.odometry])
    assert np.all(np.diff(times) >= 0) and times[0] == pytest.approx(0.000246)

    def raw_at(t):
        return log.odometry[np.searchsorted(times, t, "right") - 1].pose

    first, last = log.scans[0], log.scans[-1]
    dead_reckoned = carmen.compose(first.pose, carmen.relative(raw_at(first.t),
                                                               raw_at(last.t)))
    drift = math.hypot(dead_reckoned[0] - last.pose[0], dead_reckoned[1] - last.pose[1])
    assert 50 < drift < 75      # the data's README: 62 m of drift by the end


def stalled_log(times: list[str]) -> str:
    """Scans at ``times`` (as printed), an odometry line before, between and after them."""
    lines = ["ODOM 0 0 0 0 0 0 T h T"]
    for k, t in enumerate(times):
        lines.append(f"FLASER 2 1.0 2.0 {k} 0 0 {k} 0 0 {t} h {t}")
        lines += [f"ODOM {k + 0.5} 0 0 0 0 0 {t} h {t}"] * (k % 2 + 1)
    return "\n".join(lines).replace("T", times[0]) + "\n"


def test_a_log_whose_times_do_not_advance_is_refused_naming_scan_rate(tmp_path, capsys):
    path = tmp_path / "run.log"
    path.write_text(stalled_log(["1.13486e+09"] * 4 + ["1.13487e+09"]))
    with pytest.raises(SystemExit) as ended:
        cli.main(["carmen", str(path), "-o", str(tmp_path / "run.mcap")])
    assert ended.value.code == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "do not advance: 5 scans at 2 distinct times" in err
    assert "--scan-rate HZ" in err
    # half the scans at distinct times is not refused (two lasers, a repeated stamp)
    path.write_text(stalled_log(["1.5", "1.5", "1.6", "1.7"]))
    assert len(carmen.read_log(path).scans) == 4


def test_scan_rate_places_scans_in_log_order_and_odometry_between(tmp_path):
    path = tmp_path / "run.log"
    path.write_text(stalled_log(["1.13486e+09"] * 3))
    log = carmen.read_log(path, scan_rate=10.0)
    t0 = 1.13486e9
    assert log.scan_rate == 10.0
    np.testing.assert_allclose([s.t - t0 for s in log.scans], [0.0, 0.1, 0.2], atol=1e-6)
    assert [s.pose[0] for s in log.scans] == [0.0, 1.0, 2.0]     # the log's order
    # one line before the first scan (in the period before it), one after scan 0, two
    # after scan 1 (thirds of the period), one after the last (in the period after it)
    np.testing.assert_allclose([o.t - t0 for o in log.odometry],
                               [-0.05, 0.05, 0.1 + 0.1 / 3, 0.1 + 0.2 / 3, 0.25],
                               atol=1e-6)
    assert [o.pose[0] for o in log.odometry] == [0.0, 0.5, 1.5, 1.5, 2.5]
    assert log.odometry_reordered == 0


@pytest.mark.parametrize("text, rate, error", [
    ("FLASER 2 1 2 0 0 0 0 0 0 -5 h 0\nFLASER 2 1 2 0 0 0 0 0 0 1 h 1\n", None,
     "a scan at -5 s"),
    ("FLASER 2 1 2 0 0 0 0 0 0 1 h 1\nODOM 0 0 0 0 0 0 3e9 h 0\n", None,
     "an odometry line at 3e+09 s"),
    ("FLASER 2 1 2 0 0 0 0 0 0 1 h 1\nFLASER 2 1 2 0 0 0 0 0 0 1 h 1\n", "1e-300",
     "a scan at 1e+300 s"),
])
def test_a_time_a_ros_stamp_cannot_hold_is_one_line(tmp_path, capsys, text, rate, error):
    path = tmp_path / "run.log"
    path.write_text(text)
    with pytest.raises(SystemExit) as ended:
        cli.main(["carmen", str(path), "-o", str(tmp_path / "run.mcap"),
                  *(["--scan-rate", rate] if rate else [])])
    assert ended.value.code == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and error in err


def test_scan_rate_puts_no_time_below_0(tmp_path):
    path = tmp_path / "run.log"
    path.write_text("ODOM 0 0 0 0 0 0 0 h 0\nFLASER 2 1 2 0 0 0 0 0 0 0 h 0\n"
                    "ODOM 0.5 0 0 0 0 0 0 h 0\nFLASER 2 1 2 1 0 0 1 0 0 0 h 0\n")
    log = carmen.read_log(path, scan_rate=4.0)
    assert [s.t for s in log.scans] == [0.0, 0.25]
    assert [o.t for o in log.odometry] == [0.0, 0.125]


def test_scan_rate_is_a_finite_positive_rate(tmp_path, capsys):
    with pytest.raises(SystemExit) as ended:
        cli.main(["carmen", "run.log", "--scan-rate", "0", "-o", str(tmp_path / "r.mcap")])
    assert ended.value.code == 2 and "--scan-rate must be" in capsys.readouterr().err


def intel_lines() -> list[str]:
    with gzip.open(SHARED / "carmen" / "intel-corrected.log.gz", "rt") as stream:
        return stream.read().splitlines()


def intel_with(tmp_path: Path, rewrite) -> Path:
    """The Intel log with each line (its tokens, and whether it is the first ODOM after a
    FLASER: a restart) rewritten by ``rewrite`` (None: dropped)."""
    out, after_scan = [], False
    for line in intel_lines():
        tokens = line.split()
        restart = after_scan and tokens[0] == "ODOM"
        after_scan = tokens[0] == "FLASER" or (after_scan and tokens[0] != "ODOM")
        new = rewrite(tokens, restart)
        if new is not None:
            out.append(" ".join(new))
    path = tmp_path / "intel.log"
    path.write_text("\n".join(out) + "\n")
    return path


def printed_g(base: float):
    """Times as a log printed with %g would have them: six significant digits."""
    def rewrite(tokens: list[str], restart: bool) -> list[str]:
        if tokens[0] == "FLASER":
            at = 2 + int(tokens[1]) + 6
        elif tokens[0] == "ODOM" and not restart:
            at = 7
        else:
            return tokens
        stamp = f"{base + float(tokens[at]):g}"
        return tokens[:at] + [stamp, tokens[at + 1], stamp]
    return rewrite


@needs_shared
def test_the_intel_log_printed_with_g_is_refused_then_read_at_a_scan_rate(tmp_path, capsys):
    path = intel_with(tmp_path, printed_g(1134863500.0))
    with pytest.raises(carmen.LogError, match="910 scans at 2 distinct times"):
        carmen.read_log(path)
    out = tmp_path / "intel.mcap"
    cli.main(["carmen", str(path), "--scan-rate", "10", "-o", str(out)])
    assert "times placed at 10 Hz from 1134860000.000 s" in capsys.readouterr().out
    original = carmen.read_log(SHARED / "carmen" / "intel-corrected.log.gz")
    log = carmen.read_log(path, scan_rate=10.0)
    times = np.array([s.t for s in log.scans])
    np.testing.assert_allclose(np.diff(times), 0.1, atol=1e-6)
    assert len(log.odometry) == 14541 and log.odometry_reordered == 0
    assert [s.pose for s in log.scans] == [s.pose for s in original.scans]
    # the raw odometry is rebuilt in the log's order whatever its times: the same poses
    for axis in range(3):
        np.testing.assert_allclose(np.sort([o.pose[axis] for o in log.odometry]),
                                   np.sort([o.pose[axis] for o in original.odometry]),
                                   atol=1e-9)
    # and at each scan (the restart line, at the scan's time) the raw odometry there
    odom_times = np.array([o.t for o in log.odometry])
    first, last = (log.odometry[np.searchsorted(odom_times, t, "right") - 1].pose
                   for t in (times[0], times[-1]))
    dead_reckoned = carmen.compose(log.scans[0].pose, carmen.relative(first, last))
    drift = math.hypot(dead_reckoned[0] - log.scans[-1].pose[0],
                       dead_reckoned[1] - log.scans[-1].pose[1])
    assert 50 < drift < 75
    topics = decoded(out)
    assert len(topics["/scan"]) == 910 and len(topics["/odom"]) == 14541
    assert stamp(topics["/scan"][1][1]) - stamp(topics["/scan"][0][1]) \
        == pytest.approx(0.1, abs=1e-6)


def flaser_only_log(odometry: list[tuple[float, float, float]]) -> str:
    """Three scans whose laser poses are CORRECTED-like and whose odometry fields are
    ``odometry``, and no ODOM line (a raw SLAM-benchmark .clf log has this shape)."""
    poses = [(0.0, 0.0, 0.0), (1.1, 0.05, 0.12), (2.7, 1.2, 0.85)]
    lines = ["PARAM robot_frontlaser_offset 0.0 nohost 0"]
    for t, (x, y, th), (ox, oy, oth) in zip((10.0, 10.5, 11.0), poses, odometry):
        lines.append(f"FLASER 3 1.5 2.5 3.5 {x} {y} {th} {ox} {oy} {oth} {t} h {t}")
    return "\n".join(lines) + "\n"


def test_a_flaser_only_log_gives_its_odometry_from_the_odometry_fields(tmp_path, capsys):
    path = tmp_path / "run.clf"
    path.write_text(flaser_only_log(RAW[:3]))
    out = tmp_path / "run.mcap"
    cli.main(["carmen", str(path), "-o", str(out)])
    printed = capsys.readouterr().out
    assert "/odom from the scan lines' odometry fields" in printed
    assert "no /ground_truth" not in printed
    topics = decoded(out)
    odom = [m for _, m in topics["/odom"]]
    assert [stamp(m) for m in odom] == pytest.approx([10.0, 10.5, 11.0])
    np.testing.assert_allclose([(m.pose.pose.position.x, m.pose.pose.position.y,
                                 2 * math.atan2(m.pose.pose.orientation.z,
                                                m.pose.pose.orientation.w)) for m in odom],
                               RAW[:3], atol=1e-9)
    assert odom[1].twist.twist.linear.x == 0.0          # FLASER carries no velocities
    truth = [m for _, m in topics["/ground_truth"]]
    assert [m.pose.position.x for m in truth] == pytest.approx([0.0, 1.1, 2.7])


def test_a_log_whose_laser_pose_is_its_odometry_is_raw_and_has_no_truth(tmp_path, capsys):
    path = tmp_path / "run.clf"
    poses = [(0.0, 0.0, 0.0), (1.1, 0.05, 0.12), (2.7, 1.2, 0.85)]
    path.write_text(flaser_only_log(poses))
    out = tmp_path / "run.mcap"
    cli.main(["carmen", str(path), "-o", str(out)])
    assert "no /ground_truth: the laser pose equals the odometry pose on every scan line" \
        in capsys.readouterr().out
    topics = decoded(out)
    assert sorted(topics) == ["/odom", "/scan", "/tf", "/tf_static"]
    assert len(topics["/scan"]) == 3
    # with ODOM lines that never restart at a scan: raw too, the ODOM poses as they are
    text = path.read_text() + "ODOM 3.0 1.5 0.9 0.3 0.1 0 11.2 h 11.2\n"
    path.write_text(text)
    log = carmen.read_log(path)
    assert not log.corrected and not log.odometry_from_scans
    assert [o.pose for o in log.odometry] == [(3.0, 1.5, 0.9)]
    # one scan whose laser pose is not its odometry's: corrected
    path.write_text(text.replace("2.7 1.2 0.85 2.7", "2.75 1.2 0.85 2.7"))
    assert carmen.read_log(path).corrected


def without_odom(raw_at_scans: list | None = None):
    """The ODOM lines dropped; with ``raw_at_scans``, each FLASER's odometry fields set to
    the raw odometry at that scan (the laser pose stays the corrected one)."""
    scans = iter(raw_at_scans or [])

    def rewrite(tokens: list[str], restart: bool) -> list[str] | None:
        if tokens[0] == "ODOM":
            return None
        if tokens[0] == "FLASER" and raw_at_scans is not None:
            at = 2 + int(tokens[1]) + 3
            return tokens[:at] + [repr(v) for v in next(scans)] + tokens[at + 3:]
        return tokens
    return rewrite


@needs_shared
def test_the_intel_log_without_odom_lines_is_raw_or_corrected_by_its_fields(tmp_path):
    intel = SHARED / "carmen" / "intel-corrected.log.gz"
    # the corrected log's odometry fields repeat the corrected pose: without its ODOM
    # lines (the restarts), nothing says it was corrected
    log = carmen.read_log(intel_with(tmp_path, without_odom()))
    assert not log.corrected and log.odometry_from_scans
    assert {o.t: o.pose for o in log.odometry} == {s.t: s.pose for s in log.scans}
    # the raw odometry at each scan copied into the fields: corrected, with its drift
    placed = carmen.read_log(intel, scan_rate=10.0)     # the restart lines at the scans
    at = {o.t: o.pose for o in placed.odometry}
    raw = [at[s.t] for s in placed.scans]
    log = carmen.read_log(intel_with(tmp_path, without_odom(raw)))
    assert log.corrected and log.odometry_from_scans and len(log.odometry) == 910
    odometry = {o.t: o.pose for o in log.odometry}
    np.testing.assert_allclose([odometry[s.t] for s in log.scans], raw, atol=1e-12)
    first, last = log.scans[0], log.scans[-1]
    dead_reckoned = carmen.compose(first.pose, carmen.relative(odometry[first.t],
                                                               odometry[last.t]))
    assert 50 < math.hypot(dead_reckoned[0] - last.pose[0], dead_reckoned[1] - last.pose[1]) \
        < 75


def robotlaser(ranges, remissions, laser_pose, robot_pose, t, tail="0.3 0.1 0.5 0.2 0.0"):
    """A ROBOTLASER1 line in CARMEN's layout (writelog.c); ``tail``: tv rv
    forward_safety_dist side_safety_dist turn_axis."""
    return " ".join(["ROBOTLASER1 0 -1.0 1.5 0.5 30 0.01 0",
                     str(len(ranges)), *map(str, ranges), str(len(remissions)),
                     *map(str, remissions), *map(repr, laser_pose), *map(repr, robot_pose),
                     tail, repr(t), "myhost", repr(t + 0.001)])


MOUNT = (0.2, 0.0, 0.0)


def test_robotlaser1_lines_are_read_with_the_lasers_own_angles_and_range(tmp_path, capsys):
    path = tmp_path / "run.log"
    lines = [robotlaser([1.0, 30.0, 2.5], [100, 0, 7], carmen.compose(raw, MOUNT), raw, t)
             for t, raw in zip((5.0, 5.1, 5.2), RAW)]
    path.write_text("# ROBOTLASER1 in CARMEN's layout\n" + "\n".join(lines) + "\n")
    out = tmp_path / "run.mcap"
    cli.main(["carmen", str(path), "-o", str(out)])
    printed = capsys.readouterr().out
    assert "range_max 30 m (the laser's maximum_range)" in printed
    assert "/odom from the scan lines' odometry fields" in printed
    # the laser sits 0.2 m ahead of the robot on every line, nothing corrects it: raw
    assert "no /ground_truth: the laser pose is the odometry pose moved by one fixed mount " \
        "(x 0.200 m, y 0.000 m, yaw 0.0000 rad)" in printed
    topics = decoded(out)
    assert sorted(topics) == ["/odom", "/scan", "/tf", "/tf_static"]
    scan = topics["/scan"][1][1]
    assert stamp(scan) == pytest.approx(5.1)
    assert scan.angle_min == pytest.approx(-1.0) and scan.range_max == pytest.approx(30)
    assert scan.angle_increment == pytest.approx(0.5) and scan.angle_max == pytest.approx(0.0)
    np.testing.assert_allclose(scan.ranges, [1.0, 30.0, 2.5])
    np.testing.assert_allclose(scan.intensities, [100, 0, 7])
    odom = [m for _, m in topics["/odom"]]
    np.testing.assert_allclose([(m.pose.pose.position.x, m.pose.pose.position.y)
                                for m in odom], [r[:2] for r in RAW[:3]], atol=1e-9)
    assert odom[2].twist.twist.linear.x == pytest.approx(0.3)
    assert odom[2].twist.twist.angular.z == pytest.approx(0.1)


def test_a_robotlaser1_line_in_another_layout_is_malformed(tmp_path, capsys):
    # One more number before the timestamp (a "turn safety distance"): the host would
    # be read from a number; counted, never guessed at.
    path = tmp_path / "run.log"
    six = robotlaser([1.0, 2.0], [], (0, 0, 0), (0, 0, 0), 5.0, "0.3 0.1 0.5 0.2 0.4 0.0")
    path.write_text(six + "\n" + robotlaser([1.0], [], (0, 0, 0), (0, 0, 0), 5.1) + "\n")
    log = carmen.read_log(path)
    assert len(log.scans) == 1 and log.left_out == {"malformed ROBOTLASER1 lines": 1}
    assert log.scans[0].remissions.size == 0 and log.scans[0].t == 5.1
    path.write_text(six + "\n" + six.replace("ROBOTLASER1 0", "ROBOTLASER1 x") + "\n")
    with pytest.raises(SystemExit) as ended:
        cli.main(["carmen", str(path), "-o", str(tmp_path / "run.mcap")])
    assert ended.value.code == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "no scan line could be read (2 malformed" in err


def as_robotlaser1(tokens: list[str], restart: bool) -> list[str]:
    """A FLASER line as the ROBOTLASER1 line of the same scan (180 beams of 1 degree)."""
    if tokens[0] != "FLASER":
        return tokens
    n = int(tokens[1])
    ranges, poses, rest = tokens[2:2 + n], tokens[2 + n:2 + n + 6], tokens[2 + n + 6:]
    return ["ROBOTLASER1", "0", repr(-math.pi / 2), repr(math.pi), repr(math.pi / n),
            "81.83", "0.01", "0", str(n), *ranges, "0", *poses,
            "0", "0", "0.5", "0.2", "0", *rest]


@needs_shared
def test_the_intel_log_as_robotlaser1_reads_as_its_flaser_lines(tmp_path):
    original = carmen.read_log(SHARED / "carmen" / "intel-corrected.log.gz")
    log = carmen.read_log(intel_with(tmp_path, as_robotlaser1))
    assert log.left_out == {} and log.corrected and len(log.scans) == 910
    assert [s.t for s in log.scans] == [s.t for s in original.scans]
    assert [s.pose for s in log.scans] == [s.pose for s in original.scans]
    np.testing.assert_array_equal(np.stack([s.ranges for s in log.scans]),
                                  np.stack([s.ranges for s in original.scans]))
    assert all(s.angle_min == -math.pi / 2 and s.angle_increment == pytest.approx(math.pi / 180)
               for s in log.scans)
    # the ODOM lines restart after each ROBOTLASER1 as after each FLASER
    assert log.odometry == original.odometry and log.odometry_reordered == 840
    assert log.laser_range_max == 81.83


# --- UTIAS -------------------------------------------------------------------------------

HEADER = "# UTIAS\n# by\n# format\n# columns\n"


def utias_folder(tmp_path: Path) -> Path:
    folder = tmp_path / "dataset"
    folder.mkdir()
    (folder / "Barcodes.dat").write_text(HEADER + "1 5\n2 14\n6 27\n7 54\n")
    (folder / "Landmark_Groundtruth.dat").write_text(
        HEADER + "6 1.0 2.0 0.001 0.001\n7 -1.0 0.5 0.001 0.001\n")
    (folder / "Robot1_Odometry.dat.gz").write_bytes(gzip.compress(
        (HEADER + "10.0 0.1 0.0\n10.5 0.1 0.2\nbad line\n11.0 0.0 0.0\n").encode()))
    (folder / "Robot1_Measurement.dat").write_text(
        HEADER + "10.2 27 2.0 0.1\n10.2 54 3.0 -0.2\n10.2 14 1.0 0.0\n10.7 99 1.0 0.0\n"
                 "10.7 27 1.9 0.12\n")
    (folder / "Robot1_Groundtruth.dat").write_text(
        HEADER + "9.9 0.0 0.0 0.0\n10.4 0.05 0.0 0.0\n11.0 0.1 0.0 0.1\n")
    return folder


def test_a_utias_run_keeps_landmarks_only_and_counts_the_rest(tmp_path):
    run = utias.read_run(utias_folder(tmp_path), 1)
    assert run.landmarks == {6: (1.0, 2.0), 7: (-1.0, 0.5)}
    assert run.detections[:, 1].tolist() == [6, 7, 6]
    assert run.left_out == {"detections of robots": 1, "detections of unknown barcodes": 1,
                            "malformed lines in Robot1_Odometry": 1}
    assert [(t, len(rows)) for t, rows in run.frames()] == [(10.2, 2), (10.7, 1)]


def test_a_utias_run_becomes_odometry_landmark_clouds_and_truth(tmp_path, capsys):
    out = tmp_path / "run.mcap"
    cli.main(["utias", str(utias_folder(tmp_path)), "--robot", "1", "-o", str(out)])
    printed = capsys.readouterr().out
    assert "left out: 1 detections of robots" in printed
    topics = decoded(out)
    assert {t: len(m) for t, m in topics.items()} == {
        "/odom": 3, "/landmark_observations": 2, "/ground_truth": 3}
    cloud = topics["/landmark_observations"][0][1]
    assert stamp(cloud) == pytest.approx(10.2) and cloud.width == 2
    assert [f.name for f in cloud.fields] == ["x", "y", "z", "id"]
    points = np.frombuffer(bytes(cloud.data), dtype=[("x", "<f4"), ("y", "<f4"),
                                                     ("z", "<f4"), ("id", "<u4")])
    np.testing.assert_allclose(points["x"], [2.0 * math.cos(0.1), 3.0 * math.cos(-0.2)],
                               rtol=1e-6)
    np.testing.assert_allclose(points["y"], [2.0 * math.sin(0.1), 3.0 * math.sin(-0.2)],
                               rtol=1e-6)
    assert points["id"].tolist() == [6, 7]
    odom = topics["/odom"][1][1]
    assert odom.twist.twist.angular.z == pytest.approx(0.2)
    assert odom.pose.pose.position.x == pytest.approx(0.05)      # 0.5 s at 0.1 m/s
    landmarks = (tmp_path / "run.landmarks.yaml").read_text()
    assert "{id: 6, x: 1.0, y: 2.0}" in landmarks


def test_a_missing_robot_file_is_one_line_and_exit_2(tmp_path, capsys):
    with pytest.raises(SystemExit) as ended:
        cli.main(["utias", str(utias_folder(tmp_path)), "--robot", "2", "-o",
                  str(tmp_path / "run.mcap")])
    assert ended.value.code == 2
    assert "Robot2_Odometry" in capsys.readouterr().err
