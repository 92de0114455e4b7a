"""Bad input that would end in a traceback, options that would be silently ignored, and the
EXR layers the README promises: each a one-line error (exit 2, nothing written), a one-line
warning, or a layer list checked against what a render writes."""
import os
import re
import sys
import warnings

import mitsuba as mi
import pytest

from foveated_mi import cli
from foveated_mi import config as config_module
from foveated_mi.cli import main
from foveated_mi.configure import (DENOISER_OPTIONS, FILM_OPTIONS, FOVEAL_OPTIONS,
                                   LAW_OPTIONS, ignored_options)
from foveated_mi.integrators.foveated import FoveatedIntegrator
from foveated_mi.io import read_exr
from foveated_mi.options import SCHEMA, IgnoredOptionWarning, denoisers, validate_options
from foveated_mi.scenes import (check_integrator_type, integrator_names, load_scene,
                                scene_dict)
from foveated_mi.validate import ParameterError

README = os.path.join(os.path.dirname(__file__), "..", "README.md")

STUDY = """seed = 0
size = [16, 16]
[[scenes]]
scene = "cornell-box"
[foveated.grid]
theta = [0.1, 0.2]
"""

SEQUENCE = """scene = "cornell-box"
frames = 1
size = [16, 16]
"""


def run(args, capsys):
    code = main(args)
    out = capsys.readouterr()
    return code, out.out, out.err


def one_line_exit_2(args, out_dir, capsys, *needles):
    """Run the CLI: exit 2, one line on stderr holding every needle, nothing written."""
    code, _, err = run(args + ["--out", str(out_dir)], capsys)
    lines = err.strip().splitlines()
    assert code == 2 and len(lines) == 1, err
    assert "Traceback" not in err and lines[0].startswith("foveated-mi: error: "), err
    for needle in needles:
        assert needle in lines[0], (needle, lines[0])
    assert not os.path.exists(out_dir)
    return lines[0]


# -- files that are not TOML text ------------------------------------------------------------

@pytest.mark.parametrize("command", ["study", "sequence"])
def test_a_file_that_is_not_utf8_is_one_line(tmp_path, capsys, command):
    bad = tmp_path / "bad.toml"
    bad.write_bytes(b"\xff\xfe s\x00e\x00e\x00d\x00 = 0")    # UTF-16, say
    line = one_line_exit_2([command, str(bad), "--no-progress"], tmp_path / "out", capsys,
                           str(bad), "UTF-8", "0xff at offset 0")
    assert "UnicodeDecodeError" not in line


@pytest.mark.parametrize("command", ["study", "sequence"])
def test_an_unreadable_file_is_one_line(tmp_path, capsys, monkeypatch, command):
    path = tmp_path / "locked.toml"
    path.write_text(STUDY if command == "study" else SEQUENCE)

    def refuse(*args, **kwargs):    # root reads a file of mode 000: refuse as the OS would
        raise PermissionError(13, "Permission denied", str(path))
    monkeypatch.setattr(config_module, "open", refuse, raising=False)
    one_line_exit_2([command, str(path), "--no-progress"], tmp_path / "out", capsys,
                    str(path), "a readable TOML file (Permission denied)")


def test_a_folder_is_not_a_toml_file(tmp_path, capsys):
    folder = tmp_path / "dir.toml"
    folder.mkdir()
    one_line_exit_2(["study", str(folder)], tmp_path / "out", capsys, "an existing TOML file")


# -- a misspelt nested integrator ------------------------------------------------------------

def test_a_sequence_with_a_misspelt_integrator_fails_at_parse_time(tmp_path, capsys):
    path = tmp_path / "seq.toml"
    path.write_text(SEQUENCE + '[integrator]\ntype = "pth"\nmax_depth = 3\n')
    one_line_exit_2(["sequence", str(path), "--no-progress"], tmp_path / "out", capsys,
                    f"{path}: integrator.type = 'pth' is invalid", "did you mean 'path'?")


def test_a_study_with_a_misspelt_integrator_fails_before_any_task(tmp_path, capsys):
    path = tmp_path / "study.toml"
    path.write_text(STUDY.replace("[[scenes]]", '[integrator]\ntype = "volpth"\n[[scenes]]'))
    one_line_exit_2(["study", str(path), "--no-progress"], tmp_path / "out", capsys,
                    f"{path}: integrator.type = 'volpth' is invalid", "did you mean 'volpath'?")
    # A scene's own integrator too, under its dotted key.
    path.write_text(STUDY + '[scenes.integrator]\ntype = "prbb"\n')
    one_line_exit_2(["study", str(path), "--no-progress"], tmp_path / "out", capsys,
                    "scenes[0].integrator.type = 'prbb'", "did you mean 'prb'?")


