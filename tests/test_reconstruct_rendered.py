"""Reconstruction on a rendered frame: fast_sibson stays within 1 dB of sibson, and both beat
the Voronoi fill (issue 3)."""
import drjit as dr
import mitsuba as mi
import numpy as np

from foveated_mi import reconstruct as rec
from foveated_mi.frame.gbuffer import render_gbuffer
from foveated_mi.metrics import psnr
from foveated_mi.render import to_display
from foveated_mi.frame.sampling import depth_edges, sampling_map
from foveated_mi.scenes import load_scene


def test_fast_sibson_within_1db_of_sibson_on_rendered_frame():
    W, H = 96, 80
    scene = load_scene("eye-exam", width=W, height=H, spp=1,
                       integrator={"type": "path", "max_depth": 2})
    ref = mi.render(scene, spp=16, seed=3)   # converged enough: noise must not hide the fill
    ref_c = dr.unravel(mi.Color3f, ref.array)
    gb = render_gbuffer(scene, scene.sensors()[0])
    smap, _ = sampling_map(W, H, gaze=(0.5, 0.5), theta=0.1, sigma_p=0.8, seed=1,
                           edges=depth_edges(gb.depth, gb.hit, W, H, 0.1))
    shading = dr.select(smap, ref_c, 0.0)
    nearest = rec.jump_flood(smap, W, H)
    ref_d = to_display(np.array(ref))
    score = {}
    for method in ("voronoi", "sibson", "fast_sibson"):
        out = rec.reconstruct(method, shading, smap, nearest, W, H, max_radius=32)
        img = np.array(dr.ravel(out)).reshape(H, W, 3)
        score[method] = psnr(ref_d, to_display(img), data_range=1.0)
    assert abs(score["fast_sibson"] - score["sibson"]) <= 1.0, score
    assert score["sibson"] > score["voronoi"], score
