"""The guard-advice study on a tiny field of the simulator's own family."""

from __future__ import annotations

from pathlib import Path

from bench.guard_advice import advice_records, format_advice
from core.directions import hemisphere_layout
from core.field_store import ReflectanceField
from sim.field import field_cameras, simulate_field
from sim.skies import procedural_sky


def test_each_firing_is_scored_on_test_lights_under_both_advices(tmp_path: Path) -> None:
    views = field_cameras(4, width=24, height=24)
    simulate_field(tmp_path / "fit.zarr", "glossy-sphere", lights=12, cameras=views, points=400,
                   layout="fibonacci")  # fmt: skip
    simulate_field(tmp_path / "test.zarr", "glossy-sphere", lights=hemisphere_layout(4, "grid"),
                   cameras=views, points=400)  # fmt: skip
    fit, test = (ReflectanceField.open(tmp_path / n) for n in ("fit.zarr", "test.zarr"))
    sky = {"sunny": procedural_sky(32, sun_share=0.9)}
    records = advice_records("glossy sphere", "own family", fit, test, sky)
    codes = {r["warning"] for r in records}
    assert "ghosting" in codes and "sun-ghosting" in codes  # 12 lights against a 30 deg lobe
    for r in records:
        # The simulator's material is the model: the held-out comparison finds it, and the
        # new advice (the models) is the old one, better than interpolating on test lights.
        assert r["models_win_held_out"] and r["new_advice"] == r["old_advice"] < r["in_use"]
        assert "relight through the per-sample models" in r["message"]
    table = format_advice(records)
    assert f"{len(records)} firings: the old advice made 0 worse, the new advice 0." in table
