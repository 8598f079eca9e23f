"""Relighting engines and their modes, splat plans, sequences, outputs, guards, the advisor."""
