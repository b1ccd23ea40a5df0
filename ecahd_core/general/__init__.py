"""The generalist (map-conditioned) Sparse Diffusion of issue 40: one SD model that sees the map
and plans on buildings it never saw.

- :mod:`~ecahd_core.general.views`: a planning problem (grid, start, goal) as the fixed-size,
  metric, frame-independent images the model sees, and the affine map between world metres and
  the view's normalised coordinates [-1, 1]^2 (pure numpy).
- :mod:`~ecahd_core.general.model`: the map-conditioned denoiser (the Transformer of
  :mod:`~ecahd_core.diffusion.denoiser` with cross-attention to map tokens computed once per
  plan).
- :mod:`~ecahd_core.general.data`: the generalist dataset (generated maps of every family x A*
  expert problems, stored as views + waypoints in view coordinates, in resumable shards).
- :mod:`~ecahd_core.general.train`: its training (batches of K maps x M problems, the global
  CNN once per distinct view; the 8 symmetries of the square; resumable bit for bit), behind
  ``ecahd train-general``.
- :mod:`~ecahd_core.general.checkpoint`: the generalist checkpoint (model and view config, EMA
  weights, training state).
"""
