"""Modelling a tree by hand (seed 000 ch. 4-5): strokes, lobes from strokes, surface and stroke edits, the hull
contact guard, the brush and growth inside the drawn lobes. Positions are treefarm's frame: Z up, metres.
"""
