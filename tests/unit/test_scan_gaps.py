"""nodes/scan_gaps: scans missed between those received, by their stamps."""

from __future__ import annotations

from estimation_nodes.nodes.scan_gaps import LONGEST_GAP, ScanGaps

MS = 1_000_000


def test_the_driver_s_scan_time_gives_the_period():
    gaps = ScanGaps()
    received = [0, 100, 400, 500, 1000]           # ms; a scan every 100 ms was made
    assert [gaps.note(t * MS, 0.1) for t in received] == [0, 0, 2, 0, 4]
    assert gaps.missed == 6


def test_without_scan_time_nothing_is_counted_but_every_scan_received():
    gaps = ScanGaps()
    # Irregular times (a thinned-out log): no period to count by.
    assert [gaps.note(t * MS, 0.0) for t in [0, 300, 400, 700, 725, 775]] == [0] * 6
    assert (gaps.missed, gaps.received) == (0, 6)


def test_jitter_is_not_a_missed_scan():
    gaps = ScanGaps()
    assert [gaps.note(t * MS, 0.1) for t in [0, 104, 196, 310, 395]] == [0] * 5


def test_time_going_back_a_pause_and_unstamped_scans_count_nothing():
    gaps = ScanGaps()
    assert gaps.note(5000 * MS, 0.1) == 0
    assert gaps.note(1000 * MS, 0.1) == 0                   # a recording played again
    assert gaps.note(None, 0.1) == 0
    assert gaps.note((1000 + 100 * (LONGEST_GAP + 2)) * MS, 0.1) == 0   # a pause
    assert gaps.missed == 0
