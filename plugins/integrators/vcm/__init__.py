"""``lab_vcm``: vertex connection and merging (Georgiev, Krivanek, Davidovic & Slusallek 2012).

Built on ``lab_bdpt`` (its subpaths, light vertices, connections and weights, which carry the
merging terms) and on ``common``'s counting-sort grid, as ``lab_photon``'s photon map:

* ``merging``: the grid over a pass's light vertices and the merging estimate at a camera vertex;
* ``volume_merging``: the same in participating media (balls around medium vertices);
* ``integrator``: the plugin (one pass per sample, the radius schedule, the modes);
* ``pilot``: the pilot's renders and the render it chooses; ``selection``: its choice, without a
  variant;
* ``estimator``: what lab_vcm can render, without a variant.
"""
