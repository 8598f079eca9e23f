"""Relighting, point splatting, output images and charts."""
