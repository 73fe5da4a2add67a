"""Errors raised inside Dr.Jit symbolic code reach the user by their cause.

Dr.Jit re-raises them as RuntimeError("...: encountered an exception (see
above).") with the original exception as ``__cause__``; ``one_line`` must show
the original, and ``is_interrupt`` must see a Ctrl-C behind the wrapper.
"""
import drjit as dr
import mitsuba as mi
import pytest

from mitsuba_lab.errors import LabError, innermost, is_interrupt, is_wrapper, one_line

needs_jit_ad = pytest.mark.skipif(not (dr.is_jit_v(mi.Float) and dr.is_diff_v(mi.Float)),
                                  reason="needs a JIT AD variant (llvm_ad_* or cuda_ad_*)")


def raise_in_loop(exc: BaseException, mode: str = "symbolic"):
    def body(i):
        raise exc

    i = mi.UInt32(0, 1)
    dr.while_loop((i,), lambda i: i < 3, body, mode=mode)


def caught(fn, *args, **kwargs) -> BaseException:
    with pytest.raises(BaseException) as info:
        fn(*args, **kwargs)
    return info.value


@needs_jit_ad
@pytest.mark.parametrize("mode", ["symbolic", "evaluated"])
def test_while_loop_error_names_its_cause(mode):
    err = caught(raise_in_loop, ValueError("boom: the cause"), mode)
    assert "see above" in str(err)                           # what Dr.Jit itself says
    assert isinstance(err.__cause__, ValueError)             # the mechanism relied upon
    assert is_wrapper(err)
    assert isinstance(innermost(err), ValueError)
    assert one_line(err) == "boom: the cause"
    assert not is_interrupt(err)


class RaisingOp(dr.CustomOp):
    def eval(self, x):
        raise ValueError("boom: the cause")


class RaisingForwardOp(dr.CustomOp):
    def eval(self, x):
        return x * 2

    def forward(self):
        raise ValueError("boom: the cause")


class LoopInOp(dr.CustomOp):
    """A symbolic loop inside a custom op: two wrappers deep, like mi.render + lab plugin."""

    def eval(self, x):
        raise_in_loop(KeyboardInterrupt())
        return x


@needs_jit_ad
def test_custom_op_error_names_its_cause():
    err = caught(dr.custom, RaisingOp, mi.Float(1, 2))
    assert "custom differentiable operation" in str(err)
    assert isinstance(innermost(err), ValueError)
    assert one_line(err) == "boom: the cause"


@needs_jit_ad
def test_custom_op_forward_error_names_its_cause():
    x = mi.Float(1, 2)
    dr.enable_grad(x)
    y = dr.custom(RaisingForwardOp, x)                       # (kept: the graph must reach it)
    err = caught(dr.forward, x)
    assert "boom: the cause" in one_line(err)
    del y


@needs_jit_ad
def test_interrupt_inside_while_loop_is_seen():
    err = caught(raise_in_loop, KeyboardInterrupt())
    assert isinstance(err, RuntimeError)                     # not a KeyboardInterrupt any more
    assert is_interrupt(err)
    assert isinstance(innermost(err), KeyboardInterrupt)
    assert one_line(err) == "interrupted"


@needs_jit_ad
def test_interrupt_two_wrappers_deep_is_seen():
    err = caught(dr.custom, LoopInOp, mi.Float(1, 2))
    assert is_wrapper(err) and is_wrapper(err.__cause__)
    assert is_interrupt(err)
    assert isinstance(innermost(err), KeyboardInterrupt)


@needs_jit_ad
def test_bug_in_loop_body_shows_type_and_place():
    def body(i):
        return (i.no_such_attribute,)

    i = mi.UInt32(0, 1)
    err = caught(dr.while_loop, (i,), lambda i: i < 3, body)
    line = one_line(err)
    assert line.startswith("AttributeError: ") and "no_such_attribute" in line
    assert "test_errors.py" in line and "in body" in line


class BoomIntegrator(mi.SamplingIntegrator):
    """A Python integrator whose sample() raises what it was given (inside mi.render's custom op)."""

    exc: BaseException = ValueError("boom: the cause")

    def sample(self, scene, sampler, ray, medium=None, active=True):
        raise type(self).exc


