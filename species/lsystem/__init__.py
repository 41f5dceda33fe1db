"""L-systems: parametric, stochastic rewriting, the 3D turtle, L-strings to and from skeletons, grafting,
phyllotaxis twigs, and the presets.
"""
from __future__ import annotations

from .generator import Field, grow, SCHEMA, validate
from .rewrite import (format_modules, GrammarError, LSystem, Module, parse_modules, parse_rule, rewrite, Rule,
    TURTLE_SYMBOLS)
from .turtle import initial_frame, interpret, leaf_cards, turn_matrices, TurtlePath
from .lstring_io import branch_orders, edge_angles, lstring_to_tree, LStringError, tree_to_lstring
from .graft import extract_subtree, graft, pipe_smooth_radius, side_anchor, smooth_radius, subtree_mask
from .phyllotaxis import add_twigs, PATTERNS, twig_template

__all__ = [
    "grow", "validate", "SCHEMA", "Field", "GrammarError", "Rule", "LSystem", "TURTLE_SYMBOLS", "parse_modules",
    "parse_rule", "format_modules", "rewrite", "Module", "TurtlePath", "interpret", "initial_frame", "turn_matrices",
    "leaf_cards", "LStringError", "tree_to_lstring", "lstring_to_tree", "edge_angles", "branch_orders",
    "side_anchor", "graft", "smooth_radius", "pipe_smooth_radius", "subtree_mask", "extract_subtree", "PATTERNS",
    "add_twigs", "twig_template",
]
