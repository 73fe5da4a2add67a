"""The mitsuba-lab command: outputs, metadata, and one-line errors with exit status 2."""
import io
import json
import os
import re
import subprocess
import sys

import numpy as np
import pytest

from mitsuba_lab import cli, images

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
CORNELL = os.path.join(ROOT, "scenes", "cornell_box.xml")


def run(argv):
    out, err = io.StringIO(), io.StringIO()
    old_out, old_err, sys.stdout, sys.stderr = sys.stdout, sys.stderr, out, err
    try:
        code = cli.main(argv)
    except SystemExit as exc:              # argparse usage errors and --help
        code = exc.code
    finally:
        sys.stdout, sys.stderr = old_out, old_err
    return code, out.getvalue(), err.getvalue()


@pytest.mark.slow
def test_render_writes_exr_with_metadata_and_png(tmp_path):
    target = tmp_path / "cb.exr"
    code, out, err = run(["render", CORNELL, "-D", "res=32", "--spp", "4", "--integrator", "lab_mis",
                          "--max-depth", "4", "--heuristic", "balance", "--seed", "3", "-o", str(target)])
    assert code == 0, err
    image, meta = images.read_exr(str(target))
    assert image.shape == (32, 32, 3) and image.dtype == np.float32
    assert np.isfinite(image).all() and image.mean() > 0.05
    assert meta["mitsuba_lab.integrator"] == "lab_mis"
    assert json.loads(meta["mitsuba_lab.params"]) == {      # as used: every default filled in
        "max_depth": 4, "rr_depth": 5, "hide_emitters": False, "count_rays": True,
        "heuristic": "balance", "beta": 2.0, "emitter_samples": 1, "medium_sampling": "mis",
        "equiangular_samples": 1, "transmittance": "ratio", "majorants": "global", "majorant_resolution": 16,
        "spectral_mis": True}
    assert json.loads(meta["mitsuba_lab.sampler"]) == {"type": "independent", "params": {"sample_count": 4}}
    stats = json.loads(meta["mitsuba_lab.stats"])
    assert stats["spp"] == 4 and stats["seed"] == 3 and stats["rays"]["camera"] == 32 * 32 * 4
    assert meta["mitsuba_lab.variant"] == "llvm_ad_rgb" and int(meta["mitsuba_lab.libllvm"].split(".")[0]) >= 16
    assert (tmp_path / "cb.png").stat().st_size > 100
    assert "compile" in out and "kernels" in out and "shadow" in out


@pytest.mark.slow
def test_render_reports_what_lab_vcms_pilot_chose(tmp_path):
    """The summary names a bidirectional integrator's statistics, lab_vcm's pilot choice among
    them: whether path tracing alone, the light subpaths chosen (0 for path tracing) and each
    choice's score as a table (which choice a 16x16 image gets is timing noise: not checked;
    ``pilot_share`` 1: at 256 spp the default share, 1/8 of the counted work, affords no pilot)."""
    code, out, err = run(["render", CORNELL, "-D", "res=16", "--spp", "256", "--integrator", "lab_vcm",
                          "--param", "pilot=true", "--param", "light_paths=0.0625", "--param", "light_paths_max=0.125",
                          "--param", "pilot_share=1", "-o", str(tmp_path / "v.exr")])
    assert code == 0, err
    line = next(line for line in out.splitlines() if line.startswith("statistics: "))
    assert "pilot_s" in line and "pilot_scores (0.0625: " in line and ", 0.125: " in line and "path tracing: " in line
    chose = re.search(r"chose_path_tracing (\w+), light_paths_chosen ([0-9.]+)", line)
    assert chose and (chose[1] == "True") == (float(chose[2]) == 0.0) and float(chose[2]) in (0.0, 0.0625, 0.125)


def test_param_values_are_parsed():
    assert cli.parse_assignments(["a=8", "b=0.5", "c=true", "d=power"], "--param") == \
        {"a": 8, "b": 0.5, "c": True, "d": "power"}


@pytest.mark.parametrize("argv, expected", [
    (["render", CORNELL, "--integrator", "foo"], "unknown integrator 'foo'; lab integrators: lab_naive"),
    (["render", CORNELL, "--integrator", "lab_mis", "--heuristic", "foo"],
     "parameter 'heuristic' must be one of balance, power"),
    (["render", CORNELL, "--integrator", "lab_mis", "--beta", "0"], "parameter 'beta' must be a finite number > 0"),
    (["render", CORNELL, "--integrator", "lab_mis", "--emitter-samples", "0"],
     "parameter 'emitter_samples' must be an integer >= 1"),
    (["render", CORNELL, "--integrator", "lab_nee", "--heuristic", "power"], "unknown parameter 'heuristic'"),
    (["render", CORNELL, "--heuristic", "power"], "integrator 'path': unknown parameter 'heuristic'"),
    (["render", CORNELL, "--spp", "0"], "--spp: must be a positive integer"),
    (["render", os.path.join(ROOT, "scenes", "missing.xml")], "scene file not found"),
    (["render", CORNELL, "--param", "oops"], "--param expects KEY=VALUE"),
    (["--variant", "nope", "render", CORNELL], "unknown variant 'nope'"),
])
def test_bad_input_is_one_line_exit_2(argv, expected, tmp_path):
    target = tmp_path / "x.exr"
    code, out, err = run(argv + ["-o", str(target)])
    assert code == 2
    lines = err.strip().splitlines()
    assert len(lines) == 1 and expected in lines[0], err
    assert "Traceback" not in err
    assert list(tmp_path.iterdir()) == []             # nothing written, not even a temp file


