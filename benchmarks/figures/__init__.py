"""Figures: the workshop's plots, the flight, consistency and replay figures
(a module each), and the 3-D attitude animation. Built on matplotlib's
``Figure`` (no pyplot) and seaborn's styles."""
