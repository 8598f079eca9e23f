"""``rig demo``: the demonstration pipeline (application layer, like :mod:`rig.cli`).

For now it covers the environment-lighting half of the method on the bundled panorama: samples
it with every sampler and several K, disassembles the light, and writes the pictures and a
report. Later stages (simulated capture, processing, relighting) join it as they land.
"""

from __future__ import annotations

import time
from importlib import resources
from pathlib import Path

from tqdm import tqdm

from rig.atomic import atomic_path

__all__ = ["DEMO_KS", "bundled_panorama_path", "run_demo"]

DEMO_KS = (8, 64, 256)


def bundled_panorama_path() -> Path:
    """Path of the sample panorama shipped with the package (see its ATTRIBUTION.md)."""
    return Path(str(resources.files("processing") / "data" / "courtyard.exr"))


def run_demo(directory: str | Path) -> Path:
    """Write the demo outputs under ``directory``; returns the path of ``report.md``."""
    import numpy as np

    from processing.environment import LightingControls
    from processing.panorama import read_panorama
    from processing.sampling import SAMPLERS
    from render.lighting_outputs import write_lighting_outputs

    out = Path(directory)
    panorama = read_panorama(bundled_panorama_path())
    runs: list[tuple[str, LightingControls]] = [
        (f"tmed-k{k}", LightingControls(k=k)) for k in DEMO_KS
    ]
    runs += [(f"{m}-k64", LightingControls(k=64, method=m)) for m in SAMPLERS if m != "tmed"]
    runs.append(("paper-tmed-k64", LightingControls(k=64, paper=True)))
    runs.append(("tmed-k64-yaw90", LightingControls(k=64, yaw_deg=90.0)))
    lines = [
        "# Demo report",
        "",
        f"Panorama: `{panorama.source}` ({panorama.width}x{panorama.height}).",
        "",
        "| run | K | seconds | total light R, G, B (radiance x sr) | pictures |",
        "|---|---|---|---|---|",
    ]
    for name, controls in tqdm(runs, desc="sampling", unit="run"):
        start = time.perf_counter()
        lighting = write_lighting_outputs(panorama, controls, out / "sampling" / name)
        seconds = time.perf_counter() - start
        total = ", ".join(f"{v:.4f}" for v in np.sum(lighting.lights.rgb, axis=0))
        lines.append(
            f"| {name} | {lighting.lights.k} | {seconds:.3f} | {total} | "
            f"[overlay](sampling/{name}/overlay.png), [lights](sampling/{name}/lights.png) |"
        )
    lines += ["", "Every run gathers the same total light: disassembling conserves energy.", ""]
    report = out / "report.md"
    with atomic_path(report) as temporary:
        temporary.write_text("\n".join(lines), encoding="utf-8")
    return report
