"""``lab_photon``: progressive photon mapping in Dr.Jit, split by role.

* ``estimator``: what lab_photon knows without rendering (the scenes it can render, what a
  sweep's sample count sets), needing no Mitsuba variant;
* ``records``: the photon records (structure of arrays) and their memory cost;
* ``grid``: the photon map of a pass, in ``common``'s hashed grid;
* ``tracer``: the photon pass (emitters chosen by power, BSDF-sampled light paths, the
  adjoint correction of ``common.adjoint``);
* ``gather``: the camera pass (camera paths through delta lobes) and the kernel density
  estimate;
* ``integrator``: the driver (passes, radius schedule, batching) and its settings;
  it registers the plugin on its last line.
"""
