"""Figures: the workshop's plots, the flight and consistency figures, and the
3-D attitude animation. Built on matplotlib's ``Figure`` (no pyplot) and
seaborn's styles."""
