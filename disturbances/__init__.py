"""Disturbance database (see the disturbance-database issue)."""
