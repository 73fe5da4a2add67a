"""One scene checked: every strategy that applies, measured and judged against the reference
(the package doc says how)."""
from __future__ import annotations

import os

import numpy as np

from .. import metrics
from ..film import resolution_text
from .measure import measure
from .render import bias_ladder, is_consistent, render_ladder, render_splits
from .scenes import load_check_scene, references
from .verdicts import Rung, Verdict, empty_pixels, judge, judge_consistent, twin_status

#: name -> (integrator type, parameters); max_depth comes from --max-depth.
PATH_STRATEGIES = {
    "lab_naive": ("lab_naive", {}),
    "lab_nee": ("lab_nee", {}),
    "lab_mis_power": ("lab_mis", {"heuristic": "power"}),
    "lab_mis_balance": ("lab_mis", {"heuristic": "balance"}),
}
#: The bidirectional and density-estimation strategies: lab_bdpt and lab_vcm's bpt are unbiased
#: (the z-test), lab_vcm's vcm and ppm and lab_photon consistent (bias^2 shrinking). lab_photon's
#: sample count is its passes (``Estimator.SAMPLE_COUNT_PARAMETER``), of fewer photons than its
#: default: check's images are small.
BIDIRECTIONAL_STRATEGIES = {
    "lab_bdpt": ("lab_bdpt", {}),
    "lab_vcm_bpt": ("lab_vcm", {"mode": "bpt"}),
    "lab_vcm": ("lab_vcm", {"mode": "vcm", "pilot": False}),   # (merging itself, not the pilot's choice)
    "lab_vcm_ppm": ("lab_vcm", {"mode": "ppm"}),
    "lab_photon": ("lab_photon", {"photons_per_pass": 10_000}),
}
#: Markov chains: lab_pssmlt and lab_mmlt are unbiased (their chains start from bootstrap paths
#: drawn in proportion to their luminance, ``mlt/chain.py``), so the z-test judges them, with the
#: heavy-tail escalation; each split is its own bootstrap and set of chains, so b's error is in the
#: splits' spread. 1024 chains and a 16384-path bootstrap (lab_mmlt's split over its lengths): at
#: check's default budget (32 x 32, 8 spp per split) 8 steps per chain.
CHAIN_STRATEGIES = {
    "lab_pssmlt": ("lab_pssmlt", {"chains": 1024, "bootstrap": 16384}),
    "lab_mmlt": ("lab_mmlt", {"chains": 1024, "bootstrap": 16384}),
}
STRATEGIES = {**PATH_STRATEGIES, **BIDIRECTIONAL_STRATEGIES, **CHAIN_STRATEGIES}


def _z_against(row: dict, mean: float, variance: float) -> float:
    means = row["split_means"]
    return metrics.z_score(row["mean"], np.var(means, ddof=1), len(means), mean, variance, 1)


