"""``lab_bdpt``: bidirectional path tracing with every (s, t) strategy under one MIS.

* ``recursion``: the multiple-importance weights of every strategy of a path, computed in O(1)
  per connection from running quantities per subpath vertex (Georgiev 2012, as SmallVCM
  writes it); ``weights``: the lab's extensions to it, each a layer (strategy subsets,
  connection counts, merging from the second camera vertex, caustic-only merges, per-lane
  radii), plus a brute-force reference; no Mitsuba variant needed, on numpy or Dr.Jit arrays.
* ``endpoints``: the emitters' emission and emitter-sampling densities and the sensor's
  direction density, which the weights need and Mitsuba does not return.
* ``light_subpath``: light subpaths in one symbolic loop, the t = 1 strategy (light tracing)
  splatted on the way (``splats``: the film block and its edge correction), and the storage of
  connectable vertices (``vertices``); ``render_light_tracing`` renders light tracing alone.
* ``camera_subpath``: camera subpaths and the s = 0, s = 1 and s, t >= 2 strategies.
* ``media_paths``: both subpaths and every strategy in scenes with homogeneous media (compiled
  only for those: the loops above stay surface-only).
* ``integrator``: passes sized to ``max_vertices``, the two images, the plugin; ``passes``: what
  a plugin built on it (lab_vcm) sets for each pass; ``estimator``: what lab_bdpt can render,
  without a variant;
* ``techniques``: the techniques as flags and a strategy as (s, t), parsed once from what users
  write, without a variant.
"""
