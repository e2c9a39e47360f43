"""Tuning: warm-up adaptation of step size, mass, field and trajectory length."""
