"""``mitsuba-lab invert CONFIG``: prb inverse-rendering demos and gradient variance against time
(``mitsuba_lab.inverse``); here its options and what it prints."""
from __future__ import annotations

import os

from ..errors import LabError

EPILOG = """config tables: [scene] path | builtin ("cornell_texture"), resolution, texture_size, defaults;
[render] max_depth (required), spp, target_spp, seed; [optimise] iterations, learning_rate,
loss (l2 | relative_l2), eval_spp; [parameters."KEY"] init, min, max, truth; [gradients] key, spp, samplers,
seeds, reference_spp, reference_seeds. Defaults and meanings: src/mitsuba_lab/inverse/config.py."""


def add_arguments(parser) -> None:
    """Arguments of ``mitsuba-lab invert``."""
    parser.description = ("Inverse rendering with Mitsuba's prb: optimise scene parameters from a target "
                          "rendered at known values ([optimise]) and/or measure the gradient's variance "
                          "against time per sampler x spp ([gradients]); writes CSVs, images, plots and a "
                          "report (HTML + Markdown).")
    parser.epilog = EPILOG
    parser.add_argument("config", help="inverse-rendering TOML file (experiments/inverse_*.toml)")
    parser.add_argument("-o", "--output", help="output folder (default: the config's experiment.output)")
    parser.add_argument("--iterations", type=int, help="override optimise.iterations (>= 0)")
    parser.add_argument("--skip-optimise", action="store_true", help="do not run the [optimise] part")
    parser.add_argument("--skip-gradients", action="store_true", help="do not run the [gradients] part")


def run(args, out) -> int:
    """``mitsuba-lab invert``: returns the exit status; errors are LabError (one line, exit 2)."""
    import dataclasses

    from ..inverse.config import load_config
    from ..inverse.report import write_report
    from ..progress import ProgressBar

    cfg = load_config(args.config)
    if args.iterations is not None:
        if args.iterations < 0:
            raise LabError(f"--iterations must be >= 0, got {args.iterations}")
        cfg = dataclasses.replace(cfg, iterations=args.iterations, optimise=True)
    folder = args.output or cfg.output
    os.makedirs(os.path.join(folder, "report"), exist_ok=True)
    if not os.access(folder, os.W_OK):
        raise LabError(f"output folder is not writable: {folder}")
    run_opt = cfg.optimise and not args.skip_optimise
    run_grad = cfg.gradients is not None and not args.skip_gradients
    if not (run_opt or run_grad):
        raise LabError(f"{cfg.source}: nothing to run (no [optimise] or [gradients] table, or both skipped)")
    bar = ProgressBar()
    try:
        sections = run_parts(cfg, folder, run_opt, run_grad, bar, out)
    finally:
        bar.close()                                        # (Ctrl-C: no live bar left mid-line)
    paths = write_report(folder, f"Inverse rendering: {cfg.name}", sections)
    print(f"wrote {paths['html']}, {paths['md']} and the CSVs in {folder}", file=out)
    return 0


def run_parts(cfg, folder: str, run_opt: bool, run_grad: bool, bar, out) -> list[str]:
    """The optimisation and the gradient sweep, as asked, their results written; their
    report sections (Markdown)."""
    from ..inverse.gradients import gradient_sweep
    from ..inverse.optimise import optimise
    from ..inverse.report import format_gradient_table, write_gradients, write_optimisation

    sections = []
    if run_opt:
        bar.begin(cfg.iterations, f"optimising {', '.join(cfg.keys)} ({cfg.iterations} iterations)")
        result = optimise(cfg, lambda i, n, row: bar.step(f"loss {row['loss']:.4g} error {row['param_error']:.4g}"))
        sections.append(write_optimisation(cfg, result, folder)[0])
        print(f"{cfg.name}: parameter RMS error {result.error_start:.4g} -> {result.error_end:.4g} "
              f"({result.error_start / max(result.error_end, 1e-30):.3g}x) in {cfg.iterations} iterations, "
              f"{result.rows[-1]['time_s']:.3g} s", file=out)
    if run_grad:
        sweep = gradient_sweep(cfg, lambda i, n, label: (bar.begin(n, "gradient sweep") if i == 1 else None,
                                                         bar.step(label)))
        sections.append(write_gradients(cfg, sweep, folder)[0])
        print(format_gradient_table(sweep), file=out)
    return sections

