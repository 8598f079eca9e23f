"""What every package shares: conventions, camera, colour, errors, IO, BRDF, splats, field store."""
