"""``lab_bdpt`` (bidirectional path tracing), built in steps; not a plugin yet.

* ``weights``: the multiple-importance weights of every (s, t) strategy of a path, computed in
  O(1) per connection from two running quantities per subpath vertex (Georgiev 2012), plus a
  brute-force reference; no Mitsuba variant needed, on numpy or Dr.Jit arrays.
* ``light_subpath``: light subpaths in one symbolic loop and the t = 1 strategy (light
  tracing), with ``render_light_tracing``; checked against Mitsuba's ``ptracer``.

Still to come: storing light vertices, camera subpaths and their connections (s >= 1, t >= 2),
exact emission and camera densities for the weights of those strategies, and the plugin.
"""
