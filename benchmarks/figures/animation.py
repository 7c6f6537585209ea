"""The spacecraft seen in 3-D, true and estimated attitude together (the workshop's steps 1–2).

The body is a box (the bus) with two solar panels along its body y axis and
its three body axes drawn as arrows; each frame rotates it by ``R(q)``
(body → reference) for the true and, if given, the estimated attitude. The
estimate is drawn as a translucent orange ghost over the solid truth.
"""
from __future__ import annotations

import numpy as np
from matplotlib.animation import FuncAnimation, PillowWriter
from matplotlib.figure import Figure
from matplotlib.patches import Patch
from mpl_toolkits.mplot3d.art3d import Poly3DCollection

from benchmarks.output import atomic_path, write_figure
from benchmarks.figures.plots import freeze_layout
from dynamics.quaternion import rotation_matrix
from dynamics.validation import InvalidParameterError

TITLE = "Spacecraft Attitude"
TRUE_STYLE = {"facecolor": "#4C72B0", "edgecolor": "#1b2a44", "alpha": 0.9}
ESTIMATE_STYLE = {"facecolor": "#DD8452", "edgecolor": "#8a4a1f", "alpha": 0.35}
AXIS_COLOURS = ("#d62728", "#2ca02c", "#1f77b4")   # body x, y, z
#: Body axes reach past the solar panels (which end at y = ±1.5) so all three show.
AXIS_LENGTH = 1.8


def _box(center, half_sizes):
    """The 6 faces (each 4x3 corners) of an axis-aligned box."""
    cx, cy, cz = center
    hx, hy, hz = half_sizes
    corners = np.array([[cx + sx * hx, cy + sy * hy, cz + sz * hz]
                        for sx in (-1, 1) for sy in (-1, 1) for sz in (-1, 1)])
    faces = ((0, 1, 3, 2), (4, 5, 7, 6), (0, 1, 5, 4), (2, 3, 7, 6), (0, 2, 6, 4), (1, 3, 7, 5))
    return [corners[list(face)] for face in faces]


def spacecraft_faces() -> np.ndarray:
    """Body-frame polygons: a 1.0 x 0.7 x 0.5 bus and two thin panels on ±y."""
    bus = _box((0, 0, 0), (0.5, 0.35, 0.25))
    panel_half = (0.3, 0.55, 0.01)
    panels = _box((0, 0.95, 0), panel_half) + _box((0, -0.95, 0), panel_half)
    return np.array(bus + panels)


class AttitudeView:
    """A 3-D axes showing the spacecraft at the true (and estimated) attitude."""

    def __init__(self, figure: Figure, with_estimate: bool):
        self.ax = figure.add_subplot(projection="3d")
        self.faces = spacecraft_faces()
        self.with_estimate = with_estimate
        self.true_body = Poly3DCollection(self.faces, **TRUE_STYLE)
        self.ax.add_collection3d(self.true_body)
        self.true_axes = [self.ax.plot([], [], [], color=c, linewidth=2.5)[0]
                          for c in AXIS_COLOURS]
        handles = [Patch(**TRUE_STYLE, label="True")]
        if with_estimate:
            self.est_body = Poly3DCollection(self.faces, **ESTIMATE_STYLE)
            self.ax.add_collection3d(self.est_body)
            self.est_axes = [self.ax.plot([], [], [], color=c, linewidth=1.5, linestyle="--")[0]
                             for c in AXIS_COLOURS]
            handles.append(Patch(**ESTIMATE_STYLE, label="Estimated"))
        limit = AXIS_LENGTH
        for setter in (self.ax.set_xlim, self.ax.set_ylim, self.ax.set_zlim):
            setter(-limit, limit)
        self.ax.set_box_aspect((1, 1, 1))
        self.ax.set_xlabel("x")
        self.ax.set_ylabel("y")
        self.ax.set_zlabel("z")
        self.ax.legend(handles=handles, loc="upper left")
        figure.suptitle(TITLE, fontsize=14)
        self.subtitle = self.ax.set_title("Time = 0.0 s")

    def _place(self, body, axes, q):
        rotation = rotation_matrix(q)
        body.set_verts(self.faces @ rotation.T)
        for column, line in enumerate(axes):
            tip = AXIS_LENGTH * rotation[:, column]
            line.set_data_3d([0, tip[0]], [0, tip[1]], [0, tip[2]])

    def show(self, time_s: float, q_true, q_est=None):
        self._place(self.true_body, self.true_axes, q_true)
        diverged = self.with_estimate and not np.isfinite(q_est).all()
        if self.with_estimate:
            # A diverged estimator (NaN) has no attitude to draw: it vanishes.
            self.est_body.set_visible(not diverged)
            for line in self.est_axes:
                line.set_visible(not diverged)
            if not diverged:
                self._place(self.est_body, self.est_axes, q_est)
        self.subtitle.set_text(f"Time = {time_s:.1f} s" + (" (estimate diverged)" if diverged
                                                             else ""))


def frame_indices(n_steps: int, every: int) -> np.ndarray:
    """Every ``every``-th step, always including the last."""
    if isinstance(every, bool) or not isinstance(every, (int, np.integer)) or every < 1:
        raise InvalidParameterError("every", every, "must be a whole number >= 1")
    indices = np.arange(0, n_steps, every)
    return indices if indices[-1] == n_steps - 1 else np.append(indices, n_steps - 1)


def write_attitude_animation(time_s, q_true, q_est, gif_path, png_path, every: int = 50,
                             fps: int = 10, progress_bar=None) -> int:
    """Animate the attitude to ``gif_path`` and save its last frame to ``png_path``.

    ``q_est`` may be None (truth alone). Returns the number of frames.
    """
    indices = frame_indices(len(time_s), every)
    figure = Figure(figsize=(6, 6), layout="constrained")
    view = AttitudeView(figure, with_estimate=q_est is not None)

    def update(i):
        k = indices[i]
        view.show(time_s[k], q_true[k], None if q_est is None else q_est[k])
        if progress_bar is not None:
            progress_bar.update()

    update(0)
    freeze_layout(figure)
    animation = FuncAnimation(figure, update, frames=len(indices), blit=False)
    with atomic_path(gif_path) as temporary:
        animation.save(temporary, writer=PillowWriter(fps=fps), dpi=80)
    view.show(time_s[indices[-1]], q_true[indices[-1]],
              None if q_est is None else q_est[indices[-1]])
    write_figure(png_path, figure, dpi=100)
    return len(indices)
