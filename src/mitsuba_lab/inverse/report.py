"""What an inversion writes: CSVs, images, plots and the report (Markdown + HTML).

``OUTDIR/optimisation.csv`` (``OPT_COLUMNS``, one row per iteration), ``OUTDIR/gradients.csv``
(``GRAD_COLUMNS``, one row per sampler x spp), the initial / target / final renders as EXR
and PNG, and ``OUTDIR/report/index.html`` (self-contained) + ``summary.md`` with the plots
beside them, in the sweep report's format (``mitsuba_lab.reporting``).
"""
from __future__ import annotations

import math
import os
import statistics

import numpy as np

from ..reporting import dict_rows, fmt, markdown_table, pyplot, save_figure, save_loglog, write_csv, \
    write_markdown_page
from .config import InverseConfig
from .gradients import GRAD_COLUMNS, GradientSweep, best_sampler
from .optimise import OptimisationResult
from .scenes import film_of

OPT_COLUMNS = ("iteration", "loss", "param_error", "time_s", "iteration_s", "loss_eval")


def plot_convergence(rows, path: str, title: str) -> None:
    """Loss (with the untimed fixed-seed evaluation loss) and parameter error against
    iteration and against optimisation time, log scale."""
    plt = pyplot()
    fig, axes = plt.subplots(2, 2, figsize=(9, 6.4), dpi=100)
    it = [r["iteration"] for r in rows]
    t = [r["time_s"] for r in rows]
    for col, (x, xlabel) in enumerate(((it, "iteration"), (t, "optimisation wall time (s)"))):
        for row, (name, ylabel) in enumerate((("loss", "loss"), ("param_error", "parameter RMS error"))):
            ax = axes[row][col]
            ax.plot(x, [max(r[name], 1e-12) for r in rows], marker=".", ms=3,
                    label="this iteration's render" if name == "loss" else None)
            if name == "loss" and any(math.isfinite(r.get("loss_eval", math.nan)) for r in rows):
                ax.plot(x, [max(r["loss_eval"], 1e-12) for r in rows], marker=".", ms=3,
                        label="fixed-seed evaluation render (untimed)")
                ax.legend(fontsize=7)
            ax.set_yscale("log")
            ax.set_xlabel(xlabel)
            ax.set_ylabel(ylabel)
            ax.grid(True, which="both", alpha=0.3)
    fig.suptitle(title, fontsize=10)
    save_figure(fig, path)


def plot_images(result: OptimisationResult, path: str, texture_key: str | None) -> None:
    """The initial, target and final renders (sRGB), and for a texture parameter the initial,
    true and final textures (gamma 2.2)."""
    from ..images import srgb_preview

    plt = pyplot()
    panels = [(result.images[k], f"{k} render") for k in ("initial", "target", "final")]
    if texture_key:
        for label, values in (("initial", result.init), ("true", result.truth), ("final", result.final)):
            panels.append((np.clip(values[texture_key], 0, 1) ** (1 / 2.2), f"{label} texture", ))
    cols = 3
    rows = (len(panels) + cols - 1) // cols
    fig, axes = plt.subplots(rows, cols, figsize=(3 * cols, 3.1 * rows), dpi=100, squeeze=False)
    for ax, (image, label) in zip(axes.flat, panels):
        shown = srgb_preview(image) if "render" in label else image
        ax.imshow(shown, interpolation="nearest")
        ax.set_title(label, fontsize=9)
    for ax in axes.flat:
        ax.set_xticks([])
        ax.set_yticks([])
    save_figure(fig, path)


def plot_gradients(sweep: GradientSweep, path: str) -> None:
    """Relative MSE of the gradient against time per sampler, each point labelled by its spp."""
    plt = pyplot()
    fig, ax = plt.subplots(figsize=(6.4, 4.2), dpi=100)
    for name in dict.fromkeys(p.sampler for p in sweep.points):
        pts = sorted((p for p in sweep.points if p.sampler == name and p.status == "ok"), key=lambda p: p.time_s)
        if pts:
            ax.plot([p.time_s for p in pts], [p.rel_mse for p in pts], marker="o", label=name)
            for p in pts:
                ax.annotate(f"{p.spp}", (p.time_s, p.rel_mse), fontsize=7, xytext=(3, 3), textcoords="offset points")
    save_loglog(fig, ax, path, "median wall time of one gradient: forward + backward (s)",
                "relative MSE of dLoss/dtheta", f"gradient error against time ({sweep.key}); labels: spp",
                legend_size=8, title_size=9)


