"""A sweep from its config to its stored results: config -> plan -> reference -> run -> store.

``config`` (the TOML schema), ``validate`` (every plugin instantiated before anything renders),
``reference_choice`` (a reference that renders every feature of its scene), ``plan`` (the points),
``reference`` (the content-addressed reference cache), ``run`` (``SweepRunner``: references, then
the points, resumable), ``store`` (results.jsonl and the images), ``identity`` (what determines
a run), ``budget`` (a time budget's tolerance: a point rendered again or marked).
"""
