"""Loading Mitsuba XML scenes with overrides, by editing the parser's state.

XML scenes (:func:`foveated_mi.scenes.load_scene` with a path) are parsed with Mitsuba 3.9's
scene parser (:mod:`mi.parser`), whose intermediate representation is edited before
instantiation: film ``width``/``height`` and sampler ``sample_count`` are set on their nodes,
and an ``integrator`` dict is parsed with :func:`mi.parser.parse_dict` and spliced in place of
the file's integrator node. This works whether or not the file declares ``<default>``
parameters (of the shared scenes only ``lego`` declares ``resx``/``resy``/``spp``;
``staircase`` and ``voxel-monument`` hard-code their film), so no XML text is rewritten and
relative mesh and texture paths resolve against the scene's folder. The alternatives fall
short: ``mi.load_file(path, resx=...)`` only reaches declared ``<default>`` parameters (others
fail with "Found unused parameters"); a loaded scene's integrator cannot be replaced; and an
instantiated integrator object stored in the parsed root was dropped by
``transform_merge_meshes`` (checked with Mitsuba 3.9.1). Version 0.x files (``staircase``) are
upgraded first (``maxDepth`` -> ``max_depth``), as ``mi.load_file`` does.

A bad option of the file's ``foveated`` integrator is reported as one line naming the file,
the XML line and the option (``scene.xml, line 2: foveated integrator: theta = -1.0 is
invalid: expected a finite number > 0``), also when an ``integrator`` given here replaces it;
other errors name the file and Mitsuba's reason, without its Python traceback.
"""
from __future__ import annotations

import os
import re
import warnings

import mitsuba as mi

from ..validate import ParameterError
from .camera import film_dict, look_at, principal_point_props


def _splice_dict(state: "mi.parser.ParserState", config: "mi.parser.ParserConfig",
                 d: dict, index: int | None = None) -> int:
    """Parse plugin dict ``d`` and put its nodes into ``state``; returns its root node's index.

    The root replaces node ``index`` when given (references to it now point at ``d``),
    otherwise it is appended; nested nodes are appended with their references re-based.
    """
    sub = mi.parser.parse_dict(config, d)
    nodes = state.nodes
    base = len(nodes)
    new_index = {0: base if index is None else index}
    for k in range(1, len(sub.nodes)):
        new_index[k] = base + (k - 1 if index is not None else k)
    Ref = mi.Properties.ResolvedReference
    for k, node in enumerate(sub.nodes):
        node = mi.parser.SceneNode(node)
        for key in node.props.keys():
            if node.props.type(key) == mi.Properties.Type.ResolvedReference:
                node.props[key] = Ref(new_index[node.props[key].index()])
        if k == 0 and index is not None:
            node.file_index, node.offset = nodes[index].file_index, nodes[index].offset
            nodes[index] = node
        else:
            nodes.append(node)
    return new_index[0]


# "[parser.cpp:1718] ": where in Mitsuba's sources the error was raised, noise to a user.
_SOURCE_TAG = re.compile(r"\[[\w.]+\.(?:cpp|h|inl):\d+\]\s*")
# Where Mitsuba's parser says the foveated plugin failed: "At FILE (line 2, col 6): failed
# to instantiate integrator plugin of type "foveated": ..."
_AT_FOVEATED = re.compile(r'At (?P<file>.+?) \(line (?P<line>\d+), col \d+\): failed to '
                          r'instantiate \w+ plugin of type "foveated"')


def _one_line(e: Exception) -> str:
    """Mitsuba's (possibly multi-line) error message on one line, without the source tags
    and without the frames of a Python traceback it quotes (its last line, the exception,
    is kept)."""
    parts, in_traceback = [], False
    for line in _SOURCE_TAG.sub("", str(e)).splitlines():
        head, tb, _ = line.partition("Traceback (most recent call last):")
        if tb:
            parts.append(head)
            in_traceback = True
        elif not (in_traceback and line.startswith("  ")):   # a frame and its code line
            in_traceback = False
            parts.append(line)
    return " ".join(p.strip() for p in parts if p.strip()) or type(e).__name__


def _located(e: ParameterError, source: str, line: int | None) -> ParameterError:
    """``e`` of the foveated integrator of ``source`` re-issued as ``SOURCE, line N: foveated
    integrator: NAME = VALUE is invalid: expected ...``."""
    where = source if line is None else f"{source}, line {line}"
    err = ParameterError(f"{where}: foveated integrator: {e.name}", e.value, e.allowed)
    err.key, err.source, err.line = e.name, source, line
    return err


def _override_error(e: ParameterError) -> ParameterError:
    """``e`` of a foveated integrator given as the ``integrator`` dict, re-issued as
    ``integrator.NAME = VALUE is invalid: expected ...``."""
    err = ParameterError(f"integrator.{e.name}", e.value, e.allowed)
    err.key = e.name
    return err


