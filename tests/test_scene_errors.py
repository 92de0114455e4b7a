"""A bad option of an XML scene's foveated integrator is one line naming the file, the XML line,
the option, its value and what is allowed: from the CLI, a study and load_scene."""
import textwrap

import mitsuba as mi
import pytest

from foveated_mi.cli import main
from foveated_mi.scenes import load_scene
from foveated_mi.study import run_study
from foveated_mi.validate import ParameterError

# The integrator is on line 4, so a line number taken from anywhere else shows.
SCENE = """\
<scene version="3.0.0">
    <sensor type="perspective"><film type="hdrfilm"><integer name="width" value="16"/>
        <integer name="height" value="16"/></film></sensor>
    <integrator type="{plugin}">{option}</integrator>
    <shape type="sphere"/>
    <emitter type="constant"/>
</scene>
"""

BAD = {
    "range": ('<float name="theta" value="-1"/>',
              "theta = -1.0 is invalid: expected a finite number > 0"),
    "unknown": ('<float name="thetta" value="0.2"/>',
                "thetta = 0.2 is invalid: expected a known parameter (did you mean 'theta'?)"),
    "preset": ('<string name="preset" value="hmd"/>',
               "preset = 'hmd' is invalid: expected one of 'auto', 'paper'"),
}


def scene_file(tmp_path, kind, plugin="foveated"):
    option = BAD[kind][0] if kind in BAD else kind
    p = tmp_path / f"bad_{plugin}.xml"
    p.write_text(SCENE.format(plugin=plugin, option=option))
    return str(p)


def expected(path, kind):
    return f"{path}, line 4: foveated integrator: {BAD[kind][1]}"


def one_line(text):
    assert "\n" not in text.strip() and "Traceback" not in text and "parser.cpp" not in text, text
    return text.strip()


@pytest.mark.parametrize("kind", list(BAD))
def test_cli_bad_xml_option_is_one_line_exit_2(kind, tmp_path, capsys):
    path = scene_file(tmp_path, kind)
    out = tmp_path / "f.exr"
    code = main(["render", path, "--warmup", "0", "--out", str(out), "--stats",
                 str(tmp_path / "s.json")])
    err = one_line(capsys.readouterr().err)
    assert code == 2
    assert err.startswith("foveated-mi: error: " + expected(path, kind)), err
    assert sorted(p.name for p in tmp_path.iterdir()) == ["bad_foveated.xml"]   # nothing else


@pytest.mark.parametrize("kind", list(BAD))
def test_study_reports_the_same_line(kind, tmp_path):
    path = scene_file(tmp_path, kind)
    study = tmp_path / "study.toml"
    study.write_text(textwrap.dedent("""
        repeats = 1
        warmup = 0
        size = [16, 16]
        [reference]
        spp = 1
        [[scenes]]
        scene = "bad_foveated.xml"
        label = "bad"
        [[foveated.configs]]
        theta = 0.2
        frames = [1]
    """))
    result = run_study(str(study), out=str(tmp_path / "out"), progress=False, echo=None)
    assert result.rows == [] and len(result.failed) == 2, result.failed
    first = one_line(result.failed[0])
    assert first.startswith("reference of bad failed: ParameterError: " + expected(path, kind))
    assert one_line(result.failed[1]).endswith("not run: its reference failed")


@pytest.mark.parametrize("name, close", [("thetta", "theta"), ("sigmap", "sigma_p"),
                                         ("zzzz", None)])
def test_an_unknown_option_names_the_closest_one_in_a_short_line(name, close, tmp_path):
    """Not the list of every option: the closest one, or where they are listed."""
    from foveated_mi.integrators.foveated import FoveatedIntegrator
    with pytest.raises(ParameterError) as info:
        FoveatedIntegrator(**{name: 0.1})
    python = one_line(str(info.value))
    assert python.startswith(f"{name} = 0.1 is invalid: expected an option of the foveated "
                             "integrator"), python
    path = scene_file(tmp_path, f'<float name="{name}" value="0.1"/>')
    with pytest.raises(ParameterError) as info:
        load_scene(path)
    where = f"{path}, line 4: "
    xml = one_line(str(info.value))
    assert xml.startswith(where + f"foveated integrator: {name} = 0.1 is invalid: "), xml
    for msg in (python, xml[len(where):]):
        assert len(msg) < 120, msg
        if close is None:
            assert "did you mean" not in msg and msg.endswith(
                "(none is close; see `foveated-mi render --help`)"), msg
        else:
            assert msg.endswith(f"(did you mean {close!r}?)"), msg


@pytest.mark.parametrize("integrator", [None, {"type": "path"}])
def test_load_scene_raises_one_line(integrator, tmp_path):
    # With an integrator given, the file's own is replaced (as a study does): still checked.
    path = scene_file(tmp_path, "range")
    with pytest.raises(ParameterError) as info:
        load_scene(path, integrator=integrator)
    assert one_line(str(info.value)) == expected(path, "range")
    assert (info.value.key, info.value.source, info.value.line) == ("theta", path, 4)
    assert (info.value.value, info.value.allowed) == (-1.0, "a finite number > 0")


def test_other_xml_errors_name_the_file_and_mitsubas_reason(tmp_path):
    broken = tmp_path / "broken.xml"
    broken.write_text('<scene version="3.0.0">\n  <shape type="sphere">\n</scene>\n')
    with pytest.raises(ParameterError) as info:
        load_scene(str(broken))
    msg = one_line(str(info.value))
    assert str(broken) in msg and "Start-end tags mismatch (line 3" in msg, msg

    # A Python plugin's own exception: its last line is kept, the traceback frames are not.
    class Raises(mi.SamplingIntegrator):
        def __init__(self, props):
            super().__init__(props)
            raise KeyError("boom")
    mi.register_integrator("raises_in_test", lambda props: Raises(props))
    path = scene_file(tmp_path, "", plugin="raises_in_test")
    with pytest.raises(ParameterError) as info:
        load_scene(path)
    msg = one_line(str(info.value))
    assert path in msg and "line 4" in msg and msg.endswith("KeyError: 'boom')"), msg
    assert "File " not in msg, msg


@pytest.mark.parametrize("scene", ["cornell-box", "xml"])
def test_bad_integrator_dict_is_one_line_and_not_blamed_on_the_file(scene, tmp_path):
    if scene == "xml":       # a valid file: the bad option is the dict's, not line 4's
        scene = scene_file(tmp_path, "", plugin="path")
    with pytest.raises(ParameterError) as info:
        load_scene(scene, width=8, height=8,
                   integrator={"type": "foveated", "theta": -1.0})
    assert one_line(str(info.value)) == ("integrator.theta = -1.0 is invalid: "
                                         "expected a finite number > 0")