def optimisation_markdown(cfg: InverseConfig, result: OptimisationResult, plots: list[str]) -> str:
    rows = result.rows
    total = rows[-1]["time_s"]
    ratio = lambda start, end: f"{fmt(start / max(end, 1e-30))}x"          # noqa: E731
    quantities = [
        ["parameter RMS error", fmt(result.error_start, 4), fmt(result.error_end, 4),
         ratio(result.error_start, result.error_end)],
        ["loss (noisy iteration render)", fmt(rows[0]["loss"], 4), fmt(rows[-1]["loss"], 4),
         ratio(rows[0]["loss"], rows[-1]["loss"])],
        [f"loss of the fixed-seed evaluation render ({cfg.eval_spp} spp)", fmt(rows[0]["loss_eval"], 4),
         fmt(rows[-1]["loss_eval"], 4), ratio(rows[0]["loss_eval"], rows[-1]["loss_eval"])]]
    lines = [f"## Optimisation: {', '.join(f'`{k}`' for k in cfg.keys)}", "",
             f"prb, max_depth {cfg.max_depth}, {cfg.spp} spp per iteration, Adam lr {cfg.learning_rate}, "
             f"{cfg.iterations} iterations, loss `{cfg.loss}`, values clamped to each parameter's "
             f"[min, max]; target rendered at the true values with {cfg.target_spp} spp.",
             "", *markdown_table(["quantity", "start", "end", "ratio"], quantities), "",
             f"Optimisation wall time {total:.3g} s ({result.compile_note}); median iteration "
             f"{statistics.median([r['iteration_s'] for r in rows[1:]]) if len(rows) > 1 else math.nan:.3g} s."]
    if all(np.asarray(v).size <= 4 for v in result.truth.values()):
        show = lambda a: ", ".join(f"{x:.4f}" for x in np.asarray(a).ravel())     # noqa: E731
        lines += ["", *markdown_table(["key", "initial", "final", "true"],
                                      [[key, show(result.init[key]), show(result.final[key]), show(result.truth[key])]
                                       for key in cfg.keys])]
    lines += [""] + [f"![{alt}]({os.path.basename(p)})" for alt, p in plots]
    return "\n".join(lines)


def gradients_markdown(cfg: InverseConfig, sweep: GradientSweep, plot: str) -> str:
    spec = cfg.gradients
    ref_norm2 = max(float(np.sum(sweep.reference ** 2)), 1e-300)
    lines = [f"## Gradient variance against time: `{sweep.key}`", "",
             f"At the start point, loss `{sweep.loss}` against a {cfg.target_spp}-spp target; prb, max_depth "
             f"{cfg.max_depth}, {'x'.join(map(str, film_of(cfg)))}. Reference gradient: mean of "
             f"{spec.reference_seeds} gradients at {spec.reference_spp} spp (Mitsuba independent), "
             f"|g_ref| = {fmt(float(np.linalg.norm(sweep.reference)), 4)} (standard error "
             f"{fmt(sweep.reference_sem)}). Per point: {spec.seeds} seeds after one warm-up; "
             "time = median wall time of forward + backward; variance = sum over components of the "
             "variance across seeds; rel. variance = variance / |g_ref|^2; efficiency = "
             "1 / (rel. variance x time). The gradient is unbiased (primal and gradient pass use "
             "decorrelated seeds, every sampler is randomised), so its variance is its MSE; relMSE = "
             "mean |g - g_ref|^2 / |g_ref|^2 also contains the reference's own noise "
             f"(relative {fmt(sweep.reference_sem ** 2 / ref_norm2)}) "
             "and is shown as a check; rel. bias^2 = (|mean g - g_ref|^2 - variance / seeds) / |g_ref|^2 "
             "(noise: can be < 0).", "",
             *markdown_table(["sampler", "spp", "time (s)", "rel. variance", "rel. bias^2", "relMSE", "efficiency",
                              "status"],
                             [[p.sampler, p.spp, fmt(p.time_s), fmt(p.rel_variance), fmt(p.bias2 / ref_norm2),
                               fmt(p.rel_mse), fmt(p.efficiency), p.status] for p in sweep.points])]
    best = best_sampler(sweep.points)
    if best:
        lines += ["", f"Most gradient accuracy per second: **{best[0]}** (efficiency {fmt(best[1])})."]
    if sweep.notes:
        lines += [""] + [f"Note: {n}" for n in sweep.notes]
    lines += ["", f"![gradient relMSE against time]({os.path.basename(plot)})"]
    return "\n".join(lines)


