"""Figures a reader can read: checked on the figure objects themselves —
where the legends sit, what the axes are called, whether tick labels
collide, whether coinciding curves are named, what the axes' ranges hold."""
import numpy as np
import pandas as pd
import pytest
from matplotlib.backends.backend_agg import FigureCanvasAgg

from benchmarks import Scenario, simulate
from benchmarks.experiments.runs import flight_comparison_figure
from benchmarks.figures.plots import distribution_figure
from benchmarks.figures.style import coinciding, symlog_axis, upper_envelope

SMALLSAT = Scenario.from_toml("scenarios/smallsat.toml").replace(tstop=40.0)


def drawn(figure):
    FigureCanvasAgg(figure).draw()
    return figure


def texts(figure) -> str:
    """Every text of the figure, legends' included, as one string."""
    parts = [t.get_text() for t in figure.findobj(lambda a: hasattr(a, "get_text"))]
    return " ".join(parts)


def assert_legends_outside_the_panels(figure):
    assert figure.legends, "one legend for the figure"
    renderer = figure.canvas.get_renderer()
    for legend in figure.legends:
        box = legend.get_window_extent(renderer)
        for ax in figure.axes:
            assert ax.get_legend() is None
            assert not box.overlaps(ax.get_window_extent(renderer)), "legend over a panel"


def assert_tick_labels_do_not_collide(ax):
    renderer = ax.figure.canvas.get_renderer()
    boxes = sorted((label.get_window_extent(renderer) for label in ax.get_yticklabels()
                    if label.get_visible() and label.get_text()), key=lambda b: b.y0)
    for lower, upper in zip(boxes, boxes[1:]):
        assert upper.y0 >= lower.y1 - 0.5, "two y tick labels overlap"


@pytest.fixture(scope="module")
def smallsat_run():
    return simulate(SMALLSAT, ["dead-reckoning", "ekf", "mekf", "usque"], seed=0, traces=True)


def test_the_per_axis_comparison_reads_as_the_issue_asks(smallsat_run):
    figure = drawn(flight_comparison_figure(smallsat_run))
    assert_legends_outside_the_panels(figure)
    words = texts(figure)
    assert "Body x error (arcsec)" in words and "Roll" not in words
    # USQUE coincides with the MEKF: drawn in its own line style, and named.
    assert "USQUE (UKF) under MEKF: differ by <" in words
    lines = {line.get_label(): line for line in figure.axes[0].get_lines()}
    assert lines["USQUE (UKF)"].get_linestyle() != lines["MEKF"].get_linestyle()
    # Each filter's ±3σ band is in the legend, in its own colour.
    labels = [text.get_text() for text in figure.legends[0].get_texts()]
    assert "EKF ±3σ" in labels and "MEKF ±3σ" in labels
    for ax in figure.axes[::2]:
        assert_tick_labels_do_not_collide(ax)
    # The bias panels hold every estimate from the start (the initial transient).
    bias_ax = figure.axes[1]
    estimate = smallsat_run.traces["mekf"].bias_radps[:, 0] * 180 / np.pi * 3600
    low, high = bias_ax.get_ylim()
    assert low <= estimate.min() and estimate.max() <= high


def test_without_a_bias_estimate_there_is_no_bias_column():
    run = simulate(SMALLSAT.replace(tstop=5.0), ["ekf"], seed=0, traces=True)
    figure = flight_comparison_figure(run)
    assert len(figure.axes) == 3


def test_symlog_ticks_are_powers_of_ten_and_zero():
    from matplotlib.figure import Figure
    figure = Figure(figsize=(4, 3))
    ax = figure.subplots()
    ax.plot([0, 1], [-3e5, 3e5])
    symlog_axis(ax, 7.3, 3e5)
    ticks = ax.get_yticks()
    assert 0.0 in ticks and 1.0 in ticks and 1e4 in ticks
    assert len(ticks) <= 9                  # every other decade beyond four
    drawn(figure)
    assert_tick_labels_do_not_collide(ax)


def test_an_envelope_goes_through_the_peaks_not_the_sawtooth():
    sawtooth = np.tile([1.0, 2.0, 3.0, 0.5], 25)           # grows, drops at a reading
    envelope = upper_envelope(sawtooth, 5)
    assert envelope[5:-5].min() == 3.0


def test_curves_that_agree_to_a_tolerance_are_found_and_others_not():
    base = np.linspace(0, 1, 50)
    under = coinciding({"a": base, "b": base + 1e-7, "c": base + 0.1}, 1e-6)
    assert under == {"b": ("a", pytest.approx(1e-7))}


def test_the_consistency_figure_keeps_every_estimator_readable(tmp_path):
    from benchmarks.experiments.consistency import figure, run_consistency
    result = run_consistency(Scenario(tstop=10.0), ["ekf", "mekf"], 20)
    fig = drawn(figure(result))
    assert_legends_outside_the_panels(fig)
    anees_ax = fig.axes[0]
    low, high = result.summary["mekf"]["anees_low"], result.summary["mekf"]["anees_high"]
    bottom, top = anees_ax.get_ylim()
    assert bottom < low and high < top and top / bottom < 20     # the band readable
    words = texts(fig)
    # The workshop EKF's ANEES (about 4e-4) lies far below: marked at the edge with its value.
    assert "EKF: " in words and "↓" in words
    assert "95 % band" in words
    for ax in fig.axes:
        assert [t for t in ax.get_yticklabels() if t.get_text()], "every axis has tick labels"
    # The bound's ±3σ is an envelope: no drop at a reading step.
    bound_line = [line for line in fig.axes[1].get_lines()
                  if line.get_label().startswith("best achievable")][0]
    # (20 steps a reading; without the envelope the σ drops 3 % at each.)
    values = np.asarray(bound_line.get_ydata())[100:]
    assert np.max(np.abs(np.diff(values))) < 0.01 * values.max()


def test_montecarlo_shows_rms_in_arcsec_on_a_log_axis_when_estimators_differ():
    frame = pd.DataFrame({"run": np.tile(np.arange(20), 2),
                          "estimator": ["dead-reckoning"] * 20 + ["mekf"] * 20})
    rng = np.random.default_rng(0)
    for column in ("rms_deg", "std_deg", "max_deg"):
        frame[column] = np.concatenate([0.1 + 0.01 * rng.random(20), 0.002 + 1e-4 * rng.random(20)])
    fig = drawn(distribution_figure(frame))
    assert fig.axes[0].get_title() == "RMS error"
    assert fig.axes[0].get_ylabel() == "arcsec (log scale)"


def test_sweep_and_animation_name_their_units(tmp_path):
    from benchmarks.cli import main
    assert main(["sweep", "--estimator", "ekf", "--param", "gyro-noise", "--values",
                 "1e-5,2e-5", "--tstop", "2", "--out", str(tmp_path), "--quiet"]) == 0
    from benchmarks.experiments.runs import SWEEP_PARAMETERS
    assert SWEEP_PARAMETERS["gyro-noise"].unit == "rad^2/s"
    from matplotlib.figure import Figure
    from benchmarks.figures.animation import AttitudeView
    view = AttitudeView(Figure(), with_estimate=False)
    assert view.subtitle.get_text().endswith(" s")
