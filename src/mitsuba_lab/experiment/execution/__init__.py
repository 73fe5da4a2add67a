"""How a sweep's renders execute: ``worker`` (one point's seeds, timed), ``progressive`` (one
accumulating render per seed), ``executors`` (in this process, in a render process of the sweep's
own, ``render_process``, or on a Dask cluster) and ``strategy_grid`` (lab_bdpt's per-strategy
images)."""
