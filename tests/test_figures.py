"""Figures a reader can read: checked on the figure objects themselves —
where the legends sit, what the axes are called, whether tick labels
collide, whether coinciding curves are named, what the axes' ranges hold."""
import math

import numpy as np
import pandas as pd
import pytest
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.text import Text

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


def lines_by_gid(figure, prefix: str) -> dict:
    """``{gid: (axes, line)}`` of the figure's lines whose gid starts with ``prefix``."""
    return {line.get_gid(): (ax, line) for ax in figure.axes for line in ax.get_lines()
            if (line.get_gid() or "").startswith(prefix)}


def assert_shown(ax, line, share: float = 0.99):
    """The line is drawn opaque enough to see, and (nearly) all of its finite
    values (on a log axis, its positive ones) lie inside the axes' y limits."""
    assert line.get_visible() and (line.get_alpha() is None or line.get_alpha() >= 0.9)
    values = np.asarray(line.get_ydata(), dtype=float)
    values = values[np.isfinite(values) & ((values > 0) | (ax.get_yscale() != "log"))]
    low, high = ax.get_ylim()
    assert values.size and np.mean((values >= low) & (values <= high)) >= share


def assert_texts_do_not_overlap(figure):
    """No two visible, non-empty texts of the figure (titles, labels, tick
    labels, legend entries, annotations) overlap."""
    renderer = figure.canvas.get_renderer()
    boxes = [(text.get_text(), text.get_window_extent(renderer))
             for text in figure.findobj(Text)
             if text.get_visible() and text.get_text().strip() and text.axes is not None]
    for i, (first, a) in enumerate(boxes):
        for second, b in boxes[i + 1:]:
            overlap_x = min(a.x1, b.x1) - max(a.x0, b.x0)
            overlap_y = min(a.y1, b.y1) - max(a.y0, b.y0)
            assert overlap_x <= 1 or overlap_y <= 1, f"{first!r} overlaps {second!r}"


@pytest.mark.slow
def test_every_estimator_of_the_comparison_can_be_seen(smallsat_run):
    figure = drawn(flight_comparison_figure(smallsat_run))
    assert_legends_outside_the_panels(figure)
    names = list(smallsat_run.labels)
    errors = lines_by_gid(figure, "error ")
    for name in names:
        for axis in range(3):
            ax, line = errors[f"error {name} {axis}"]
            # Its own panel: no other estimator's error drawn over it.
            assert [gid for gid, (other, _) in errors.items() if other is ax] == \
                [f"error {name} {axis}"]
            assert_shown(ax, line)
    # The rows share one scale, so a glance down a column compares them.
    first = errors[f"error {names[0]} 0"][0]
    assert all(ax.get_ylim() == first.get_ylim() for ax, _ in errors.values())
    assert first.get_ylabel().startswith("Dead Reckoning")
    words = texts(figure)
    assert "Body x error" in words and "Roll" not in words
    # The comparison panel: every estimator's total error, log scale; USQUE,
    # which coincides with the MEKF, dashed over it and named.
    totals = lines_by_gid(figure, "total ")
    assert {ax for ax, _ in totals.values()} == {figure.axes[0]}
    assert figure.axes[0].get_yscale() == "log"
    for name in names:
        assert_shown(*totals[f"total {name}"])
    _, mekf = totals["total mekf"]
    _, usque = totals["total usque"]
    assert usque.get_linestyle() != mekf.get_linestyle() and usque.get_zorder() > mekf.get_zorder()
    assert "USQUE (UKF) under MEKF: differ by <" in words
    for ax, _ in errors.values():
        assert_tick_labels_do_not_collide(ax)
    # The bias panels hold every estimate from the start (the initial transient).
    bias_ax, _ = lines_by_gid(figure, "bias mekf")["bias mekf 0"]
    estimate = smallsat_run.traces["mekf"].bias_radps[:, 0] * 180 / np.pi * 3600
    low, high = bias_ax.get_ylim()
    assert low <= estimate.min() and estimate.max() <= high


