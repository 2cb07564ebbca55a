"""Stages: ``run_*(paths, config)`` functions that read inputs, estimate and write artifacts."""
