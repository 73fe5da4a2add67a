import os
import subprocess
import sys

import mitsuba as mi
import pytest

from mitsuba_lab import runtime
from mitsuba_lab.errors import LabError, one_line


@pytest.mark.parametrize("name, version", [
    ("libLLVM-19.so", (19, 0)),
    ("libLLVM.so.19.1", (19, 1)),
    ("libLLVM-15.so.1", (15, 0)),
    ("libLLVM-14.0.6.so.1", (14, 0)),
    ("libLLVM-17.0.so", (17, 0)),
    ("libLLVM.so", None),
    ("libLLVMSupport.a", None),
])
def test_parse_llvm_version(name, version):
    assert runtime.parse_llvm_version(name) == version


def make_libs(folder, names):
    for name in names:
        (folder / name).write_bytes(b"\x7fELF")
    return [str(folder)]


def test_configure_llvm_picks_newest_usable(tmp_path):
    dirs = make_libs(tmp_path, ["libLLVM-15.so.1", "libLLVM-17.so", "libLLVM.so.19.1", "libLLVM-14.so"])
    env = {}
    chosen = runtime.configure_llvm(env, dirs)
    assert chosen == env["DRJIT_LIBLLVM_PATH"] == str(tmp_path / "libLLVM.so.19.1")


def test_configure_llvm_keeps_users_choice(tmp_path):
    dirs = make_libs(tmp_path, ["libLLVM-19.so"])
    env = {"DRJIT_LIBLLVM_PATH": "/opt/my/libLLVM.so"}
    assert runtime.configure_llvm(env, dirs) is None
    assert env["DRJIT_LIBLLVM_PATH"] == "/opt/my/libLLVM.so"


def test_configure_llvm_refuses_old_llvm_in_one_line(tmp_path):
    dirs = make_libs(tmp_path, ["libLLVM-15.so.1", "libLLVM-14.so"])
    with pytest.raises(LabError) as err:
        runtime.configure_llvm({}, dirs)
    message = str(err.value)
    assert "15.0" in message and "apt-get install libllvm19" in message and "\n" not in message


def test_default_variant_is_llvm_ad_rgb():
    assert mi.variant() == os.environ.get("MITSUBA_LAB_VARIANT", "llvm_ad_rgb")


def test_unknown_variant_is_one_line():
    with pytest.raises(LabError, match="unknown variant 'nope'"):
        runtime.set_variant("nope")


def old_llvm():
    libs = [lib for lib in runtime.find_llvm_libraries() if lib.major < runtime.MIN_LLVM_MAJOR]
    return libs[0].path if libs else None


@pytest.mark.skipif(old_llvm() is None, reason="no libLLVM < 16 on this machine")
def test_old_llvm_forced_by_user_never_aborts():
    # Dr.Jit with libLLVM 15 dies with "LLVM ERROR: Cannot select ... fminimum"
    # at the first kernel; the lab must stop before that, with one line.
    env = {**os.environ, "DRJIT_LIBLLVM_PATH": old_llvm()}
    proc = subprocess.run([sys.executable, "-m", "mitsuba_lab_command", "render", "scenes/cornell_box.xml"],
                          env=env, capture_output=True, text=True, timeout=120,
                          cwd=os.path.dirname(os.path.dirname(__file__)))
    assert proc.returncode == 2, proc.stderr
    assert "LLVM ERROR" not in proc.stderr + proc.stdout
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1 and "libllvm19" in lines[0]


def test_one_line_strips_source_tags_and_tracebacks():
    text = ('[parser.cpp:1718] At dictionary node "root": failed to instantiate: Traceback (most recent '
            'call last):\n  File "x.py", line 5, in <module>\nValueError: bad beta')
    assert one_line(text) == 'At dictionary node "root": failed to instantiate: bad beta'


def test_importing_the_package_selects_a_variant_unless_told_not_to():
    """Importing mitsuba_lab selects a variant whatever the script is called; with
    MITSUBA_LAB_ACTIVATE=0 (what the mitsuba-lab command's entry point sets) it imports no Mitsuba."""
    import mitsuba_lab
    import mitsuba_lab_command

    assert mitsuba_lab.ACTIVATE_ENV == mitsuba_lab_command.ACTIVATE_ENV
    code = ("import sys\n"
            "sys.argv[0] = 'mitsuba-lab'\n"
            "import mitsuba_lab\n"
            "print('mitsuba' in sys.modules and bool(sys.modules['mitsuba'].variant()))\n")
    root = os.path.dirname(os.path.dirname(__file__))
    env = {k: v for k, v in os.environ.items() if k != mitsuba_lab.ACTIVATE_ENV}
    runs = [subprocess.run([sys.executable, "-c", code], env=extra, capture_output=True, text=True,
                           timeout=120, cwd=root)
            for extra in (env, {**env, mitsuba_lab.ACTIVATE_ENV: "0"})]
    assert [proc.returncode for proc in runs] == [0, 0], runs[0].stderr + runs[1].stderr
    assert [proc.stdout.strip() for proc in runs] == ["True", "False"]
