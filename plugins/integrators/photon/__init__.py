"""``lab_photon``: progressive photon mapping in Dr.Jit, split by role.

* ``estimator``: what lab_photon knows without rendering (the scenes it can render, what a
  sweep's sample count sets), needing no Mitsuba variant;
* ``records``: the photon records (structure of arrays) and their memory cost;
* ``grid``: the hashed uniform grid, built by a counting sort;
* ``tracer``: the photon pass (emitters chosen by power, BSDF-sampled light paths);
* ``gather``: the camera pass (camera paths through delta lobes) and the kernel density
  estimate;
* ``spectral``: one set of wavelengths per pass for photons and camera rays (spectral
  variants);
* ``integrator``: the driver (passes, radius schedule, batching) and its settings;
  it registers the plugin on its last line.
"""
