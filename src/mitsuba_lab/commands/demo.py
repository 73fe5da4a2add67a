"""``mitsuba-lab demo``: the Cornell box with every lab integrator, EXR + PNG each."""
from __future__ import annotations

import os

from .args import positive_int, project_root
from .render import format_stats, write_outputs

DEMO_STRATEGIES = (
    ("lab_naive", {}),
    ("lab_nee", {}),
    ("lab_mis", {"heuristic": "balance"}),
    ("lab_mis", {"heuristic": "power"}),
)


def add_arguments(parser) -> None:
    parser.description = ("Render scenes/cornell_box.xml with lab_naive, lab_nee and lab_mis (power "
                          "and balance) and write EXR + PNG files.")
    parser.add_argument("-o", "--output", default="out/demo", help="output folder (default: out/demo)")
    parser.add_argument("--spp", type=positive_int, default=64, help="samples per pixel (default: 64)")
    parser.add_argument("--res", type=positive_int, default=128, help="image width and height "
                                                                      "(default: 128)")
    parser.add_argument("--max-depth", type=int, default=8, help="max_depth of every integrator "
                                                                "(default: 8)")


def run(args, out) -> int:
    from .. import images, scene as scenes
    from ..plugins.params import resolve
    from ..render import render
    from ..runtime import versions

    os.makedirs(args.output, exist_ok=True)
    images.check_writable(os.path.join(args.output, "x.exr"))
    scene_path = os.path.join(project_root(), "scenes", "cornell_box.xml")
    scene = scenes.load_scene(scene_path, res=args.res)
    info = versions()
    print(f"Cornell box {args.res}x{args.res}, {args.spp} spp, max_depth {args.max_depth}, "
          f"variant {info['variant']}", file=out)
    for name, extra in DEMO_STRATEGIES:
        params = {"max_depth": args.max_depth, **extra}
        integrator = scenes.make_integrator(name, params)
        render(scene, integrator, spp=args.spp, seed=0)        # warm-up: compiles the kernel
        image, stats = render(scene, integrator, spp=args.spp, seed=1)
        label = name + "".join(f"_{v}" for v in extra.values())
        output = os.path.join(args.output, f"cornell_box_{label}.exr")
        settings = {"integrator": {"type": name, "params": resolve(name, params)}}
        write_outputs(output, image, stats, settings, scene_path, info)
        print(f"  {format_stats(label, stats)}", file=out)
    print(f"wrote EXR + PNG files to {args.output}", file=out)
    return 0