def _instantiate_error(e: RuntimeError, path: str, override: bool) -> ParameterError:
    """Mitsuba's instantiation error as one line: a foveated option's ParameterError with
    its file and line when that is the cause, else the file and Mitsuba's reason. With an
    ``override`` integrator the cause is the override's: the file's own integrator was
    replaced (and checked by :func:`_check_replaced`), though Mitsuba reports its line."""
    from ..integrators import take_plugin_error
    text = str(e)
    cause = take_plugin_error(text)
    if cause is None:
        return ParameterError("scene", path, f"a loadable Mitsuba XML file ({_one_line(e)})")
    if override:
        return _override_error(cause)
    at = _AT_FOVEATED.search(text)
    return _located(cause, at["file"] if at else path, int(at["line"]) if at else None)


def _line_of(path: str, offset: int) -> int | None:
    """1-based line of byte ``offset`` in ``path`` (None when unreadable)."""
    try:
        with open(path, "rb") as f:
            return f.read(offset).count(b"\n") + 1
    except OSError:
        return None


def _check_replaced(state: "mi.parser.ParserState", index: int, path: str) -> None:
    """Check the options of a foveated integrator node that an override replaces: dropped
    silently, its mistakes would go unseen (a study always replaces the file's integrator)."""
    node = state.nodes[index]
    if node.props.plugin_name() != "foveated":
        return
    from ..integrators.foveated import FoveatedIntegrator
    props = mi.Properties(node.props)
    for key in list(props.keys()):
        if props.type(key) == mi.Properties.Type.ResolvedReference:
            del props[key]      # its nested integrator: replaced as well, not checked here
    try:
        with warnings.catch_warnings():     # advice on options of an integrator not used
            warnings.simplefilter("ignore")
            FoveatedIntegrator(props)
    except ParameterError as e:
        files = state.files      # the scene and its <include>s; the node names its own
        source = str(files[node.file_index]) if node.file_index < len(files) else path
        raise _located(e, source, _line_of(source, node.offset)) from None


def _xml_state(path: str, params: dict) -> tuple:
    config = mi.parser.ParserConfig(mi.variant())
    values = {}
    for key, value in params.items():
        if isinstance(value, bool):
            value = "true" if value else "false"
        if not isinstance(value, (str, int, float)):
            raise ParameterError(key, value, "a string or number for the XML parameter "
                                 f"${key} of {path}")
        values[key] = str(value)
    try:
        state = mi.parser.parse_file(config, path, **values)
    except RuntimeError as e:
        raise ParameterError("scene", path,
                             f"a loadable Mitsuba XML file ({_one_line(e)})") from None
    return config, state


def _children(state, node_index: int, kind: "mi.ObjectType") -> list[int]:
    props = state.nodes[node_index].props
    out = []
    for key in props.keys():
        if props.type(key) == mi.Properties.Type.ResolvedReference:
            j = props[key].index()
            if state.nodes[j].type == kind:
                out.append(j)
    return out


def _load_xml(path: str, width, height, spp, integrator, camera, params) -> "mi.Scene":
    config, state = _xml_state(path, params)
    mi.parser.transform_upgrade(config, state)      # e.g. maxDepth -> max_depth (v0.x files)
    sensors = _children(state, 0, mi.ObjectType.Sensor)
    for s in sensors:
        films = _children(state, s, mi.ObjectType.Film)
        if (width is not None or height is not None) and not films:
            _add_child(state, config, s, film_dict(width or 768, height or 576))
        for f in films:
            if width is not None:
                state.nodes[f].props["width"] = width
            if height is not None:
                state.nodes[f].props["height"] = height
            for key in ("crop_offset_x", "crop_offset_y", "crop_width", "crop_height"):
                if (width is not None or height is not None) and key in state.nodes[f].props:
                    del state.nodes[f].props[key]   # a crop of the old size would not fit
        samplers = _children(state, s, mi.ObjectType.Sampler)
        if spp is not None and not samplers:
            _add_child(state, config, s, {"type": "independent", "sample_count": spp})
        for sm in samplers:
            if spp is not None:
                state.nodes[sm].props["sample_count"] = spp
        if camera is not None:
            props = state.nodes[s].props
            for key in ("fov", "fov_axis", "focal_length", "principal_point_offset_x",
                        "principal_point_offset_y"):
                if key in props:
                    del props[key]
            props["to_world"] = look_at(camera)
            props["fov"] = camera["fov"]
            props["fov_axis"] = "x"
            for key, value in principal_point_props(camera).items():
                props[key] = value
    if integrator is not None:
        old = _children(state, 0, mi.ObjectType.Integrator)
        if old:
            _check_replaced(state, old[0], path)
            _splice_dict(state, config, integrator, old[0])
        else:
            _add_child(state, config, 0, integrator)
    mi.parser.transform_all(config, state)
    # Relative file names (meshes, textures) resolve against the scene's folder, as in
    # mi.load_file; the search path is restored afterwards.
    resolver = mi.file_resolver()
    resolver.prepend(os.path.dirname(path))
    try:
        scene = mi.parser.instantiate(config, state)
    except RuntimeError as e:
        raise _instantiate_error(e, path, integrator is not None) from None
    finally:
        del resolver[0]
    return scene


def _add_child(state, config, parent: int, d: dict) -> None:
    index = _splice_dict(state, config, d)
    props = state.nodes[parent].props
    k = 0
    while f"_arg_{k}" in props or f"_override_{k}" in props:
        k += 1
    props[f"_override_{k}"] = mi.Properties.ResolvedReference(index)

