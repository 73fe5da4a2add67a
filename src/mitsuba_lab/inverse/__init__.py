"""prb inverse-rendering demos: optimisation, finite-difference checks, gradient variance.

``mitsuba-lab invert CONFIG.toml -o OUTDIR`` reads one TOML file (``config``) and runs

* an **optimisation** (``[optimise]``, ``optimise``): ``mi.ad.Adam`` on the chosen scene
  parameters with Mitsuba's ``prb``, from ``init`` towards a target rendered at the true
  values, every iteration timed and logged to ``OUTDIR/optimisation.csv``;
* a **gradient sweep** (``[gradients]``, ``gradients``): at the start point, the gradient
  dLoss/dtheta for each sampler x spp over ``seeds`` seeds, timed, against a high-spp
  reference gradient, written to ``OUTDIR/gradients.csv``.

Both end in a report in the sweep runner's format (``report``): ``OUTDIR/report/index.html``
(self-contained), ``OUTDIR/report/summary.md`` and the CSVs.

Modules, by role: ``config`` (the TOML schema), ``scenes`` (scene building, the builtin
``cornell_texture``, parameters as numpy), ``prb`` (rendering and losses), ``optimise``
(the Adam loop and its timing), ``gradients`` (gradient variance against time, finite
differences), ``report`` (CSVs, plots, Markdown and HTML). The command's options and what it
prints: ``commands.invert``.
"""
from __future__ import annotations

from .config import load_config, parse_config
from .gradients import best_sampler, finite_difference, gradient, gradient_sweep
from .optimise import optimise
from .prb import loss_function, make_prb, render_image
from .report import format_gradient_table, write_gradients, write_optimisation, write_report
from .scenes import load_inverse_scene, select_params, set_values, start_and_truth, to_numpy, truth_texture

__all__ = ["load_config", "parse_config", "optimise", "gradient", "gradient_sweep",
           "finite_difference", "best_sampler", "loss_function", "make_prb", "render_image", "load_inverse_scene",
           "select_params", "set_values", "start_and_truth", "to_numpy", "truth_texture", "write_optimisation",
           "write_gradients", "write_report", "format_gradient_table"]
