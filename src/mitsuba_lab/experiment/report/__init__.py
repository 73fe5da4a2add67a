"""The sweep report, made from stored results only (it never renders).

``build`` (``Report``: results.csv, index.html, summary.md), ``sections`` (the parts of a
scene's section, in order, each with ``applies`` and ``render``), ``tables``, ``bias`` and
``veach`` (the tables those sections draw), ``analysis`` and ``verdicts`` (statistics over the
seeds, and when a difference is resolved), ``comparisons`` (which renders are compared),
``spectrum`` (error spectra and slopes), ``viewer`` + ``viewer.js`` (the comparison viewer),
``figure`` (``report --figure``), ``browser`` and ``viewer_shots`` (the page in headless
Chromium).
"""
