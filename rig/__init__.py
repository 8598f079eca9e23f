"""Rig hardware, configuration, geometry and the project's shared conventions."""
