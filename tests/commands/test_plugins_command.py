"""`mitsuba-lab plugins [NAME]`: the lab's plugins and their declared parameters, no variant needed."""
import os
import subprocess
import sys

import pytest

from mitsuba_lab.commands import plugin_text as command
from mitsuba_lab.plugins import params

from test_cli import ROOT, run


def test_lists_every_lab_plugin_one_line_each():
    code, out, err = run(["plugins"])
    assert code == 0 and err == ""
    lines = out.strip().splitlines()
    assert [line.split()[0] for line in lines] == list(params.lab_plugins())
    for line in lines:
        name, kind, *about = line.split()
        assert kind == params.plugin_kind(name)
        assert about, f"{name} has no summary"
    by_name = {line.split()[0]: line for line in lines}
    assert by_name["lab_mis"].endswith("Multiple importance sampling path tracer")
    assert by_name["lab_photon"].endswith("Progressive photon mapping")
    assert "monosp" not in out


@pytest.mark.parametrize("name", params.lab_plugins())
def test_parameter_table_follows_the_declarations(name):
    code, out, err = run(["plugins", name])
    assert code == 0 and err == ""
    lines = out.strip().splitlines()
    assert lines[0].startswith(f"{name} ({params.plugin_kind(name)})")
    assert lines[1].split() == ["parameter", "type", "default", "allowed", "meaning"]
    rows = {line.split()[0]: line for line in lines[2:2 + len(params.declared(name))]}
    assert list(rows) == [p.name for p in params.declared(name)]
    start = lines[1].index("default")
    allowed_at, meaning_at = lines[1].index("allowed"), lines[1].index("meaning")
    for p in params.declared(name):
        row = rows[p.name]
        assert row.split()[1] == {int: "int", float: "float", bool: "bool", str: "string"}[p.kind]
        assert row[start:allowed_at].strip() == command.show(p.default)
        assert row[allowed_at:meaning_at].strip() == command.allowed_text(p)
        assert row[meaning_at:] == p.doc


def test_lab_mis_table():
    code, out, _ = run(["plugins", "lab_mis"])
    assert code == 0
    rows = {line.split()[0]: line.split() for line in out.splitlines()[2:]}
    assert rows["heuristic"][:7] == ["heuristic", "string", "power", "balance", "|", "power", "|"]
    assert rows["beta"][:3] == ["beta", "float", "2"]
    assert rows["emitter_samples"][:6] == ["emitter_samples", "int", "1", "an", "integer", ">="]
    assert rows["hide_emitters"][:3] == ["hide_emitters", "bool", "false"]
    assert "timeout" in out.splitlines()[-1]          # Mitsuba's base parameters are named too


@pytest.mark.parametrize("name", ["lab_bdpt", "lab_vcm"])
def test_a_refused_base_parameter_is_not_listed(name):
    """lab_bdpt and lab_vcm refuse samples_per_pass (their passes are sized by max_vertices): the
    table lists only the base parameters they accept, and using the refused one is an error
    naming the plugin (params.REFUSED_BASE_PARAMETERS)."""
    from mitsuba_lab.plugins import params

    code, out, _ = run(["plugins", name])
    assert code == 0
    last = out.splitlines()[-1]
    assert "timeout" in last and "block_size" in last and "samples_per_pass" not in last
    assert "count_rays" in out
    with pytest.raises(params.ParameterError, match=f"^{name}: parameter 'samples_per_pass' is not supported"):
        params.resolve(name, {"samples_per_pass": 4})
    assert params.resolve("lab_mis", {"samples_per_pass": 4})["samples_per_pass"] == 4


def test_defaults_are_shown_as_written():
    assert [command.show(v) for v in (True, False, 2.0, 2.0 / 3.0, -1, "owen", 1 << 21)] == \
        ["true", "false", "2", "0.666667", "-1", "owen", "2097152"]


@pytest.mark.parametrize("name, hint", [("lab_miss", "did you mean 'lab_mis'?"),
                                        ("lab_sobl", "did you mean 'lab_sobol'?"),
                                        ("path", "lab plugins: lab_naive, ")])
def test_unknown_name_is_one_line_exit_2(name, hint):
    code, out, err = run(["plugins", name])
    assert code == 2 and out == ""
    lines = err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith(f"mitsuba-lab: error: unknown lab plugin '{name}'")
    assert hint in lines[0]


def test_needs_no_mitsuba_variant():
    """Reads declarations only: no Mitsuba, Dr.Jit or numpy import; a bad --variant is not read."""
    code = ("import os, sys\n"
            "import mitsuba_lab_command\n"
            "assert mitsuba_lab_command.main(['--variant', 'nope', 'plugins']) == 0\n"
            "assert mitsuba_lab_command.main(['plugins', 'lab_photon']) == 0\n"
            "print(sorted(m for m in ('mitsuba', 'drjit', 'numpy') if m in sys.modules),\n"
            "      os.environ.get('MITSUBA_LAB_ACTIVATE'))\n")
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120, cwd=ROOT,
                          env={k: v for k, v in os.environ.items() if k != "MITSUBA_LAB_ACTIVATE"})
    assert proc.returncode == 0, proc.stderr
    assert proc.stdout.strip().splitlines()[-1] == "[] None"      # the environment is left as it was


def test_console_script():
    exe = os.path.join(os.path.dirname(sys.executable), "mitsuba-lab")
    proc = subprocess.run([exe, "plugins", "lab_zsobol"], capture_output=True, text=True, timeout=120)
    assert proc.returncode == 0 and "width" in proc.stdout, proc.stderr


def test_the_committed_plugin_reference_is_current():
    """plugins/README.md is what `mitsuba-lab plugins --markdown` writes from the declarations
    and docstrings: a parameter declared, renamed or re-documented without running it fails here."""
    from mitsuba_lab.commands.plugin_reference import markdown_reference, reference_path

    with open(reference_path(), encoding="utf-8") as handle:
        committed = handle.read()
    assert committed == markdown_reference(), "plugins/README.md is stale: run `mitsuba-lab plugins --markdown`"


def test_the_reference_has_every_plugin_and_parameter_and_no_docstring_table():
    from mitsuba_lab.commands.plugin_reference import markdown_reference

    text = markdown_reference()
    for name in params.lab_plugins():
        section = text.split(f"\n## {name}\n", 1)[1].split("\n## ", 1)[0]
        for p in params.declared(name):
            assert f"| `{p.name}` | {command.type_name(p)} | `{command.show(p.default)}` |" in section, (name, p.name)
    assert "=====" not in text and ":monosp:" not in text and ".. code-block" not in text


def test_markdown_takes_no_plugin_name():
    code, out, err = run(["plugins", "lab_mis", "--markdown"])
    assert code == 2 and "give no NAME" in err and "\n" not in err.strip()
