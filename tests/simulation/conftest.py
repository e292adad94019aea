"""Fixtures of the simulation tests."""
