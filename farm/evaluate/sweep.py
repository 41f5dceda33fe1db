"""TreeSketchNet's rotation test: one unseen tree, the camera turned about it in equal steps, the params method's
unit-cube Hausdorff per angle (digest 4.5: 72 views 5 degrees apart; the paper reports ~0.03 over the sweep).

The tree is the first held-out Weber-Penn tree of the first dataset that serves the params method (or the first
held-out tree when none is Weber-Penn); the views are rig `orbit:N:10` (N = 360 / step) rendered in `sketch_tsn`,
the style the network reads, each fitted to its drawing as the params rows are (`EvalSettings.fit_evals`).
Written to REPORT_DIR/sweep.parquet (azimuth, metric), kept on a rerun.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

from species.errors import TreefarmError

from .units import load_tree, worker_context, write_atomically

# reconstruct is imported where used (in the Ray task): the package imports torch.

__all__ = ["run_sweep", "SWEEP_FILE", "sweep_tree"]

SWEEP_FILE = "sweep.parquet"


def sweep_tree(plan):
    """The unit whose tree the sweep turns about, or None when no dataset serves the params method."""
    units = [u for u in plan.units if u.method == "params" and u.source == "held-out"]
    return units[0] if units else None


def _sweep_task(unit, models, settings, step: float) -> dict:
    import reconstruct
    from reconstruct import metrics

    ctx = worker_context(models, settings)
    tree = load_tree(unit)
    n = max(1, int(round(360.0 / step)))
    views = ctx.renderer.render(tree.mesh, tree.skeleton, f"orbit:{n}:10", ["sketch_tsn"], np.random.default_rng(0))
    net = ctx.net("sketchnet")
    rows = {"azimuth_deg": [], "unit_cube_hausdorff": []}
    for k, view in enumerate(views):
        rows["azimuth_deg"].append(k * 360.0 / n)
        try:
            result = reconstruct.from_params(view.images["sketch_tsn"], net=net, height=tree.skeleton.height,
                                             fit_evals=settings.fit_evals, renderer=ctx.renderer)
            rows["unit_cube_hausdorff"].append(metrics.unit_cube_hausdorff(result.skeleton, tree.skeleton))
        except TreefarmError:  # a view the method cannot read: a gap in the curve, not a failed job
            rows["unit_cube_hausdorff"].append(float("nan"))
    return {"tree_id": unit.tree_id, "species": tree.species, "dataset": unit.dataset, "model": net.source, **rows}


def run_sweep(plan, report: Path, models, settings, step: float):
    """The sweep's table (a pandas DataFrame), computed as one Ray task unless the report holds it; None when no
    dataset serves the params method."""
    import pandas as pd
    import ray

    path = report / SWEEP_FILE
    if path.exists():
        return pd.read_parquet(path)
    unit = sweep_tree(plan)
    if unit is None:
        return None
    out = ray.get(ray.remote(num_cpus=1)(_sweep_task).remote(unit, models, settings, step))
    frame = pd.DataFrame({"azimuth_deg": out["azimuth_deg"], "unit_cube_hausdorff": out["unit_cube_hausdorff"]})
    for key in ("tree_id", "species", "dataset", "model"):
        frame[key] = out[key]
    write_atomically(path, frame.to_parquet(index=False))
    return frame
