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
"""
from __future__ import annotations

import os

import mitsuba as mi

from ..validate import ParameterError
from .camera import film_dict, look_at


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


def _one_line(e: Exception) -> str:
    """Mitsuba's (possibly multi-line) error message on one line."""
    return " ".join(part.strip() for part in str(e).splitlines()) or type(e).__name__


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
            for key in ("fov", "fov_axis", "focal_length"):
                if key in props:
                    del props[key]
            props["to_world"] = look_at(camera)
            props["fov"] = camera["fov"]
            props["fov_axis"] = "x"
    if integrator is not None:
        old = _children(state, 0, mi.ObjectType.Integrator)
        if old:
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
        raise ParameterError("scene", path,
                             f"a loadable Mitsuba XML file ({_one_line(e)})") from None
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