def judge_strategy(row, stack, scene, strategy, args, judged, path_ref, twin) -> None:
    """Fill the row's status, note and evidence (package doc, ``verdicts``)."""
    problems = [name for name, bad in (("NaN/Inf", row["finite_fraction"] < 1),
                                       ("negative", row["negative_pixels"] > 0)) if bad]
    if is_consistent(*strategy):
        verdict = Verdict("ok")
        if judged["finite"] and not problems:
            verdict = judge_consistent(bias_ladder(scene, strategy, stack, args.spp // args.splits, args, judged),
                                       judged["mean"])
        row["note"], row["evidence"] = verdict.summary, verdict.evidence
        status = {"ok": "ok", "converging": "converging"}.get(verdict.kind, "FAIL: bias not shrinking")
        row["status"] = "FAIL: " + ", ".join(problems) if problems else status
        return
    verdict = Verdict("ok")
    if judged["finite"] and not problems:
        rungs = [Rung(1, args.spp // args.splits, row["split_means"])]
        verdict = judge(rungs, judged["mean"], judged["mean_variance"], args.z_max)
        if verdict.kind != "ok" and row["z"] < 0:      # a low mean: larger budgets tell bias from tail
            rungs, sums, lab_mean, samples, wall = render_ladder(scene, strategy, stack, rungs[0].spp,
                                                                 args.escalate)
            empty = empty_pixels(sums, judged["pixels"], lab_mean, judged["mean"], samples)
            verdict = judge(rungs, judged["mean"], judged["mean_variance"], args.z_max, empty)
            if len(rungs) > 1:
                verdict.evidence.append(f"the larger budgets took {wall:.1f} s (not in time_s)")
    elif judged["finite"] and not abs(row["z"]) <= args.z_max:
        problems.append(f"mean off by {row['z']:+.1f} sigma")
    row["note"], row["evidence"] = verdict.summary, verdict.evidence
    if twin is not None:
        row["z_twin"] = _z_against(row, twin.mean, twin.variance)
    if twin is not None and judged is not path_ref:       # path is off: judged against the twin
        z_path = _z_against(row, path_ref["mean"], path_ref["mean_variance"])
        status, row["note"] = twin_status(verdict, z_path, row["mean"] / twin.mean - 1, twin, args.z_max)
    else:
        status = {"ok": "ok", "heavy tail": "WARN: heavy tail"}.get(
            verdict.kind, f"FAIL: mean off by {row['z']:+.1f} sigma")
    row["status"] = "FAIL: " + ", ".join(problems) if problems else status


def check_scene(path, args, defines, strategies: dict, say=lambda line: None) -> tuple[list[dict], list[str]]:
    """(rows, warnings) of one scene: its reference rows, then one row per strategy of
    ``strategies`` ({name: (type, params)}), rendered, skipped (with the reason) or the same as
    another; ``args`` carries the options of ``mitsuba-lab check``, ``say(line)`` is told the film
    as rendered and each warning as soon as they are known."""
    from ..scene import SceneTraits, equivalent_strategies, strategy_applicability

    scene = load_check_scene(path, args.res, defines)
    traits = SceneTraits.from_scene(scene)
    name = os.path.basename(path)
    film = film_text(scene)
    say(f"  {name}: film {film} pixels (width x height), as rendered")
    warnings = traits.warnings()
    rows, judged, path_ref, twin, more = references(path, name, args, defines, traits)
    warnings += more
    for warning in warnings:
        say(f"  warning: {name}: {warning}")
    depth = {"max_depth": args.max_depth}
    applicable = {}
    for strategy, (kind, params) in strategies.items():
        applies, reason = strategy_applicability(traits, kind, params)
        if applies:
            applicable[strategy] = (kind, params)
        else:
            rows.append({"scene": name, "strategy": strategy, "status": "skipped", "note": reason})
    canonical = equivalent_strategies(traits, applicable)
    measured = {}
    for strategy, (kind, params) in applicable.items():
        same = canonical[strategy]
        if same != strategy:
            rows.append({**measured[same], "strategy": strategy, "status": "same", "time_s": 0.0,
                         "note": f"the same estimator as {same} on this scene: not rendered "
                                 f"(its row's numbers)", "evidence": []})
            continue
        chosen = (kind, {**params, **depth})
        render_splits(scene, chosen, args.splits, 1, 0)               # warm-up: compile
        stack, rays, seconds = render_splits(scene, chosen, args.spp, args.splits, 0)
        row = {"scene": name, "strategy": strategy, **measure(stack, rays, seconds, judged, args.firefly_k)}
        judge_strategy(row, stack, scene, chosen, args, judged, path_ref, twin)
        measured[strategy] = row
        rows.append(row)
    for row in rows:
        row.setdefault("film", film)                 # the film as rendered, in the CSV and the HTML
    return rows, warnings


def film_text(scene) -> str:
    """The scene's film as rendered, "64x48" (width x height): what ``--res`` made of it."""
    size = scene.sensors()[0].film().size()
    return f"{size[0]}x{size[1]}"


def settings_text(args) -> str:
    """The settings line of a check (its first printed line, and the HTML's)."""
    return (f"--res {resolution_text(args.res)} (each scene's film as rendered: its line and the film column), "
            f"{args.spp} spp per strategy, reference {args.ref_spp} spp, "
            f"{args.splits} splits, max_depth {args.max_depth}, |z| <= {args.z_max:g}, "
            f"escalate x{args.escalate}, firefly k = {args.firefly_k:g}")
