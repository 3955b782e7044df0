"""Gymnasium environment RocketRoll-v0 (see the environment issue)."""
