"""Synthetic sensors: ground-truth device trajectories and the IMU streams a phone would report."""