def synthetic_flight(names, steps: int = 600):
    """Inputs of :func:`flight_figure`: ``names`` with errors from 1e-4° (the
    last two equal) to 1°, an eclipse in the middle third and readings rejected."""
    rng = np.random.default_rng(1)
    time_s = np.linspace(0.0, 600.0, steps)
    scales = np.geomspace(1.0, 1e-4, len(names) - 1)
    errors, sigmas = {}, {}
    for name, scale in zip(names, [*scales, scales[-1]]):
        errors[name] = scale * rng.standard_normal((steps, 3))
        sigmas[name] = np.full((steps, 3), scale)
    errors[names[-1]] = errors[names[-2]] + 1e-9        # coincides with the one before
    eclipse = (time_s > 200) & (time_s < 400)
    rejected = {names[2]: np.array([50, 51, 300])}
    bias_truth = np.full((steps, 3), 0.1)
    biases = {names[-1]: (bias_truth + 0.01, np.full((steps, 3), 0.01))}
    return (time_s, errors, sigmas, bias_truth, biases, {name: name.upper() for name in names}), \
        {"eclipse": eclipse, "rejected": rejected}


def test_many_estimators_each_in_its_row_with_eclipses_and_rejections():
    from benchmarks.figures.flight import flight_figure
    names = ["triad", "quest", "ekf", "mekf", "usque"]
    args, kwargs = synthetic_flight(names)
    figure = drawn(flight_figure(*args, **kwargs))
    assert_legends_outside_the_panels(figure)
    errors = lines_by_gid(figure, "error ")
    for name in names:
        ax, line = errors[f"error {name} 0"]
        assert [gid for gid, (other, _) in errors.items() if other is ax] == [f"error {name} 0"]
        assert_shown(ax, line)
        assert_tick_labels_do_not_collide(ax)
    # Eclipse shaded in every panel; the rejected readings on the EKF's curves only.
    for ax in figure.axes:
        assert any(patch.get_label() == "Eclipse" or patch.get_x() == pytest.approx(
            args[0][kwargs["eclipse"]][0], abs=2) for patch in ax.patches)
    marked = [ax for ax in figure.axes for line in ax.get_lines()
              if line.get_marker() == "x" and len(line.get_xdata()) == 3]
    assert sorted(marked, key=id) == sorted((errors[f"error ekf {axis}"][0] for axis in range(3)),
                                            key=id)
    legend = [text.get_text() for text in figure.legends[0].get_texts()]
    assert "Eclipse" in legend and any("rejected by gating" in entry for entry in legend)
    assert "USQUE under MEKF: differ by < 4e-06″" in texts(figure)     # 1e-9°
    assert_texts_do_not_overlap(figure)


def test_without_a_bias_estimate_there_is_no_bias_column():
    run = simulate(SMALLSAT.replace(tstop=5.0), ["ekf"], seed=0, traces=True)
    figure = flight_comparison_figure(run)
    assert len(figure.axes) == 4                # the comparison, and the EKF's row of three
    assert "gyro bias" not in texts(figure)


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


