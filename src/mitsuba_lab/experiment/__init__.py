"""Strategy sweeps, laid out as the data flows.

``pipeline``: config -> plan -> reference -> run -> store (with identity, validate, budget);
``execution``: how a point renders (worker, executors, render_process, progressive, the strategy
grid); ``report``: what is made of the stored results (analysis, the report's sections, viewer,
figure). ``sweep`` wires them together; ``api`` is ``mitsuba_lab.sweep``.
"""
