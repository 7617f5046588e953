"""Batched nonlinear Kalman filters and the multiple-initial-value bank (see shared/spec/trackers.md)."""