def test_the_consistency_figure_shows_every_anees_whole_and_the_settle_time(tmp_path):
    from benchmarks.experiments.consistency import figure, run_consistency
    result = run_consistency(Scenario(tstop=10.0), ["ekf", "mekf"], 20)
    fig = drawn(figure(result))
    assert_legends_outside_the_panels(fig)
    assert_texts_do_not_overlap(fig)
    traces = lines_by_gid(fig, "anees ")
    for name in ("ekf", "mekf"):
        ax, line = traces[f"anees {name}"]
        # The whole ANEES, not clipped to the band: the workshop EKF's (about
        # 4e-4) lies far below its band and is drawn where it is.
        np.testing.assert_array_equal(line.get_ydata(), result.anees[name])
        assert_shown(ax, line, share=1.0)
        low, high = result.summary[name]["anees_low"], result.summary[name]["anees_high"]
        bottom, top = ax.get_ylim()
        assert bottom < low and high < top
        # Where the time averages start, marked.
        settle = [line for line in ax.get_lines() if line.get_gid() == "settle"]
        assert len(settle) == 1 and list(settle[0].get_xdata()) == [result.settle_s] * 2
        # Its time average and verdict, as the table gives them, above it.
        assert f"ANEES {result.summary[name]['anees']:.3g}, {result.summary[name]['verdict']}" \
            in ax.get_title(loc="left")
    mekf_ax = traces["anees mekf"][0]
    bottom, top = mekf_ax.get_ylim()
    assert top / bottom < 20                    # a consistent filter's band readable
    assert "95 % χ² band" in texts(fig)
    for ax in fig.axes:
        if ax.get_ylabel():                     # (each row's first panel)
            assert [t for t in ax.get_yticklabels() if t.get_text()], "every scale is labelled"
    # The bound's ±3σ is an envelope: no drop at a reading step.
    bound_line = [line for line in fig.axes[0].get_lines()
                  if line.get_label().startswith("best achievable")][0]
    # (20 steps a reading; without the envelope the σ drops 3 % at each.)
    values = np.asarray(bound_line.get_ydata())[100:]
    assert np.max(np.abs(np.diff(values))) < 0.01 * values.max()


def test_anees_far_off_the_band_is_drawn_and_its_value_legible():
    from benchmarks.figures.consistency import consistency_figure
    rng = np.random.default_rng(2)
    time_s = np.linspace(0.0, 100.0, 200)
    levels = {"a": 3.0, "b": 120.0, "c": 150.0, "d": 0.01}     # three off one band's scale
    anees = {name: level * (1 + 0.1 * rng.standard_normal(200)) ** 2
             for name, level in levels.items()}
    bands = {name: (2.0, 4.2) for name in levels}
    steps = np.linspace(0.0, 100.0, 400)
    errors = {name: 1e-3 * rng.standard_normal((400, 3)) for name in levels}
    sigmas = {name: np.full((400, 3), 1e-3) for name in levels}
    fig = drawn(consistency_figure(time_s, anees, bands, errors, sigmas,
                                   np.full((400, 3), 1e-3), steps,
                                   {name: name.upper() for name in levels},
                                   runs={name: 20 for name in levels}))
    assert_texts_do_not_overlap(fig)
    for name in levels:
        candidates = [(ax, line) for ax in fig.axes for line in ax.get_lines()
                      if len(line.get_ydata()) == 200 and np.array_equal(line.get_ydata(),
                                                                         anees[name])]
        assert len(candidates) == 1, f"{name}'s ANEES drawn as it is, once"
        assert_shown(*candidates[0], share=1.0)


def test_the_tuning_figure_holds_every_evaluation_and_marks_the_default():
    from benchmarks.experiments.estimator_tuning import EstimatorTuning, tuning_figure
    losses = [9.0, 7.5, 0.31, math.inf, 0.4, 0.25, 0.22, 0.21] + [0.2] * 40
    tuning = EstimatorTuning(
        estimator="mekf", objective="std", parameters=["gyro_noise"], scales=["log"],
        ranges=[(1e-12, 1e-6)], default={"gyro_noise": 1e-9}, tuned={"gyro_noise": 1e-8},
        loss_default=9.0, loss=0.2, method="Nelder-Mead",
        evaluations=[{"count": i + 1, "values": {}, "loss": loss}
                     for i, loss in enumerate(losses)],
        iterations=[], message="", cases=["seed 0"])
    time_s = np.linspace(0.0, 10.0, 50)
    fig = drawn(tuning_figure(tuning, time_s, {"default": np.ones(50), "tuned": np.ones(50)}))
    loss_ax = fig.axes[0]
    low, high = loss_ax.get_ylim()
    shown = [line for line in loss_ax.get_lines() if line.get_label() == "evaluation"]
    values = np.concatenate([line.get_ydata() for line in shown])
    assert sorted(values) == sorted(loss for loss in losses if math.isfinite(loss))
    assert low < min(values) and max(values) < high
    diverged = [line for line in loss_ax.get_lines() if line.get_gid() == "diverged"]
    assert len(diverged) == 1 and low < diverged[0].get_ydata()[0] < high
    default = [line for line in loss_ax.get_lines() if line.get_gid() == "default"]
    assert len(default) == 1 and list(default[0].get_ydata()) == [9.0, 9.0]
    assert_legends_outside_the_panels(fig)