def test_load_scene_checks_the_integrator_of_builtins_xml_and_foveated(tmp_path):
    with pytest.raises(ParameterError, match=r"^integrator\.type = 'pth' is invalid: "
                       r"expected a Mitsuba integrator plugin \(did you mean 'path'\?\)$"):
        load_scene("cornell-box", width=8, height=8, integrator={"type": "pth"})
    with pytest.raises(ParameterError, match=r"^integrator\.nested\.type = 'pth'"):
        scene_dict("cornell-box", integrator={"type": "foveated",
                                              "nested": {"type": "pth"}})
    xml = tmp_path / "s.xml"
    xml.write_text('<scene version="3.0.0"><integrator type="path"/>'
                   '<shape type="sphere"/><sensor type="perspective"/></scene>')
    with pytest.raises(ParameterError, match=r"^integrator\.type = 'diffuse' is invalid: "
                       r"expected an integrator plugin, not a bsdf plugin"):
        load_scene(str(xml), integrator={"type": "diffuse"})
    # Spelt right, all three load.
    assert load_scene(str(xml), integrator={"type": "direct"}) is not None


def test_the_listed_integrators_load_and_registered_ones_pass():
    names = integrator_names()
    assert {"path", "volpath", "direct", "prb", "foveated"} <= set(names)
    for name in names:
        try:
            mi.load_dict({"type": name})
        except RuntimeError as e:       # only for want of a property it needs (aov's aovs)
            assert "cannot be found" in str(e), (name, str(e))

    class Mine(mi.SamplingIntegrator):
        def to_string(self):
            return "Mine"
    mi.register_integrator("bad_input_mine", lambda props: Mine(props))
    assert check_integrator_type("integrator.type", "bad_input_mine") == "bad_input_mine"
    # One Mitsuba cannot find, close to no listed name: the list itself.
    with pytest.raises(ParameterError, match=r"a Mitsuba integrator plugin \(allowed here: "
                       r"aov, depth, direct"):
        check_integrator_type("integrator.type", "bad_input_mien")


# -- options that nothing reads --------------------------------------------------------------

def _ignored(caught):
    return [str(w.message) for w in caught if issubclass(w.category, IgnoredOptionWarning)]


def test_the_cli_warns_once_of_an_option_the_default_preset_does_not_read(tmp_path, capsys):
    exr = tmp_path / "f.exr"
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        code, _, err = run(["render", "cornell-box", "--theta", "0.1", "--sigma-p", "0.8",
                            "--size", "32", "24", "--warmup", "1", "--out", str(exr),
                            "--quiet"], capsys)
    assert code == 0, err
    # theta sizes the vr preset's disc: read. sigma_p is Eq. 1's alone. Two frames, one line.
    assert _ignored(caught) == [
        "sigma_p = 0.8 has no effect under preset 'vr' (sampling_law 'polar'); it is read by "
        "sampling_law 'kwon' (e.g. preset 'paper')"]


def test_the_cli_prints_a_warning_in_one_line(tmp_path, capsys, monkeypatch):
    """As Python would print it (its default hook), but in the command line's one line."""
    def show(message, category, filename, lineno, file=None, line=None):
        sys.stderr.write(warnings.formatwarning(message, category, filename, lineno, line))
    monkeypatch.setattr(warnings, "showwarning", show)
    with warnings.catch_warnings():
        warnings.simplefilter("always", IgnoredOptionWarning)
        code, _, err = run(["render", "cornell-box", "--sigma-p", "0.8", "--size", "32", "24",
                            "--warmup", "0", "--out", str(tmp_path / "f.exr"), "--quiet"],
                           capsys)
    assert code == 0, err
    lines = [x for x in err.splitlines() if "sigma_p" in x]
    assert lines == ["foveated-mi: warning: sigma_p = 0.8 has no effect under preset 'vr' "
                     "(sampling_law 'polar'); it is read by sampling_law 'kwon' (e.g. preset "
                     "'paper')"], err
    assert warnings.formatwarning is not cli._one_line_warning     # restored after the run


