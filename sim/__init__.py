"""The simulated rig, synthetic scenes and the ground-truth renderer."""
