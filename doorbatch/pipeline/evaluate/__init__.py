"""Metrics against a reference: door maps, static maps, trajectories."""
