"""The relighting engines: a field, a lighting and a view in, a relit image out.

- :mod:`render.engines.panorama_lit`: what every engine shares about a panorama (the user's
  controls, applied once);
- :mod:`render.engines.interpolated`: the paper's engine, interpolating the measured values
  (its sums and camera blending in :mod:`render.engines.paper_sums`);
- :mod:`render.engines.models`: through the fitted per-sample models (their shading under a
  set of lights in :mod:`render.engines.model_shading`);
- :mod:`render.engines.predicted`: through any light predictor (fields of pixels);
- :mod:`render.engines.modes`: which of them a field gets, and opening it.

One relighting request runs through them in :mod:`render.relighting`.
"""
