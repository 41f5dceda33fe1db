"""Golden outputs: sha256 digests of what the farm writes, recorded with the dependency versions that made them.

`species_digests()` grows every preset (seed 0) and the TreeSketchNet dictionaries in `shared/data/sapling/` and
hashes skeleton arrays, GLB and OBJ bytes; `job_digests(folder)` runs a small default `farm generate` and hashes
every part file; `library_digests(folder)` runs a one-asset `farm library` (every format, Blender included) and
hashes every file but `manifest.json` and `_shards/` (timings, process ids, code version). `make golden` records
this machine's digests in the JSON files beside this module; `tests/test_golden.py` compares against them.

Rasterised outputs depend on the CPU as well as on the versions: llvmpipe (Mesa's CPU renderer) and the SIMD
kernels numpy and OpenCV dispatch to give other last bits on an AVX-512 machine than on an AVX2 one (the same
code and versions gave two digests of the default job's views). So each golden file holds one entry per
platform (`platform()`: the x86-64 level or machine, and the OpenGL renderer), and `make golden` rewrites only
this platform's entry. On a platform with no entry, the outputs whose digests agree on every recorded platform are
still checked; those that differ between platforms cannot be, and the test says so.
"""
from __future__ import annotations

import hashlib
import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[2]
GOLDEN_DIR = Path(__file__).resolve().parent
SAPLING_DICTS = ROOT.parent / "shared" / "data" / "sapling"
FARM = [sys.executable, "-m", "farm.cli"]

# A small job with the default rig and outputs (one tree of each generator and two shards), and a one-asset
# library with every format.
JOB_SPEC = {"name": "golden", "seed": 0, "shard_size": 2,
            "species": {"maple": 1, "palm": 1, "sc_young_sapling": 1, "lsystem_monopodial": 1}}
LIBRARY_SPEC = {"name": "golden", "seed": 0, "species": {"maple": 1}, "texture_size": 64, "impostor_tile": 32,
                "shard_size": 1}
# Files of a farm output folder that record timings, process ids or the code version, not outputs.
VOLATILE = ("manifest.json", "_shards/")


def sha256(data: bytes) -> str:
    return hashlib.sha256(data).hexdigest()


def arrays_digest(arrays: dict[str, np.ndarray]) -> str:
    """sha256 over each array's name, dtype, shape and bytes, in sorted name order."""
    digest = hashlib.sha256()
    for name in sorted(arrays):
        array = np.ascontiguousarray(arrays[name])
        digest.update(f"{name}:{array.dtype.str}:{array.shape};".encode())
        digest.update(array.tobytes())
    return digest.hexdigest()


def tree_digests(params: dict) -> dict[str, str]:
    """Digests of one dictionary's own tree: its skeleton arrays, GLB bytes and OBJ files."""
    import species

    skeleton = species.grow(params, species.rng_for(params))
    mesh = species.build_mesh(skeleton, params)
    obj_files = mesh.to_obj()
    obj = hashlib.sha256()
    for name in sorted(obj_files):
        obj.update(name.encode() + b"\0" + obj_files[name] + b"\0")
    return {"skeleton": arrays_digest(skeleton.to_arrays()), "glb": sha256(mesh.to_glb()), "obj": obj.hexdigest()}


def species_digests() -> dict[str, dict[str, str]]:
    """Every preset sampled with seed 0, and every dictionary of `shared/data/sapling/`, by name."""
    import species

    out = {}
    for preset in species.list_presets():
        params = species.sample(preset.name, np.random.default_rng(0))
        out[f"preset:{preset.name}"] = tree_digests(params)
    for path in sorted(SAPLING_DICTS.glob("*.json")):
        out[f"sapling:{path.name}"] = tree_digests(json.loads(path.read_text()))
    return out


def folder_digests(folder: Path) -> dict[str, str]:
    """sha256 of every file under `folder` by relative path, volatile records left out."""
    out = {}
    for path in sorted(folder.rglob("*")):
        relative = path.relative_to(folder).as_posix()
        if path.is_file() and not any(relative == v or relative.startswith(v) for v in VOLATILE):
            out[relative] = sha256(path.read_bytes())
    return out


def _farm(args: list[str]) -> None:
    env = dict(os.environ, PYOPENGL_PLATFORM="egl")
    result = subprocess.run(FARM + args, cwd=ROOT, env=env, capture_output=True, text=True)
    if result.returncode != 0:
        raise RuntimeError(f"farm {' '.join(args)} failed ({result.returncode}):\n{result.stdout}{result.stderr}")


def _spec_file(folder: Path, spec: dict) -> str:
    import yaml

    path = folder.parent / f"{folder.name}-spec.yaml"
    path.write_text(yaml.safe_dump(spec))
    return str(path)


def job_digests(folder: Path) -> dict[str, str]:
    """Run the small job into `folder` and hash its part files."""
    _farm(["generate", _spec_file(folder, JOB_SPEC), "--out", str(folder), "--workers", "1", "--quiet"])
    return folder_digests(folder)


def library_digests(folder: Path) -> dict[str, str]:
    """Run the one-asset library into `folder` and hash every file it wrote."""
    _farm(["library", _spec_file(folder, LIBRARY_SPEC), "--out", str(folder), "--workers", "1", "--quiet"])
    return folder_digests(folder)


