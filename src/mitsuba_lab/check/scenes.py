"""check's scenes at the film size ``--res`` gives them, their unscaled twins, and their
references from the sweep runner's reference cache."""
from __future__ import annotations

import os

from ..errors import LabError
from ..film import as_resolution
from .measure import reference_summary
from .verdicts import Twin, path_off_note


def scene_settings(path: str, res, defines: dict) -> tuple[object, dict]:
    """(film override to edit into the XML or None, <default> values) for ``--res``: a scalar is
    the scene's ``res`` parameter when it declares one (``<default name="res" .../>``, as the
    shipped scenes do), else the film's larger side (``film``: aspect ratio kept), so any scene
    works; (W, H) sets the film's width and height. ``defines`` (-D) fill the scene's other
    <default> parameters."""
    from ..scene_xml import scene_defaults

    if isinstance(res, int) and "res" in scene_defaults(path):
        return None, {"res": res, **defines}
    defines = dict(defines)
    if "res" in defines:                      # -D res=N means the film size here too
        try:
            res = as_resolution(defines.pop("res"))
        except ValueError as err:
            raise LabError(f"-D res: {err}") from None
    return res, defines


def load_check_scene(path: str, res, defines: dict):
    """The scene at the film size ``--res`` gives it (``scene_settings``)."""
    from ..scene import load_scene
    from ..scene_xml import load_scene_variant

    resolution, defaults = scene_settings(path, res, defines)
    if resolution is None:
        return load_scene(path, **defaults)
    return load_scene_variant(path, resolution, None, defaults)


def twin_of(path: str, defines: dict) -> tuple[str, str, dict] | None:
    """(declared name, path, -D values it declares) of the scene's unscaled twin
    (``<default name="twin" value="PATH"/>``, relative to the scene file), or None."""
    from ..scene_xml import scene_defaults

    name = scene_defaults(path).get("twin")
    if not name:
        return None
    twin = os.path.normpath(os.path.join(os.path.dirname(os.path.abspath(path)), name))
    if not os.path.isfile(twin):
        raise LabError(f"{path}: its twin scene {name} is not found ({twin})")
    declared = scene_defaults(twin)
    return name, twin, {k: v for k, v in defines.items() if k in declared}


def cache_folder(option: str | None) -> str:
    """The reference cache: ``--cache``, else $MITSUBA_LAB_CACHE, else the default folder
    (as ``mitsuba-lab reference``)."""
    from ..experiment.pipeline.config import DEFAULT_CACHE

    return os.path.abspath(os.path.expanduser(option or os.environ.get("MITSUBA_LAB_CACHE") or DEFAULT_CACHE))


def check_reference(path: str, args, defines: dict, integrator: str):
    """(Reference, was_cached): ``integrator`` (Mitsuba's path, or volpathmis for a scene with
    media) at ``--ref-spp`` in ``--splits`` chunks, from the reference cache or rendered into it."""
    from ..experiment.pipeline.config import PluginSpec
    from ..experiment.pipeline.reference import get_reference

    resolution, defaults = scene_settings(path, args.res, defines)
    spec = PluginSpec("reference", integrator, {"max_depth": args.max_depth})
    return get_reference(os.path.abspath(path), resolution, defaults, spec, args.ref_spp, args.splits,
                         cache_folder(args.cache))


def _origin(reference, cached: bool, args) -> str:
    return f"{args.ref_spp} spp, {'from the cache' if cached else 'rendered into the cache'} ({reference.key})"


def references(path, name, args, defines, traits):
    """(reference rows, summary the strategies are judged against, path's summary, Twin or None,
    scene warnings): the scene's reference integrator (``features.default_reference``: Mitsuba's
    path unless the scene has media) on the scene, and on its unscaled twin when it declares one."""
    from ..features import default_reference

    integrator = default_reference(traits)
    reference, cached = check_reference(path, args, defines, integrator)
    ref, ref_row = reference_summary(reference, args.firefly_k)
    rows = [{"scene": name, "strategy": f"{integrator} (reference)", "status": "reference", **ref_row,
             "ref_mean": ref["mean"], "z": 0.0, "note": _origin(reference, cached, args)}]
    warnings = [] if ref["finite"] else [f"the {integrator} reference has non-finite pixels: no z-scores"]
    found = twin_of(path, defines)
    if found is not None and traits.far_clip_problems:   # no longer the same scene at another scale
        warnings.append(f"not compared with its unscaled twin {found[0]}: it loses geometry beyond far_clip")
        found = None
    if found is None:
        return rows, ref, ref, None, warnings
    twin_name, twin_path, twin_defines = found
    twin_reference, twin_cached = check_reference(twin_path, args, twin_defines, integrator)
    twin_ref, twin_row = reference_summary(twin_reference, args.firefly_k)
    twin = Twin.compare(twin_name, twin_ref["mean"], twin_ref["mean_variance"], ref["mean"], ref["mean_variance"],
                        integrator)
    rows[0].update(ref_mean=twin.mean, z=twin.z_path, z_twin=twin.z_path)
    rows.append({"scene": name, "strategy": f"{integrator} (twin)", "status": "twin reference", **twin_row,
                 "ref_mean": twin.mean, "note": f"{integrator} on the unscaled twin {twin_name}: "
                                                f"{_origin(twin_reference, twin_cached, args)}"})
    if twin.path_off(args.z_max) and twin_ref["finite"] and ref["finite"]:
        note = path_off_note(twin, traits.bbox_min, traits.bbox_max)
        rows[0].update(status="reference: OFF", note=note, evidence=[rows[0]["note"]])
        warnings.append(note)
        return rows, twin_ref, ref, twin, warnings
    rows[0]["note"] += f"; agrees with the unscaled twin {twin_name} ({twin.rel_path:+.1%})"
    return rows, ref, ref, twin, warnings
