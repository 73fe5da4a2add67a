"""The mitsuba-lab command: outputs, metadata, and one-line errors with exit status 2."""
import io
import json
import os
import subprocess
import sys

import numpy as np
import pytest

from mitsuba_lab import cli, images

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
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
        "heuristic": "balance", "beta": 2.0, "emitter_samples": 1}
    assert json.loads(meta["mitsuba_lab.sampler"]) == {"type": "independent", "params": {"sample_count": 4}}
    stats = json.loads(meta["mitsuba_lab.stats"])
    assert stats["spp"] == 4 and stats["seed"] == 3 and stats["rays"]["camera"] == 32 * 32 * 4
    assert meta["mitsuba_lab.variant"] == "llvm_ad_rgb" and int(meta["mitsuba_lab.libllvm"].split(".")[0]) >= 16
    assert (tmp_path / "cb.png").stat().st_size > 100
    assert "compile" in out and "kernels" in out and "shadow" in out


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


def test_theory_json_rows():
    code, out, err = run(["theory", "--quick", "--json"])
    assert code == 0, err
    rows = json.loads(out)
    assert {"problem", "quantity", "predicted", "measured"} <= set(rows[0])
    by_quantity = {(r["problem"], r["quantity"]): r for r in rows}
    assert by_quantity[("P5", "rr_variance")]["predicted"] == pytest.approx(16.6667, abs=1e-4)
