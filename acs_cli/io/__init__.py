"""File formats: trajectories, YAML/NPZ artifacts and exports (never prints)."""
