"""The Blender worker: scripts run by `.venv-blender/bin/python` (bpy, numpy<2), one JSON job file per call.

Nothing here is imported by the main environment except `cameras` (pure Python); `renderers.blender` drives it.
"""
from pathlib import Path

WORKER_SCRIPT = Path(__file__).with_name("worker.py")
REQUIREMENTS = Path(__file__).with_name("requirements.txt")