def test_malformed_scene_names_file_and_line(tmp_path):
    bad = tmp_path / "bad.xml"
    bad.write_text('<scene version="3.0.0">\n  <shape type="sphere">\n    <float name="radius" value="x"/>\n'
                   '  </shape>\n</scene>\n')
    code, _, err = run(["render", str(bad), "-o", str(tmp_path / "x.exr")])
    assert code == 2 and "bad.xml" in err and "line 3" in err and len(err.strip().splitlines()) == 1


def test_unwritable_output_is_refused_before_rendering(tmp_path):
    (tmp_path / "file").write_text("")
    code, out, err = run(["render", CORNELL, "-o", str(tmp_path / "file" / "x.exr")])
    assert code == 2 and "output folder" in err and out == "" and len(err.strip().splitlines()) == 1


@pytest.mark.slow
def test_console_script_end_to_end(tmp_path):
    """The installed command, as a user runs it (one real process)."""
    exe = os.path.join(os.path.dirname(sys.executable), "mitsuba-lab")
    proc = subprocess.run([exe, "render", CORNELL, "-D", "res=16", "--spp", "2", "--integrator", "lab_naive",
                           "-o", str(tmp_path / "n.exr")], capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stderr
    assert (tmp_path / "n.exr").exists() and (tmp_path / "n.png").exists()
    bad = subprocess.run([exe, "render", CORNELL, "--integrator", "nope"], capture_output=True, text=True,
                         timeout=300)
    assert bad.returncode == 2 and len(bad.stderr.strip().splitlines()) == 1


def test_help_documents_every_render_option():
    code, out, _ = run(["render", "--help"])
    assert code == 0
    for option in ("--integrator", "--max-depth", "--rr-depth", "--heuristic", "--beta", "--emitter-samples",
                   "--hide-emitters", "--param", "--define", "--spp", "--seed", "--output", "--no-png"):
        assert option in out


@pytest.mark.slow
def test_theory_json_rows():
    code, out, err = run(["theory", "--quick", "--json"])
    assert code == 0, err
    rows = json.loads(out)
    assert {"problem", "quantity", "predicted", "measured"} <= set(rows[0])
    by_quantity = {(r["problem"], r["quantity"]): r for r in rows}
    assert by_quantity[("P5", "rr_variance")]["predicted"] == pytest.approx(16.6667, abs=1e-4)


def test_every_command_is_a_module_with_help():
    """Each verb of the registry: a module of mitsuba_lab with add_arguments and run,
    and a --help page (exit 0)."""
    import importlib

    assert list(cli.COMMANDS) == ["render", "demo", "sweep", "reference", "report", "check", "invert",
                                  "theory", "plugins"]
    assert cli.NO_VARIANT == {"theory", "report", "plugins"}
    for verb, (module, help_line) in cli.COMMANDS.items():
        command = importlib.import_module(f"mitsuba_lab.{module}")
        assert callable(command.add_arguments) and callable(command.run) and help_line
        code, out, _ = run([verb, "--help"])
        assert code == 0 and out.startswith(f"usage: mitsuba-lab {verb}"), verb
    code, out, _ = run(["--help"])
    assert code == 0 and all(verb in out for verb in cli.COMMANDS)


def test_shared_argument_helpers_stay_importable_from_cli():
    from mitsuba_lab.commands import args

    assert cli.parse_assignments is args.parse_assignments and cli.positive_int is args.positive_int
    assert (cli.EXIT_USAGE, cli.EXIT_INTERRUPTED, cli.EXIT_PIPE) == (2, 130, 141)
    assert cli.build_parser().parse_args(["render", "x.xml", "--spp", "4"]).spp == 4


def test_help_imports_no_mitsuba():
    """`mitsuba-lab --help` builds no subcommand: no command module, no Mitsuba, Dr.Jit or numpy."""
    code = ("import sys\n"
            "import mitsuba_lab_command\n"
            "try:\n"
            "    mitsuba_lab_command.main(['--help'])\n"
            "except SystemExit as exc:\n"
            "    assert exc.code == 0\n"
            "heavy = ('mitsuba', 'drjit', 'numpy', 'mitsuba_lab.commands.render', 'mitsuba_lab.check')\n"
            "print(sorted(m for m in heavy if m in sys.modules))\n")
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120, cwd=ROOT)
    assert proc.returncode == 0, proc.stderr
    assert proc.stdout.strip().splitlines()[-1] == "[]"


def test_render_help_states_the_declared_defaults_and_values():
    from mitsuba_lab.commands.plugins import allowed_text, default_text
    from mitsuba_lab.plugins.params import declared, lab_plugins, plugin_kind

    code, out, _ = run(["render", "--help"])
    assert code == 0
    text = " ".join(out.split())
    integrators = [p for p in lab_plugins() if plugin_kind(p) == "integrator"]
    assert "lab_photon" in integrators
    assert f"integrator plugin: {', '.join(integrators)} or any of Mitsuba's" in text
    options = {"--max-depth": "max_depth", "--rr-depth": "rr_depth", "--heuristic": "heuristic",
               "--beta": "beta", "--emitter-samples": "emitter_samples"}
    for option, name in options.items():
        section = text.split(f"{option} {name.upper()} ", 1)[1].split(" --", 1)[0]
        holders = [p for plugin in integrators for p in declared(plugin) if p.name == name]
        assert section.startswith(holders[0].doc), (option, section)      # the first declaration's meaning
        for p in holders:
            assert f"{allowed_text(p)} (default: {default_text(p)})" in section, (option, section)
    assert "lab_mis, lab_pssmlt: balance | power | max | average (default: power)" in text
