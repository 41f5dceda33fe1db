"""The GL side of the depth maps: importing the renderers leaves the GL platform alone; making a renderer picks
EGL unless the user chose one."""
from __future__ import annotations


def test_importing_the_renderers_sets_no_gl_platform_and_a_users_choice_is_kept():
    import os
    import subprocess
    import sys

    code = ("import os, renderers, renderers.gl_depth as gl_depth; print(os.environ.get('PYOPENGL_PLATFORM')); "
            "gl_depth.use_headless_gl(); print(os.environ['PYOPENGL_PLATFORM'])")
    env = {k: v for k, v in os.environ.items() if k != "PYOPENGL_PLATFORM"}
    out = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True, check=True).stdout
    assert out.split() == ["None", "egl"]
    chosen = subprocess.run([sys.executable, "-c", code], env={**env, "PYOPENGL_PLATFORM": "osmesa"},
                            capture_output=True, text=True, check=True).stdout
    assert chosen.split() == ["osmesa", "osmesa"]




def test_a_renderer_dropped_without_close_leaves_the_others_drawing():
    # the EGL display is one per process: pyrender's own clean-up of a dropped renderer terminated it, and the
    # next pass of every other renderer failed with EGL_BAD_CONTEXT
    import gc

    import numpy as np

    import species
    from renderers import ViewRenderer

    skeleton, tree = species.rebuild(species.sample("maple", np.random.default_rng(0)))
    kept, dropped = ViewRenderer(48), ViewRenderer(48)
    before = kept.render(tree, skeleton, "tsn4", ["mask"], np.random.default_rng(0))
    dropped.render(tree, skeleton, "tsn4", ["mask"], np.random.default_rng(0))
    del dropped
    gc.collect()
    after = kept.render(tree, skeleton, "tsn4", ["mask"], np.random.default_rng(0))
    kept.close()
    assert len(after) == len(before) and (before[0].images["mask"] > 0).mean() > 0.02
    for old, new in zip(before, after):
        np.testing.assert_array_equal(new.images["mask"], old.images["mask"])
