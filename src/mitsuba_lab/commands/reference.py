"""``mitsuba-lab reference SCENE``: build (or find) one cached high-spp reference."""
from __future__ import annotations

from .args import parse_assignments, positive_int, resolution_arg


def add_arguments(parser) -> None:
    parser.description = ("Render SCENE's reference in independent chunks, cache it (content-addressed) "
                          "and print its key and noise floor.")
    parser.add_argument("scene", help="Mitsuba XML scene file")
    parser.add_argument("--integrator",
                        help="reference integrator; it must render every feature of the scene (default: "
                             "path, or volpathmis where the scene has participating media)")
    parser.add_argument("--max-depth", type=int, help="max_depth of the integrator")
    parser.add_argument("--param", action="append", metavar="KEY=VALUE",
                        help="other integrator parameter (repeatable)")
    parser.add_argument("--spp", type=positive_int, default=4096, help="total samples per pixel "
                                                                        "(default: 4096)")
    parser.add_argument("--chunks", type=positive_int, default=8,
                        help="independent chunks (>= 2, dividing --spp) for the noise floor (default: 8)")
    parser.add_argument("--res", type=resolution_arg,
                        help="film size: N sets the larger side and keeps the scene's aspect ratio, WxH "
                             "sets both (default: the scene's)")
    parser.add_argument("--define", "-D", action="append", metavar="KEY=VALUE",
                        help="scene <default> value (repeatable)")
    parser.add_argument("--cache", help="cache folder (default: $MITSUBA_LAB_CACHE or "
                                        "~/.cache/mitsuba_lab/references)")
    parser.add_argument("-o", "--output", help="also write the reference image here (.exr, + .png)")


def run(args, out) -> int:
    from ..experiment import sweep

    params = parse_assignments(args.param, "--param")
    if args.max_depth is not None:
        params["max_depth"] = args.max_depth
    from ..progress import ProgressBar

    ref, cached, cache, integrator = sweep.build_reference(
        args.scene, args.integrator, params, args.spp, args.chunks, args.res, parse_assignments(args.define, "--define"),
        args.cache, args.output, ProgressBar())
    origin = "found in the cache" if cached else f"rendered in {ref.meta.get('seconds', 0):.1f} s"
    height, width = ref.image.shape[:2]
    print(f"reference {ref.key} ({integrator}, {width}x{height}) {origin}: {cache}/{ref.key}.exr; noise floor "
          f"MSE {ref.mse_floor:.4g}, relMSE {ref.rel_mse_floor():.4g}", file=out)
    if args.output:
        sweep.write_reference_image(args.output, ref)
        print(f"wrote {args.output}", file=out)
    return 0
