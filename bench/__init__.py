"""Benchmarks: programs that measure and print figures, saved as JSON and charts."""
