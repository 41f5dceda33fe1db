"""A finished dataset's tables as Ray Data: the reader that needs Ray, kept on the farm's top floor because the
dataset format (`farm.dataset`) does not know Ray."""
from __future__ import annotations

from farm.dataset import part_files

__all__ = ["to_ray"]


def to_ray(path: str, table: str = "views"):
    """One table as a `ray.data.Dataset` (rows in part order); call after `ray.init()` or let Ray start one."""
    import ray.data  # here: Ray is heavy, and `import farm.ray_data` must stay cheap for the command line

    location, files = part_files(path, table)
    return ray.data.read_parquet(files, filesystem=location.filesystem)
