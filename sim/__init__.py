"""The simulated world: device emulators, synthetic scenes and camera, ground truth, Mitsuba."""
