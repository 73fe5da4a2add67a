"""``lab_bdpt`` (bidirectional path tracing), built in steps; only its MIS weights exist so far.

* ``weights``: the multiple-importance weights of every (s, t) strategy of a path, computed in
  O(1) per connection from two running quantities per subpath vertex (Georgiev 2012), plus a
  brute-force reference; no Mitsuba variant needed, on numpy or Dr.Jit arrays.

The integrator itself (subpath tracing, connections, light-tracing splats) is not written yet.
"""