def test_montecarlo_shows_rms_in_arcsec_on_a_log_axis_when_estimators_differ():
    frame = pd.DataFrame({"run": np.tile(np.arange(20), 2),
                          "estimator": ["dead-reckoning"] * 20 + ["mekf"] * 20})
    rng = np.random.default_rng(0)
    for column in ("rms_deg", "std_deg", "max_deg"):
        frame[column] = np.concatenate([0.1 + 0.01 * rng.random(20), 0.002 + 1e-4 * rng.random(20)])
    fig = drawn(distribution_figure(frame))
    assert fig.axes[0].get_title() == "RMS error"
    assert fig.axes[0].get_ylabel() == "arcsec (log scale)"


def test_sweep_and_animation_name_their_units(tmp_path, monkeypatch):
    from benchmarks.cli import main
    from benchmarks.experiments import runs
    drawn, real = [], runs.figure_bytes
    monkeypatch.setattr(runs, "figure_bytes",
                        lambda path, figure, *args: drawn.append(figure) or real(path, figure,
                                                                                 *args))
    assert main(["sweep", "--estimator", "ekf", "--param", "gyro-noise", "--values",
                 "1e-5,2e-5", "--tstop", "2", "--out", str(tmp_path), "--quiet"]) == 0
    # Each curve of the figure's legend names its value with the unit.
    legends = drawn[0].legends + [ax.get_legend() for ax in drawn[0].axes if ax.get_legend()]
    texts = [text.get_text() for legend in legends for text in legend.get_texts()]
    assert sum(text.endswith(" rad^2/s") for text in texts) == 2, texts
    from matplotlib.figure import Figure
    from benchmarks.figures.animation import AttitudeView
    view = AttitudeView(Figure(), with_estimate=False)
    assert view.subtitle.get_text().endswith(" s")


def test_the_blitting_gif_writer_writes_what_pillow_would_write(tmp_path):
    # Its frames get their palettes in a worker while the next is drawn; the
    # file must be the one Pillow's GIF writer makes from the same RGBA frames.
    from PIL import Image
    from benchmarks.figures.plots import BlittingPillowWriter, new_figure
    figure, (ax,) = new_figure(width=3.0, height=2.0)
    line, = ax.plot(np.linspace(0, 1, 50), np.zeros(50))
    ax.set_ylim(-1, 1)
    writer = BlittingPillowWriter([line], fps=5)
    rgba = []
    with writer.saving(figure, tmp_path / "a.gif", 50):
        for phase in range(4):
            line.set_ydata(np.sin(np.linspace(0, 6, 50) + phase))
            writer.grab_frame()
            canvas = figure.canvas
            rgba.append(Image.frombuffer("RGBA", canvas.get_width_height(),
                                         bytes(canvas.buffer_rgba()), "raw", "RGBA", 0, 1))
    rgba[0].save(tmp_path / "b.gif", save_all=True, append_images=rgba[1:], duration=200, loop=0)
    written = (tmp_path / "a.gif").read_bytes()
    assert written == (tmp_path / "b.gif").read_bytes()
    assert Image.open(tmp_path / "a.gif").n_frames == 4       # the frames differ: none merged
