"""Decoding, calibration, field building, panoramas, sampling, lighting, interpolation, models."""