def write_report(folder: str, title: str, sections: list[str]) -> dict[str, str]:
    """``folder/report/summary.md`` and ``index.html``: ``title`` and the sections."""
    return write_markdown_page(os.path.join(folder, "report"), title, "\n\n".join([f"# {title}"] + sections))


def texture_key(cfg: InverseConfig, result: OptimisationResult) -> str | None:
    """The first optimised key whose value is an image (a texture), if any."""
    for key in cfg.keys:
        if np.asarray(result.truth[key]).ndim == 3:
            return key
    return None


def write_optimisation(cfg: InverseConfig, result: OptimisationResult, folder: str) -> tuple[str, list[str]]:
    """CSV, EXR + PNG images and plots of one optimisation; returns (markdown, files)."""
    from .. import images

    report_dir = os.path.join(folder, "report")
    os.makedirs(report_dir, exist_ok=True)
    files = [os.path.join(folder, "optimisation.csv")]
    write_csv(files[0], OPT_COLUMNS, dict_rows(result.rows, OPT_COLUMNS))
    for name, image in result.images.items():
        exr = os.path.join(folder, f"{name}.exr")
        images.write_exr(exr, image, {"mitsuba_lab.inverse": name, "mitsuba_lab.config": cfg.source})
        images.write_png(os.path.splitext(exr)[0] + ".png", image)
        files.append(exr)
    conv = os.path.join(report_dir, "convergence.png")
    plot_convergence(result.rows, conv, f"{cfg.name}: loss and parameter error")
    strip = os.path.join(report_dir, "images.png")
    plot_images(result, strip, texture_key(cfg, result))
    files += [conv, strip]
    md = optimisation_markdown(cfg, result, [("loss and parameter error against iteration and time", conv),
                                             ("initial, target and final renders", strip)])
    return md, files


def write_gradients(cfg: InverseConfig, sweep: GradientSweep, folder: str) -> tuple[str, list[str]]:
    """gradients.csv and the gradient plot; returns (markdown, files)."""
    report_dir = os.path.join(folder, "report")
    os.makedirs(report_dir, exist_ok=True)
    csv_path = os.path.join(folder, "gradients.csv")
    write_csv(csv_path, GRAD_COLUMNS, dict_rows([p.as_row() for p in sweep.points], GRAD_COLUMNS))
    plot = os.path.join(report_dir, "gradients.png")
    plot_gradients(sweep, plot)
    return gradients_markdown(cfg, sweep, plot), [csv_path, plot]


def format_gradient_table(sweep: GradientSweep) -> str:
    """The gradient sweep as a fixed-width text table for the terminal."""
    head = f"{'sampler':<16} {'spp':>5} {'time_s':>9} {'rel_var':>10} {'rel_mse':>10} {'efficiency':>11}"
    lines = [f"gradient of {sweep.loss} loss w.r.t. {sweep.key}:", head]
    for p in sweep.points:
        if p.status != "ok":
            lines.append(f"{p.sampler:<16} {p.spp:>5} {p.status}")
            continue
        lines.append(f"{p.sampler:<16} {p.spp:>5} {p.time_s:>9.4f} {p.rel_variance:>10.3g} {p.rel_mse:>10.3g} "
                     f"{p.efficiency:>11.4g}")
    best = best_sampler(sweep.points)
    if best:
        lines.append(f"most gradient accuracy per second: {best[0]} (efficiency {best[1]:.4g})")
    lines += [f"note: {n}" for n in sweep.notes]
    return "\n".join(lines)
