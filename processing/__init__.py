"""Panorama I/O, importance sampling, light disassembling and reflectance-field processing."""