def test_the_integrator_warns_once_and_not_for_what_a_preset_sets():
    scene = load_scene("cornell-box", width=32, height=24)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        integ = FoveatedIntegrator(nested=scene.integrator(), theta=0.1, sigma_p=0.8)
        for seed in (0, 1):
            mi.render(scene, integrator=integ, seed=seed)
        integ.set_options(gaze=(0.4, 0.5))                 # an unrelated change: silent
        paper = FoveatedIntegrator(preset="paper", theta=0.1, sigma_p=0.8)
        FoveatedIntegrator(preset="vr")                      # its own ray_budget, theta, ...
        FoveatedIntegrator(preset="guided")
        FoveatedIntegrator(preset="oidn") if denoisers()["oidn"].available() else None
    said = _ignored(caught)
    assert len(said) == 1 and said[0].startswith("sigma_p = 0.8 has no effect under preset "
                                                 "'vr' (sampling_law 'polar')"), said
    assert "\n" not in said[0]
    assert paper.options["sigma_p"] == 0.8
    with warnings.catch_warnings(record=True) as caught:     # a change that makes it anew
        warnings.simplefilter("always")
        integ.set_options(sigma_p=0.5)
    assert _ignored(caught) == [said[0].replace("0.8", "0.5")]


@pytest.mark.parametrize("given,option,why", [
    ({"preset": "paper", "ray_budget": 0.2}, "ray_budget", "sampling_law 'kwon'"),
    ({"preset": "paper", "theta_deg": 5.0, "theta": 0.2}, "theta", "theta_deg = 5"),
    ({"preset": "vr", "reconstruction": "guided"}, "reconstruction", "formation 'foveal'"),
    ({"preset": "vr", "viewer_ppd": 20.0}, "viewer_ppd", "polar_cells 'log'"),
    ({"preset": "guided", "sigma_color": 0.3}, "sigma_color", "denoiser 'svgf'"),
    ({"preset": "guided", "sibson_inclusive": False}, "sibson_inclusive",
     "reconstruction 'guided'"),
    ({"preset": "paper", "foveal_disc": "resolved"}, "foveal_disc", "formation 'film'"),
])
def test_each_kind_of_unread_option_is_named(given, option, why):
    said = ignored_options(given, validate_options(given))
    assert list(said) == [option]
    assert f"under preset '{given['preset']}' ({why}); it is read by" in said[option]


def test_no_preset_warns_of_its_own_options():
    from foveated_mi.options import PRESETS
    for preset, values in PRESETS.items():
        given = {"preset": preset, **values}    # as if the user had typed the preset's values
        said = ignored_options(given, validate_options(given))
        # vr's disc-less options aside, what a preset sets is what it reads.
        assert said == {}, (preset, said)


def test_options_resolved_and_passed_on_warn_of_nothing():
    # A study's task holds every option, resolved: which the user set is not known there.
    full = validate_options({"preset": "guided"})
    del full["gaze"], full["timing"]                   # given with each frame
    assert ignored_options(full, validate_options(full)) == {}


def test_the_tables_name_options_of_the_schema():
    for name in (*LAW_OPTIONS, *FILM_OPTIONS, *FOVEAL_OPTIONS, *DENOISER_OPTIONS):
        assert name in SCHEMA, name
    reads = {n for d in denoisers().values() for n in d.reads}
    assert set(DENOISER_OPTIONS) - {"sigma_luminance_moving"} <= reads


# -- the README's EXR layers -----------------------------------------------------------------

def readme_layer_rows():
    """``(flags, layers)`` of each preset the README's sentence on EXR layers names: its
    ``FLAGS, FLAGS: LAYER, LAYER, ...`` groups."""
    with open(README, encoding="utf-8") as f:
        text = " ".join(f.read().split())
    start = text.index("The EXR's layers: ")
    sentence = text[start:text.index(" (`full`", start)]
    rows = []
    for flags, layers in re.findall(r"((?:`--preset \w+`(?:, )?)+)(?: \(the default\))?: "
                                    r"((?:`\w+`(?:, )?)+)", sentence):
        for flag in re.findall(r"`([^`]+)`", flags):
            rows.append((flag.split(), re.findall(r"`([^`]+)`", layers)))
    return rows


def test_the_readme_lists_every_preset():
    presets = {flags[1] for flags, _ in readme_layer_rows()}
    assert presets == {"paper", "guided", "oidn", "vr", "auto"}


@pytest.mark.parametrize("flags,layers", readme_layer_rows(),
                         ids=lambda v: " ".join(v) if isinstance(v[0], str) and
                         v[0].startswith("--") else None)
def test_the_exr_holds_the_layers_the_readme_lists(tmp_path, capsys, flags, layers):
    if "oidn" in flags and not denoisers()["oidn"].available():
        pytest.skip("Open Image Denoise is not installed")
    exr = tmp_path / "f.exr"
    code, _, err = run(["render", "cornell-box", *flags, "--size", "32", "24", "--warmup", "0",
                        "--out", str(exr), "--quiet"], capsys)
    assert code == 0, err
    assert sorted(read_exr(exr)) == sorted(layers)
