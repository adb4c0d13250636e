"""Fragments: instances too small to be an object on their own.

On real depth a box's top face, a printed patch or a rim often comes out as a separate instance a
few square centimetres large, and which ones do changes from frame to frame with the sensor's noise.
An instance whose visible area is under min_instance_area_m2 and whose outline runs at least
min_contact_share along larger instances at its depth is part of one and joins the one it touches
most (a strip left between two objects where one occludes the other joins the one behind): a small
object beside another touches it along one side, under a third of its outline (no small true object
on bench_seg's simulated frames reached 0.3; the strips on the OSD frames ran 0.3-0.6). A speck
under min_speck_area_m2 (too small to reconstruct or grasp: a corner of a face cut off by an edge)
joins the larger instance it touches most at its depth, and is dropped when it touches none.
Instances seen mostly without depth have no measured size and are left alone.
"""

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class FragmentParams:
    min_instance_area_m2: float = 0.0015  # 15 cm^2, a 4 x 4 cm patch seen face-on
    min_contact_share: float = 0.3  # of the fragment's outline pixel pairs, along larger instances
    min_speck_area_m2: float = 0.0002  # 2 cm^2
    contact_depth_m: float = 0.015  # neighbouring pixels of two instances this close in depth touch
    contact_reach_px: int = 2  # pixels up to this far apart along a row or a column are neighbours


def visible_areas_m2(labels: np.ndarray, depth_m: np.ndarray, K: np.ndarray) -> np.ndarray:
    """(max label + 1,) area (m^2) each instance covers facing the camera, from its pixels with depth."""
    weight = np.where(depth_m > 0, depth_m.astype(np.float64) ** 2, 0.0) / (K[0, 0] * K[1, 1])
    return np.bincount(labels.ravel(), weights=weight.ravel(), minlength=int(labels.max()) + 1)


def _neighbour_pairs(image: np.ndarray, reach_px: int):
    """(first, second) views of every pair of pixels 1..reach_px apart along a row or a column."""
    for shift in range(1, reach_px + 1):
        yield image[:, :-shift], image[:, shift:]
        yield image[:-shift, :], image[shift:, :]


def contact_counts(labels: np.ndarray, depth_m: np.ndarray, params: FragmentParams) -> tuple[np.ndarray, np.ndarray]:
    """(touching, outline): (n+1, n+1) symmetric counts of neighbouring pixel pairs of two different
    instances whose depths differ by less than contact_depth_m, and (n+1,) counts of the neighbouring
    pixel pairs across each instance's outline (to anything: table, background, another instance);
    n = max label."""
    n = int(labels.max()) + 1
    codes, sides = [np.zeros(0, dtype=np.int64)], [np.zeros(0, dtype=np.int64)]
    label_pairs = _neighbour_pairs(labels, params.contact_reach_px)
    depth_pairs = _neighbour_pairs(depth_m, params.contact_reach_px)
    for (a, b), (da, db) in zip(label_pairs, depth_pairs, strict=True):
        across = a != b
        sides += [a[across].astype(np.int64), b[across].astype(np.int64)]
        touching = across & (a > 0) & (b > 0) & (da > 0) & (db > 0) & (np.abs(da - db) < params.contact_depth_m)
        codes.append(a[touching].astype(np.int64) * n + b[touching])
    counts = np.bincount(np.concatenate(codes), minlength=n * n).reshape(n, n)
    return counts + counts.T, np.bincount(np.concatenate(sides), minlength=n)


def touching_pixels(labels: np.ndarray, depth_m: np.ndarray, i: int, j: int, params: FragmentParams) -> np.ndarray:
    """Flat indices of instance i's pixels that touch instance j at its depth (as in contact_counts)."""
    index = np.arange(labels.size).reshape(labels.shape)
    hits = [np.zeros(0, dtype=np.int64)]
    pairs = zip(
        _neighbour_pairs(labels, params.contact_reach_px),
        _neighbour_pairs(depth_m, params.contact_reach_px),
        _neighbour_pairs(index, params.contact_reach_px),
        strict=True,
    )
    for (a, b), (da, db), (ia, ib) in pairs:
        near = (da > 0) & (db > 0) & (np.abs(da - db) < params.contact_depth_m)
        hits += [ia[(a == i) & (b == j) & near], ib[(b == i) & (a == j) & near]]
    return np.unique(np.concatenate(hits))


def absorb_fragments(labels: np.ndarray, depth_m: np.ndarray, K: np.ndarray, params: FragmentParams) -> np.ndarray:
    """Labels with each fragment given to the larger instance it touches most at its depth (a chain
    of fragments ends in the object), or dropped (see the module docstring); renumbered 1..N in the
    order of the original ids."""
    n = int(labels.max())
    if n == 0:
        return labels
    areas = visible_areas_m2(labels, depth_m, K)
    pixels = np.bincount(labels.ravel(), minlength=n + 1)
    with_depth = np.bincount(labels.ravel(), weights=(depth_m > 0).ravel(), minlength=n + 1)
    # an instance seen mostly without depth (dark, shiny, nearer than the sensor's range) has no
    # measured size: it is left as it is
    measured = (pixels > 0) & (with_depth >= 0.5 * pixels)
    fragment = measured & (areas < params.min_instance_area_m2)
    fragment[0] = False
    if not fragment.any():
        return labels
    touching, outline = contact_counts(labels, depth_m, params)
    touching[:, 0] = 0
    owner = np.arange(n + 1)
    for i in np.flatnonzero(fragment):
        share = np.where(areas > areas[i], touching[i], 0) / max(outline[i], 1)
        speck = areas[i] < params.min_speck_area_m2
        if share.sum() >= params.min_contact_share or (speck and share.max() > 0):
            owner[i] = int(np.argmax(share))
        elif speck:
            owner[i] = 0
    return join_into_owners(labels, owner)


def join_into_owners(labels: np.ndarray, owner: np.ndarray) -> np.ndarray:
    """Labels with each instance i given to owner[i] (0: dropped; chains such as fragment -> larger
    fragment -> object followed to their end; every owner larger than what it takes, so there are no
    cycles), renumbered 1..N in the order of the original ids."""
    n = len(owner) - 1
    for _ in range(n):
        following = owner[owner]
        if np.array_equal(following, owner):
            break
        owner = following
    merged = owner[labels]
    used = np.unique(merged[merged > 0])
    remap = np.zeros(n + 1, dtype=labels.dtype)
    remap[used] = np.arange(1, len(used) + 1)
    return remap[merged]