def _gl_string(name: str) -> str:
    """An OpenGL string (VERSION, RENDERER) of the offscreen (EGL) context the renderers use."""
    code = ("import pyrender; from OpenGL import GL; r = pyrender.OffscreenRenderer(8, 8); "
            f"print(GL.glGetString(GL.GL_{name}).decode()); r.delete()")
    result = subprocess.run([sys.executable, "-c", code], env=dict(os.environ, PYOPENGL_PLATFORM="egl"),
                            capture_output=True, text=True)
    return result.stdout.strip() or f"unavailable ({result.stderr.strip().splitlines()[-1:]})"


def _bpy_version() -> str:
    found = sorted((ROOT / ".venv-blender").glob("lib/python*/site-packages/bpy-*.dist-info"))
    return found[-1].name[len("bpy-"):-len(".dist-info")] if found else "not installed"


def platform() -> str:
    """What besides the versions decides rasterised bytes: the CPU's x86-64 level as numpy detects it (or the
    machine name elsewhere), its vendor, and the OpenGL renderer, e.g. "x86-64-v4 GenuineIntel, llvmpipe (LLVM
    15.0.6, 256 bits)". The vendor because Blender's FBX writer gives other bytes on an Intel machine than on the
    machine of the same level that recorded "x86-64-v4, llvmpipe (LLVM 15.0.6, 256 bits)" (every FBX of the
    one-asset library, 2026-12-04; every other output the same); entries recorded before carry no vendor."""
    import platform as host

    from numpy._core._multiarray_umath import __cpu_features__ as features

    levels = [level for level in ("X86_V4", "X86_V3", "X86_V2") if features.get(level)]
    cpu = f"x86-64-v{levels[0][-1]}" if levels else host.machine()
    return f"{cpu} {_cpu_vendor()}, {_gl_string('RENDERER')}"


def _cpu_vendor() -> str:
    """The CPU vendor string (/proc/cpuinfo's vendor_id, e.g. GenuineIntel, AuthenticAMD), else the processor's
    name as Python reports it, else "unknown"."""
    import platform as host

    try:
        with open("/proc/cpuinfo", encoding="ascii", errors="replace") as info:
            for line in info:
                if line.startswith("vendor_id"):
                    return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return host.processor() or "unknown"


def versions() -> dict[str, str]:
    """The versions of everything that decides the outputs' bytes besides the code itself."""
    import zlib
    from importlib.metadata import version

    out = {name: version(name) for name in ("numpy", "scipy", "opencv-contrib-python-headless", "pyarrow",
                                            "pillow", "trimesh", "usd-core")}
    out["zlib"] = zlib.ZLIB_RUNTIME_VERSION
    out["mesa"] = _gl_string("VERSION")
    out["bpy"] = _bpy_version()
    return out


GOLDENS = {"species": species_digests, "job": job_digests, "library": library_digests}


def golden_path(name: str) -> Path:
    return GOLDEN_DIR / f"{name}.json"


def compute(name: str, scratch: Path) -> dict[str, str]:
    make = GOLDENS[name]
    if name == "species":
        return make()
    folder = scratch / name
    return make(folder)


def load(name: str) -> dict[str, dict]:
    """The golden's entries by platform: {platform: {"versions": ..., "digests": ...}}."""
    return json.loads(golden_path(name).read_text())["platforms"]


def expected_digests(entries: dict[str, dict], here: str) -> tuple[dict, dict, list[str]]:
    """What to compare on platform `here`: (digests, versions they were made with, outputs left unchecked).
    Here's own entry if recorded; otherwise the digests every recorded platform agrees on, leaving out (and
    naming) the outputs whose bytes differ between platforms."""
    if here in entries:
        return entries[here]["digests"], entries[here]["versions"], []
    recorded = list(entries.values())
    first = recorded[0]["digests"]
    agreed = {k: v for k, v in first.items() if all(e["digests"].get(k) == v for e in recorded[1:])}
    return agreed, recorded[0]["versions"], sorted(set(first) - set(agreed))


def write(name: str, digests: dict[str, str], found_versions: dict[str, str], here: str) -> None:
    """Record `digests` as platform `here`'s entry, keeping the other platforms' entries."""
    path = golden_path(name)
    entries = load(name) if path.exists() else {}
    entries[here] = {"versions": found_versions, "digests": digests}
    path.write_text(json.dumps({"platforms": entries}, indent=1, sort_keys=True) + "\n")


def main(argv: list[str]) -> int:
    import tempfile

    names = argv or list(GOLDENS)
    unknown = [n for n in names if n not in GOLDENS]
    if unknown:
        print(f"make_golden: unknown golden {unknown[0]!r}: allowed {', '.join(GOLDENS)}", file=sys.stderr)
        return 2
    found_versions, here = versions(), platform()
    with tempfile.TemporaryDirectory() as scratch:
        for name in names:
            digests = compute(name, Path(scratch))
            write(name, digests, found_versions, here)
            print(f"{golden_path(name).relative_to(ROOT)}: {len(digests)} digests for {here}")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
