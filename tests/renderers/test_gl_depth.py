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
