"""The plot renders a run to a valid PNG of the documented size."""

import struct

import numpy as np

from estimation_nodes.core.tiles import histogram
from estimation_nodes.core.tiles.models import HistogramModel
from estimation_nodes.tools.plot.estimator import DPI, FIGURE_INCHES, render
from estimation_nodes.tools.recording.run_record import RunRecord


def png_size(path):
    data = path.read_bytes()
    assert data[:8] == b"\x89PNG\r\n\x1a\n", "not a PNG"
    assert data[12:16] == b"IHDR"
    width, height = struct.unpack(">II", data[16:24])
    return width, height, len(data)


def example_6_14_record() -> RunRecord:
    model, record = HistogramModel.book(), RunRecord()
    belief = histogram.uniform(5)
    for step, observed in enumerate(["bright", "dark", "dark"], start=1):
        belief = histogram.predict(belief, 1, model.kernel)
        record.predicted.append(belief)
        belief, _ = histogram.correct(belief, model.likelihood(observed))
        record.corrected.append(belief)
        record.truth.append(step)
        record.measurements.append(step + 0.3)
        record.kalman.append((step + 0.1, 4.0 / step))
    return record


def test_render_writes_a_png_of_the_expected_size(tmp_path):
    out = render(example_6_14_record(), tmp_path / "sub" / "run.png")
    width, height, size = png_size(out)
    assert (width, height) == (int(FIGURE_INCHES[0] * DPI), int(FIGURE_INCHES[1] * DPI))
    assert size > 20_000   # bars, lines and text, not a blank canvas


def test_render_copes_with_a_run_without_beliefs_or_estimates(tmp_path):
    record = RunRecord()
    record.kalman = [(1.0, 2.0), (2.0, 1.5)]
    width, height, _ = png_size(render(record, tmp_path / "kalman_only.png"))
    assert (width, height) == (1600, 1200)
    width, height, _ = png_size(render(RunRecord(), tmp_path / "empty.png"))
    assert (width, height) == (1600, 1200)


def test_long_runs_show_at_most_twelve_evenly_spread_steps():
    from estimation_nodes.tools.plot.estimator import _chosen_steps

    assert _chosen_steps(5) == [0, 1, 2, 3, 4]
    steps = _chosen_steps(40)
    assert len(steps) == 12 and steps[0] == 0 and steps[-1] == 39
    assert np.all(np.diff(steps) > 0)


def test_render_draws_each_step_s_settled_belief_when_one_was_republished(tmp_path):
    from tests.unit.test_run_record import localizing_run_with_a_republication

    record = localizing_run_with_a_republication()
    width, height, size = png_size(render(record, tmp_path / "republished.png"))
    assert (width, height) == (1600, 1200) and size > 20_000
