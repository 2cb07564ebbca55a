"""Synthetic articulated camera systems: trajectories, sample recordings and the demo."""