@pytest.fixture
def boom_render():
    mi.register_integrator("test_errors_boom", lambda props: BoomIntegrator(props))
    scene = mi.load_dict({"type": "scene", "sensor": {"type": "perspective",
                                                      "film": {"type": "hdrfilm", "width": 8, "height": 8}}})

    def render(exc):
        BoomIntegrator.exc = exc
        return caught(mi.render, scene, integrator=mi.load_dict({"type": "test_errors_boom"}), spp=1)

    return render


@needs_jit_ad
def test_error_in_python_integrator_during_mi_render(boom_render):
    err = boom_render(ValueError("boom: the cause"))
    assert "see above" in str(err)
    assert one_line(err) == "boom: the cause"
    assert not is_interrupt(err)


@needs_jit_ad
def test_interrupt_in_python_integrator_during_mi_render(boom_render):
    err = boom_render(KeyboardInterrupt())
    assert is_interrupt(err)
    assert one_line(err) == "interrupted"


@needs_jit_ad
def test_lab_sampler_error_in_seed_is_shown():
    # lab_zsobol finds out in seed(), inside mi.render, that 1025^2 pixels x 2048 spp need more
    # Sobol index bits than it has (nothing is allocated before)
    scene = mi.load_dict({"type": "scene", "sensor": {
        "type": "perspective", "sampler": {"type": "lab_zsobol", "sample_count": 2048},
        "film": {"type": "hdrfilm", "width": 1025, "height": 1025}}})
    err = caught(mi.render, scene, integrator=mi.load_dict({"type": "path"}))
    line = one_line(err)
    assert line.startswith("lab_zsobol: 1025x1025 pixels at 2048 spp need 33 > 32 index bits")
    assert "see above" not in line


def test_wrapper_without_a_cause_keeps_its_message():
    err = RuntimeError("dr.while_loop(): encountered an exception (see above).")
    assert innermost(err) is err
    assert one_line(err) == "dr.while_loop(): encountered an exception (see above)."


def test_lab_error_raised_from_a_wrapper_keeps_its_own_message():
    try:
        try:
            raise RuntimeError("drjit.custom(<X>): error while performing a custom differentiable "
                               "operation. (see above).") from ValueError("inner")
        except RuntimeError as wrapper:
            raise LabError("cannot render: bad film") from wrapper
    except LabError as err:
        assert innermost(err) is err
        assert one_line(err) == "cannot render: bad film"


def test_chain_with_a_cycle_terminates():
    a = RuntimeError("a (see above).")
    b = RuntimeError("b (see above).")
    a.__cause__, b.__cause__ = b, a
    assert innermost(a) in (a, b)
    assert not is_interrupt(a)


def test_empty_message_shows_the_type():
    assert one_line(ValueError()) == "ValueError"
    assert one_line(KeyboardInterrupt()) == "interrupted"


def test_interrupt_during_handling_is_seen():
    try:
        try:
            raise KeyboardInterrupt
        except KeyboardInterrupt:
            raise OSError("cleanup failed")
    except OSError as err:
        assert is_interrupt(err)
        assert one_line(err) == "cleanup failed"


def test_one_line_strips_source_tags_and_tracebacks():
    text = ('[parser.cpp:1718] At dictionary node "root": failed to instantiate: Traceback (most recent '
            'call last):\n  File "x.py", line 5, in <module>\nValueError: bad beta')
    assert one_line(text) == 'At dictionary node "root": failed to instantiate: bad beta'
    assert one_line(RuntimeError(text)) == 'At dictionary node "root": failed to instantiate: bad beta'
    assert one_line("[parser.cpp:451] Error while loading\n  the scene") == "Error while loading the scene"


def test_interrupt_in_a_flattened_traceback_is_seen():
    text = ('[parser.cpp:1718] At dictionary node "root": failed to instantiate: Traceback (most recent '
            'call last):\n  File "x.py", line 5, in __init__\nKeyboardInterrupt')
    assert is_interrupt(text)
    assert is_interrupt(RuntimeError(text))
    assert not is_interrupt("interrupted by nothing")


def test_nanobind_argument_errors_are_condensed():
    text = ("arange(): incompatible function arguments. The following argument types are supported:\n"
            "    1. arange(dtype: type[T], size: int) -> T\n\nInvoked with types: type, str")
    assert one_line(text) == "arange(): incompatible function arguments (invoked with types: type, str)"
