"""Each parameter's type, default and allowed values are written once: declared in
``plugins/params.py`` and generated from there into ``plugins/README.md`` (checked by
``tests/commands/test_plugins_command.py``). ``plugins/design.md``, the long form, explains every
parameter but repeats none of that: it has no parameter table and states no default. And
experiments/README.md lists every shipped config.
"""
import os
import re

import pytest

from mitsuba_lab.plugins import params

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
INTEGRATORS = tuple(p for p in params.lab_plugins() if params.plugin_kind(p) == "integrator")
SAMPLERS = tuple(p for p in params.lab_plugins() if params.plugin_kind(p) == "sampler")
NAMES = sorted({p.name for plugin in params.lab_plugins() for p in params.declared(plugin)})

#: The long form of the plugin reference.
DESIGN = os.path.join("plugins", "design.md")


def design() -> str:
    with open(os.path.join(ROOT, DESIGN), encoding="utf-8") as handle:
        return handle.read()


def section(title: str) -> str:
    match = re.search(rf"^## {re.escape(title)}\n(.*?)(?=^## |\Z)", design(), re.M | re.S)
    assert match, f"{DESIGN} has no '## {title}' section"
    return match.group(1)


def cells(line: str) -> list[str]:
    return [c.strip() for c in line.strip().strip("|").split("|")]


def parameter_tables(text: str) -> list[str]:
    """The header lines of tables that start with parameter | type | default."""
    return [line for line in text.splitlines()
            if line.startswith("|") and cells(line)[:3] == ["parameter", "type", "default"]]


def stated_defaults(text: str) -> list[str]:
    """Where ``text`` gives a declared parameter's default: "`name` (default ...", "`name` = X
    (default)", or "`name` (" followed by a number, true or false."""
    names = "|".join(map(re.escape, NAMES))
    found = re.findall(rf"`(?:{names})`\s+\(default\b[^)]*", text)
    found += re.findall(rf"`(?:{names})`\s+=\s+`?[\w.-]+`?\s+\(default\)", text)
    found += re.findall(rf"`(?:{names})`\s+\((?:-?\d|true\b|false\b)[^)]*", text)
    return found


def test_design_md_has_no_parameter_table():
    assert parameter_tables(design()) == []


def test_design_md_states_no_default():
    assert stated_defaults(design()) == []


def test_a_stated_default_is_found():
    """The check's power: each way of writing a default in prose is caught."""
    for text in ("`rr_depth` (5, on both subpaths)", "`jitter` = true (default) or false",
                 "`width` (default 0 = taken from the film)", "`hide_emitters` (false; camera rays)",
                 "`alpha` (0.75, in (0, 1))"):
        assert stated_defaults(text), text
    assert stated_defaults("`small_step` (`normal` or `exponential`), `pilot` (modes `vcm`)") == []


@pytest.mark.parametrize("plugin", INTEGRATORS + SAMPLERS)
def test_design_md_explains_every_parameter(plugin):
    """Every declared parameter, and every value of one with choices, is named in its section."""
    text = section("Integrators" if plugin in INTEGRATORS else "Samplers")
    missing = [p.name for p in params.declared(plugin) if f"`{p.name}`" not in text]
    assert not missing, f"{DESIGN} does not explain {plugin}'s {missing}"
    unnamed = [f"{p.name}={c}" for p in params.declared(plugin) for c in p.choices if f"`{c}`" not in text]
    assert not unnamed, f"{DESIGN} does not name {plugin}'s values {unnamed}"


# -- Shipped configs ----------------------------------------------------------------------------

def test_experiments_readme_lists_every_shipped_config():
    """Each experiments/*.toml has its row in experiments/README.md's table (| `name.toml` | ...),
    and every row names a file that exists."""
    folder = os.path.join(ROOT, "experiments")
    shipped = sorted(f for f in os.listdir(folder) if f.endswith(".toml"))
    assert len(shipped) >= 10
    with open(os.path.join(folder, "README.md"), encoding="utf-8") as handle:
        rows = [cells(line)[0].strip("`") for line in handle if line.startswith("| `") and ".toml`" in line]
    assert sorted(r for r in rows if r.endswith(".toml")) == shipped
