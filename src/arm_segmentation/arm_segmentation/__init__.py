"""Unseen-object instance segmentation of tabletop RGB-D frames."""
