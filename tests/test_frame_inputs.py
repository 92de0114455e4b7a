"""The options do not travel through the frame: while a frame renders, no function of the
package outside the modules that read the options into settings receives them, under any
name, nor a mapping that carries them (the source rule is
``tests/test_code_shape.py::test_no_pass_takes_the_options``); the stats carry them still."""
from __future__ import annotations

import dataclasses
import inspect
import pathlib
import sys
from collections.abc import Mapping

import mitsuba as mi
import pytest

import foveated_mi
from foveated_mi.integrators.foveated import FoveatedIntegrator
from foveated_mi.scenes import load_scene

PACKAGE = pathlib.Path(foveated_mi.__file__).resolve().parent
#: As ``tests/test_code_shape.py``'s ``OPTION_READERS``: the modules that may take them.
OPTION_READERS = ("options.py", "configure.py", "integrators/foveated.py", "budget.py",
                  "render.py", "cli.py")


def carries(value, options: list[dict], names: set[str], depth: int = 1) -> bool:
    """Whether ``value`` is one of ``options``, or a mapping that holds most of their
    ``names`` (a copy, a subset), or (``depth`` levels down) a dataclass, named tuple or
    sequence that holds one."""
    if any(value is o for o in options):
        return True
    if isinstance(value, Mapping):
        if len(names.intersection(k for k in value if isinstance(k, str))) * 2 > len(names):
            return True
        inner = list(value.values())
    elif dataclasses.is_dataclass(value) and not isinstance(value, type):
        inner = [getattr(value, f.name, None) for f in dataclasses.fields(value)]
    elif isinstance(value, (tuple, list)):
        inner = list(value)
    else:
        return False
    return depth > 0 and any(carries(v, options, names, depth - 1) for v in inner)


class Spy:
    """Records every call into the package outside the readers whose arguments carry the
    options (:func:`carries`); the options are the integrator's and each frame's view of
    them (the return values of ``_view_options``)."""

    def __init__(self, integrator: FoveatedIntegrator):
        self.options = [integrator._options]
        self.names = set(integrator._options)
        self.calls = 0
        self.found: list[str] = []

    def __call__(self, frame, event, arg):
        if event not in ("call", "return"):
            return
        path = pathlib.Path(frame.f_code.co_filename)
        if PACKAGE not in path.parents:
            return
        where = path.relative_to(PACKAGE).as_posix()
        if event == "return":
            if frame.f_code.co_name == "_view_options" and isinstance(arg, dict):
                self.options.append(arg)
            return
        if where in OPTION_READERS:
            return
        self.calls += 1
        info = inspect.getargvalues(frame)
        args = {n: info.locals[n] for n in info.args if n in info.locals}
        if info.varargs:
            args["*" + info.varargs] = info.locals[info.varargs]
        if info.keywords:
            args["**" + info.keywords] = info.locals[info.keywords]
        self.found += [f"{where}:{frame.f_code.co_name}({n})" for n, v in args.items()
                       if carries(v, self.options, self.names)]


def _frames_under_spy(integrator, scene, frames: int) -> Spy:
    spy = Spy(integrator)
    sys.setprofile(spy)
    try:
        for k in range(frames):
            mi.render(scene, integrator=integrator, seed=k)
    finally:
        sys.setprofile(None)
    return spy


def test_the_spy_sees_a_function_that_takes_the_options():
    """The check fails where a function of the package receives them, or a copy."""
    options = {f"option_{k}": k for k in range(10)}
    names = set(options)
    assert carries(options, [options], names)
    assert carries({k: v for k, v in options.items() if k != "option_0"}, [options], names)
    assert carries((1, {**options, "gaze_tracked": [0.5, 0.5]}), [options], names)
    assert not carries({"option_0": 0, "width": 32}, [options], names)
    assert not carries([1, 2.0, "film"], [options], names)


@pytest.mark.parametrize("preset", ["paper", "vr"])
def test_no_frame_function_receives_the_options(preset):
    """Two frames with history (a film-space and a foveal-buffer preset): the frame's passes
    receive their settings and inputs, never the options; the stats still carry them."""
    scene = load_scene("cornell-box", width=48, height=32, spp=1)
    integrator = FoveatedIntegrator(nested=scene.integrator(), preset=preset)
    mi.render(scene, integrator=integrator, seed=0)     # compiles outside the spy
    spy = _frames_under_spy(integrator, scene, 2)
    assert spy.calls > 100                               # it saw the frame's functions
    assert spy.found == []
    stats = integrator.stats
    assert stats["preset"] == preset and stats["sigma_p"] == integrator.options["sigma_p"]
    assert "timing" not in stats and stats["frame"] == integrator.frame - 1
