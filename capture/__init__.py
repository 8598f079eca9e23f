"""Sweep plans, capture sessions and the dataset format."""
