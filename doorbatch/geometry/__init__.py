"""Rigid-body geometry: quaternions, SE(2)/SE(3) helpers, the TF buffer, laser scan points."""
