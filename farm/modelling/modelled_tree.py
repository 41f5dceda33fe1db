"""The tree a modelling session grows: its full parameter dictionary (the preset's typical member with the
session's overrides and seed), the skeleton grown in its lobes from its branches and painted markers, the mesh,
the GLB.

In: a ModelSession. Out: params dict, Skeleton, TreeMesh, GLB bytes (Y up); the same session gives the same bytes.
"""
from __future__ import annotations

import numpy as np

import species

from .grow import grow_model, model_params
from .session import GROW_LIMITS, MAX_PAINTED_MARKERS, ModelSession, SessionError

__all__ = ["growth_parameters", "grow_session", "session_mesh", "session_glb"]


def _overrides(session: ModelSession) -> dict:
    return {**session.parameters, "seed": session.seed}


def growth_parameters(session: ModelSession) -> dict:
    """The whole growth dictionary: the preset's typical member, the modelling defaults, the session's overrides,
    and its seed (which the dictionary's own generator, `species.rng_for`, grows from)."""
    return model_params(session.preset, _overrides(session))


def grow_session(session: ModelSession) -> tuple[dict, object]:
    """(params, Skeleton): growth inside the session's lobes from its branches, colonizing its painted markers.
    SessionError when the request is over the size limits."""
    params = growth_parameters(session)
    for key, high in GROW_LIMITS.items():
        if params.get(key, 0) > high:
            raise SessionError(f"grow refused: {key} = {params[key]} is over the modelling limit {high}")
    if len(session.markers) > MAX_PAINTED_MARKERS:
        raise SessionError(f"grow refused: {len(session.markers)} painted markers; allowed {MAX_PAINTED_MARKERS}")
    lobes = [lobe.mesh() for lobe in session.lobes]
    branches = [(np.array(b.points), b.parent) for b in session.branches]
    skeleton = grow_model(lobes, branches, np.array(session.markers), session.preset, _overrides(session),
                          species.rng_for(params), brush_paths=[np.array(b.path) for b in session.brushes])
    return params, skeleton


def session_mesh(session: ModelSession, name: str = "model"):
    """(params, Skeleton, TreeMesh) of the session's tree."""
    params, skeleton = grow_session(session)
    return params, skeleton, species.build_mesh(skeleton, {**params, "name": name})


def session_glb(session: ModelSession) -> bytes:
    return session_mesh(session)[2].to_glb()
