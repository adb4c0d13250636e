"""Instance clustering of object pixels on the organized point cloud.

1. Over-segmentation: neighbouring object pixels are separated by a depth discontinuity, a concave
   crease between their surface normals (where touching or stacked objects meet) or a sharp change
   of chromaticity; connected components of the rest are fragments. Fragments then grow by colour
   into the pixels between them (a printed surface is mostly colour edges), never across a depth
   discontinuity or a concave crease: one box's print does not flood into the box behind it.
2. Merging: adjacent fragments whose shared boundary is depth-continuous and whose mean
   chromaticities agree are one object (parts of one object meet at creases too). Regions merge
   most similar first (mutual nearest neighbours per round, means and contacts recomputed after
   each round), so a chain of small colour steps does not join objects of different colour.
   Fragments too small to be an object join the neighbour they touch most. With the learned merge
   classifier (merge_model), it decides which touching regions merge instead of their colour.
3. Growing: instances extend into nearby pixels the depth sensor dropped or that lie in the table
   band (object bottoms, thin feet) when the pixel's colour matches the instance and not the table.
"""

from dataclasses import dataclass

import cv2
import numpy as np
from scipy import ndimage
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components

from arm_core.boxes import mask_box
from arm_core.settings import setting
from arm_core.vectors import channel_sum, vector_length
from arm_segmentation.label_stats import label_maximum, label_minimum

# Rings the last flood grows into geometric edge pixels: wider than the band separating_edges marks.
EDGE_FLOOD_ITERATIONS = 3


@dataclass(frozen=True)
class ClusterParams:
    """Parameters of the edge cues, fragment merging and instance growing (metres, pixels)."""

    step_px: int = 2
    depth_jump_m: float = 0.006
    depth_jump_per_m: float = 0.012
    concave_threshold: float = 0.35
    crease_reach: int = 3  # creases are also looked for between pixels this many steps apart (a sensor rounds them)
    use_colour: bool = setting(True, "Use colour cues (false: geometry only)")
    chroma_edge_threshold: float = 0.15
    merge_chroma_threshold: float = 0.16
    contact_radius_px: int = 2
    small_fragment_px: int = 100
    small_fragment_tolerance: float = 1.6
    min_contact_px: int = 3
    min_fragment_px: int = 3
    min_instance_area_m2: float = setting(3e-4, "Smallest visible object surface, m^2", 0.0, 0.1)
    flood_iterations: int = 20
    flood_chroma_threshold: float = 0.6
    flood_strict_chroma_threshold: float = 0.25  # first flood pass: fragments claim their own colour (0: off)
    grow_radius_px: int = 3
    grow_chroma_threshold: float = 0.12
    seed_textured_regions: bool = True  # surfaces between geometric edges without a fragment get one
    geometric_merge: bool = True  # fragments meeting on one smooth surface merge whatever their colour
    geometric_min_contact_px: int = 6
    geometric_contact_share: float = 0.5  # of all their contacts
    geometric_edge_px: int = 1  # pixels this near a depth jump or a concave crease are no smooth contact
    resting_height_m: float = 0.02  # a fragment reaching this near its support rests on it
    thick_fragment_m: float = 0.02  # radius of the widest disc inside a fragment that could be an object
    max_instances: int = 255
    agglomerative: bool = True  # region merging most similar first (False: one pass over all pairs)


def chromaticity(rgb: np.ndarray, blur: int = 3) -> np.ndarray:
    """Opponent chromaticity (rgb - mean(rgb)) / (|rgb| + 5) after a blur x blur box filter, HxWx3 float32.

    Invariant to diffuse shading; a specular highlight shortens it without turning it.
    """
    rgb_f = (cv2.blur(rgb, (blur, blur)) if blur > 1 else rgb).astype(np.float32)
    norm = np.sqrt(np.einsum("hwc,hwc->hw", rgb_f, rgb_f))[..., None] + 5.0
    return (rgb_f - channel_mean(rgb_f)[..., None]) / norm


def channel_mean(image: np.ndarray) -> np.ndarray:
    """HxW mean of an HxWx3 float image's channels (the same values as image.mean(axis=2), without
    numpy's slow reduction over a short last axis)."""
    return channel_sum(image) / image.dtype.type(3)


def hue_distance(a: np.ndarray, b: np.ndarray, saturation_weight: float = 0.3) -> np.ndarray:
    """Distance of opponent chromaticities (..., 3) that mostly ignores saturation changes.

    Both vectors are shortened to the smaller length before comparing, so a shadow or a clipped
    highlight of a surface (same hue, other saturation) stays close to it.
    """
    sa = vector_length(a)[..., None]
    sb = vector_length(b)[..., None]
    common = np.minimum(sa, sb)
    hue = channel_sum(np.abs(a * (common / np.maximum(sa, 1e-6)) - b * (common / np.maximum(sb, 1e-6))))
    return hue + saturation_weight * np.abs(sa - sb)[..., 0]


def depth_jump_limit(depth_m: np.ndarray, distance_px: float, params: ClusterParams) -> np.ndarray:
    """Largest depth change (m) between pixels distance_px apart on one continuous surface."""
    return params.depth_jump_m * max(distance_px, 1.0) / 2.0 + params.depth_jump_per_m * depth_m


def _shifted(axis_shift):
    dy, dx = axis_shift
    h_a = slice(0, -dy if dy > 0 else None)
    h_b = slice(dy, None)
    if dx >= 0:
        w_a, w_b = slice(0, -dx if dx > 0 else None), slice(dx, None)
    else:
        w_a, w_b = slice(-dx, None), slice(0, dx)
    return (h_a, w_a), (h_b, w_b)


def separating_edges(points_camera, normals_camera, depth_m, chroma, mask, normal_valid, params):
    """(edge, geometric) HxW bool: pixels of `mask` that lie on a boundary between two different
    surfaces, and those of them found by geometry alone.

    Depth jumps are tested where both pixels have depth, creases where both have normals, colour
    everywhere (pixels without depth still have colour).
    """
    s = params.step_px
    edge = np.zeros(mask.shape, dtype=bool)
    geometric = np.zeros(mask.shape, dtype=bool)
    for shift in ((0, s), (s, 0)):
        a, b = _shifted(shift)
        za, zb = depth_m[a], depth_m[b]
        cut = (np.abs(za - zb) > depth_jump_limit(np.minimum(za, zb), s, params)) & (za > 0) & (zb > 0)
        cut |= _concave(points_camera, normals_camera, normal_valid, a, b, params.concave_threshold)
        geometric[a] |= cut & mask[a] & mask[b]
        geometric[b] |= cut & mask[a] & mask[b]
        if params.crease_reach > 1:  # a crease the sensor rounded over several steps: both ends marked
            wide_a, wide_b = _shifted((shift[0] * params.crease_reach, shift[1] * params.crease_reach))
            wide = _concave(points_camera, normals_camera, normal_valid, wide_a, wide_b, params.concave_threshold)
            wide &= mask[wide_a] & mask[wide_b]
            for end in (wide_a, wide_b):
                geometric[end] |= wide
                edge[end] |= wide
        if chroma is not None:
            cut |= channel_sum(np.abs(chroma[a] - chroma[b])) > params.chroma_edge_threshold
        cut &= mask[a] & mask[b]
        edge[a] |= cut
        edge[b] |= cut
    return edge, geometric


def _concave(points_camera, normals_camera, normal_valid, a, b, threshold: float) -> np.ndarray:
    """Bool over the pixel pairs (a, b) (slices from _shifted): a concave crease between them, the
    normals turning towards each other by more than threshold along the step."""
    d = points_camera[a] - points_camera[b]
    dn = normals_camera[a] - normals_camera[b]
    convexity = np.einsum("hwc,hwc->hw", dn, d) / np.maximum(vector_length(d), 1e-6)
    return (convexity < -threshold) & normal_valid[a] & normal_valid[b]


def _region_means(labels: np.ndarray, n: int, values: np.ndarray) -> np.ndarray:
    flat = labels.ravel()
    count = np.maximum(np.bincount(flat, minlength=n + 1), 1)
    return np.stack(
        [np.bincount(flat, weights=values[..., k].ravel(), minlength=n + 1) / count for k in range(values.shape[-1])],
        axis=1,
    )


def fragment_contacts(labels: np.ndarray, depth_m: np.ndarray, params: ClusterParams, smooth=None, outline=None):
    """Pixel contacts between different fragments within contact_radius_px of each other.

    Returns (pairs (P, 2) int64 with a < b, counts (P, 5) float64): contacts at a continuous depth,
    across a depth discontinuity, where a pixel has no depth, (a subset of the first) continuous
    contacts between two pixels of the HxW bool `smooth` (zero when it is None), and the summed
    outline probability of the contacts (the larger of the two pixels' in the HxW float `outline`
    from the boundary network; zero when it is None).
    """
    box = mask_box(labels > 0)  # both pixels of a contact are labelled: it lies inside
    if box is not None:
        labels, depth_m = labels[box], depth_m[box]
        smooth = None if smooth is None else smooth[box]
        outline = None if outline is None else outline[box]
    keys, kinds, smooth_kinds, outline_sums = [], [], [], []
    r = params.contact_radius_px
    shifts = [(0, k) for k in range(1, r + 1)] + [(k, 0) for k in range(1, r + 1)]
    shifts += [(k, k) for k in range(1, r)] + [(k, -k) for k in range(1, r)]
    big = np.int64(labels.max()) + 1
    for shift in shifts:
        a, b = _shifted(shift)
        la, lb = labels[a], labels[b]
        touching = (la != lb) & (la > 0) & (lb > 0)
        za, zb = depth_m[a][touching], depth_m[b][touching]
        unknown = (za <= 0) | (zb <= 0)
        continuous = ~unknown & (np.abs(za - zb) <= depth_jump_limit(np.minimum(za, zb), np.hypot(*shift) + 1, params))
        kinds.append(np.where(unknown, 2, np.where(continuous, 0, 1)))
        if smooth is not None:
            smooth_kinds.append(continuous & smooth[a][touching] & smooth[b][touching])
        if outline is not None:
            outline_sums.append(np.maximum(outline[a][touching], outline[b][touching]))
        lo = np.minimum(la[touching], lb[touching]).astype(np.int64)
        hi = np.maximum(la[touching], lb[touching]).astype(np.int64)
        keys.append(lo * big + hi)
    keys = np.concatenate(keys)
    kinds = np.concatenate(kinds)
    unique, inverse = np.unique(keys, return_inverse=True)
    counts = np.zeros((len(unique), 5), dtype=np.float64)
    for kind in range(3):
        counts[:, kind] = np.bincount(inverse[kinds == kind], minlength=len(unique))
    if smooth is not None:
        counts[:, 3] = np.bincount(inverse[np.concatenate(smooth_kinds)], minlength=len(unique))
    if outline is not None:
        counts[:, 4] = np.bincount(inverse, weights=np.concatenate(outline_sums), minlength=len(unique))
    return np.stack([unique // big, unique % big], axis=1), counts


def flood(labels: np.ndarray, mask: np.ndarray, chroma: np.ndarray, iterations: int, max_chroma: float) -> np.ndarray:
    """Grow labels into the unlabelled pixels of mask, one 8-connected ring per iteration.

    A pixel joins a neighbouring label only if its chromaticity is within max_chroma (L1) of
    that label's mean, so a region without a seed of its own is not swallowed by a neighbour.
    """
    n = int(labels.max())
    full = labels.astype(np.uint16 if n < 65535 else np.float32)
    means = _region_means(labels, n, chroma)
    todo = mask & (full == 0)
    box = mask_box(todo, 1)  # every neighbour of a pixel to fill lies in it
    if box is None:
        return full.astype(np.int64)
    out, todo, chroma = full[box], todo[box], chroma[box]  # out: a view, written through
    kernel = np.ones((3, 3), np.uint8)
    for _ in range(iterations):
        grown = cv2.dilate(out, kernel)
        gy, gx = np.nonzero(todo & (grown > 0))
        if len(gy) == 0:
            break
        owner = grown[gy, gx].astype(np.int64)
        ok = channel_sum(np.abs(chroma[gy, gx] - means[owner])) <= max_chroma
        if not np.any(ok):
            break
        out[gy[ok], gx[ok]] = owner[ok]
        todo[gy[ok], gx[ok]] = False
    return full.astype(np.int64)


def _union(n: int, pairs: np.ndarray) -> np.ndarray:
    """Component ids for labels 0..n given undirected pairs: 0 stays 0, the rest become 1..K."""
    graph = coo_matrix((np.ones(len(pairs)), (pairs[:, 0], pairs[:, 1])), shape=(n + 1, n + 1))
    component = connected_components(graph, directed=False)[1] + 1
    component[0] = 0
    return component


def _should_merge(counts: np.ndarray, params: ClusterParams) -> np.ndarray:
    continuous, broken, unknown = counts[:, 0], counts[:, 1], counts[:, 2]
    across_gap = (unknown >= params.min_contact_px) & (broken <= continuous)
    return ((continuous >= params.min_contact_px) & (continuous >= broken)) | across_gap


def _agglomerate(
    labels, n, pairs, counts, chroma, params: ClusterParams, max_rounds: int = 64, scorer=None
) -> np.ndarray:
    """Region merging: each round joins the mutually most similar mergeable neighbours, then the
    merged regions' mean colours and contact counts are recomputed, so a chain of small colour
    steps does not join two objects of different colour. scorer (merge_model.LearnedMerge, started on labels): touching
    regions merge when its probability exceeds its threshold, most probable first, instead of by
    colour. Returns the region of each label 0..n."""
    flat = labels.ravel()
    frag_size = np.bincount(flat, minlength=n + 1).astype(np.float64)
    frag_sums = np.stack([np.bincount(flat, weights=chroma[..., k].ravel(), minlength=n + 1) for k in range(3)], 1)
    owner = np.arange(n + 1)
    big = np.int64(n + 1)
    for _ in range(max_rounds):
        a, b = owner[pairs[:, 0]], owner[pairs[:, 1]]
        keep = a != b
        if not np.any(keep):
            break
        keys, inverse = np.unique(np.minimum(a, b)[keep] * big + np.maximum(a, b)[keep], return_inverse=True)
        region_pairs = np.stack([keys // big, keys % big], axis=1)
        region_counts = np.stack(
            [np.bincount(inverse, weights=counts[keep, k], minlength=len(keys)) for k in range(5)], 1
        )
        size = np.bincount(owner, weights=frag_size, minlength=n + 1)
        means = np.stack([np.bincount(owner, weights=frag_sums[:, k], minlength=n + 1) for k in range(3)], 1)
        means /= np.maximum(size, 1.0)[:, None]
        ra, rb = region_pairs[:, 0], region_pairs[:, 1]
        if scorer is not None:
            probability = scorer.probability(owner, region_pairs, region_counts)
            ok = (region_counts[:, :3].sum(axis=1) >= params.min_contact_px) & (probability > scorer.threshold)
            distance = 1.0 - probability
        else:
            distance = np.abs(means[ra] - means[rb]).sum(axis=1)
            small = np.minimum(size[ra], size[rb]) < params.small_fragment_px
            limit = params.merge_chroma_threshold * np.where(small, params.small_fragment_tolerance, 1.0)
            ok = _should_merge(region_counts, params) & (distance <= limit)
        if not np.any(ok):
            break
        if scorer is not None:
            mutual = _mutual_best(ra, rb, distance, ok)
        else:
            best = np.full(n + 1, np.inf)
            np.minimum.at(best, ra[ok], distance[ok])
            np.minimum.at(best, rb[ok], distance[ok])
            mutual = ok & (distance <= best[ra]) & (distance <= best[rb])
        component = _union(n, region_pairs[mutual])
        representative = np.full(component.max() + 1, n + 1)
        np.minimum.at(representative, component, np.arange(n + 1))
        owner = representative[component[owner]]
    return owner


def _mutual_best(ra: np.ndarray, rb: np.ndarray, distance: np.ndarray, ok: np.ndarray) -> np.ndarray:
    """(P,) bool: ok pairs that are each other's single nearest (ties broken by pair order), so one
    round never chains regions through a shared neighbour."""
    candidates = np.nonzero(ok)[0]
    candidates = candidates[np.argsort(distance[candidates], kind="stable")]
    ends = np.concatenate([ra[candidates], rb[candidates]])
    pair_of_end = np.concatenate([candidates, candidates])
    order = np.argsort(np.concatenate([np.arange(len(candidates))] * 2), kind="stable")
    regions, first = np.unique(ends[order], return_index=True)
    best_pair = np.full(int(max(ra.max(), rb.max())) + 1, -1)
    best_pair[regions] = pair_of_end[order][first]
    index = np.arange(len(ra))
    return ok & (best_pair[ra] == index) & (best_pair[rb] == index)


def widest_disc_m(labels: np.ndarray, n: int, area_m2: np.ndarray) -> np.ndarray:
    """(n + 1,) radius (m) of the widest disc inside each label 0..n (pixel side sqrt(area_m2))."""
    inner = np.ones(labels.shape, dtype=np.uint8)
    inner[:-1] &= labels[:-1] == labels[1:]
    inner[1:] &= labels[1:] == labels[:-1]
    inner[:, :-1] &= labels[:, :-1] == labels[:, 1:]
    inner[:, 1:] &= labels[:, 1:] == labels[:, :-1]
    radius_m = cv2.distanceTransform(inner, cv2.DIST_L2, 3) * np.sqrt(area_m2)
    return label_maximum(radius_m, labels, n)


def merge_geometric(labels, n, depth_m, smooth, height_m, area_m2, params: ClusterParams) -> np.ndarray:
    """Join fragments that meet mostly on one smooth surface (continuous depth, no concave crease,
    both sides above their support) when one of them cannot be an object on its own: it does not
    reach down to the support (a label, the upper part of a print) or it is thin (a stripe, a
    band). Two thick fragments that both rest on the support (boxes standing flush) stay apart,
    whatever the geometry; colour separates them."""
    pairs, counts = fragment_contacts(labels, depth_m, params, smooth)
    if not len(pairs):
        return labels
    total = counts[:, :3].sum(axis=1)
    join = (counts[:, 3] >= params.geometric_min_contact_px) & (counts[:, 3] >= params.geometric_contact_share * total)
    low = label_minimum(np.where(smooth, height_m, np.inf), labels, n)
    floating = np.asarray(low) > params.resting_height_m
    thin = widest_disc_m(labels, n, area_m2) < params.thick_fragment_m
    alone = floating | thin
    join &= alone[pairs[:, 0]] | alone[pairs[:, 1]]
    return _compact(_join_to_one_anchor(n, pairs[join], counts[join, 3], alone)[labels], 0)


def _join_to_one_anchor(n: int, pairs: np.ndarray, contact: np.ndarray, alone: np.ndarray) -> np.ndarray:
    """Region of each label 0..n: fragments that cannot be objects on their own (`alone`) that meet
    join each other, and each such group joins the one other fragment it meets most (`contact` per
    pair): a strip along the seam of two flush boxes joins one of them and never chains them."""
    both = alone[pairs[:, 0]] & alone[pairs[:, 1]]
    group = _union(n, pairs[both])  # alone fragments grouped; every other fragment its own region
    mixed = pairs[~both]
    if len(mixed):
        weight = contact[~both]
        lonely = np.where(alone[mixed[:, 0]], mixed[:, 0], mixed[:, 1])
        anchor = np.where(alone[mixed[:, 0]], mixed[:, 1], mixed[:, 0])
        big = np.int64(n + 1)
        keys, inverse = np.unique(group[lonely].astype(np.int64) * big + group[anchor], return_inverse=True)
        totals = np.bincount(inverse, weights=weight)
        owner, target = keys // big, keys % big
        order = np.lexsort((-totals, owner))  # per group, the anchor it meets most first
        first = np.ones(len(order), bool)
        first[1:] = owner[order][1:] != owner[order][:-1]
        moved = np.arange(group.max() + 1)
        moved[owner[order][first]] = target[order][first]
        group = moved[group]
    return group


def merge_fragments(
    labels, n, depth_m, chroma, area_m2, params: ClusterParams, smooth=None, height_m=None, pixel_area_m2=None,
    scorer=None,
) -> np.ndarray:  # fmt: skip
    """Merge fragments into objects (see the module docstring). Returns labels (0 = none).

    smooth: HxW bool, pixels away from geometric edges, and height_m: HxW height above the support
    (m), and pixel_area_m2 (HxW surface area of every pixel), fragments meeting on a smooth surface
    merge first (merge_geometric). scorer: a merge_model.LearnedMerge
    that decides, after the smooth-surface rule, which touching regions merge instead of their colour
    (its contacts carry its own outline probability and the smooth contacts)."""
    if n == 0:
        return labels
    if smooth is not None and height_m is not None and pixel_area_m2 is not None and params.geometric_merge:
        labels = merge_geometric(labels, n, depth_m, smooth, height_m, pixel_area_m2, params)
        n = int(labels.max())
    if scorer is not None:
        pairs, counts = fragment_contacts(labels, depth_m, params, smooth, scorer.outline)
        scorer.start(labels, n)
    else:
        pairs, counts = fragment_contacts(labels, depth_m, params)
    if len(pairs) and params.use_colour:
        if params.agglomerative or scorer is not None:
            component = _agglomerate(labels, n, pairs, counts, chroma, params, scorer=scorer)
        else:
            means = _region_means(labels, n, chroma)
            colour_distance = np.abs(means[pairs[:, 0]] - means[pairs[:, 1]]).sum(axis=1)
            sizes = np.bincount(labels.ravel(), minlength=n + 1)
            small = np.minimum(sizes[pairs[:, 0]], sizes[pairs[:, 1]]) < params.small_fragment_px
            limit = params.merge_chroma_threshold * np.where(small, params.small_fragment_tolerance, 1.0)
            merge = _should_merge(counts, params) & (colour_distance <= limit)
            component = _union(n, pairs[merge])
        labels = _compact(component[labels], 0)
        pairs, counts = fragment_contacts(labels, depth_m, params)
    n = int(labels.max())
    area = np.bincount(labels.ravel(), weights=area_m2.ravel(), minlength=n + 1)
    small = area < params.min_instance_area_m2
    small[0] = False
    if len(pairs) and np.any(small):
        target = np.arange(n + 1)
        contact = counts[:, 0] + counts[:, 2]
        both = np.concatenate([pairs, pairs[:, ::-1]])
        weight = np.concatenate([contact, contact])
        candidate = small[both[:, 0]] & ~small[both[:, 1]] & (weight >= params.min_contact_px)
        both, weight = both[candidate], weight[candidate]
        order = np.lexsort((-weight, both[:, 0]))
        both = both[order]
        first = np.ones(len(both), dtype=bool)
        first[1:] = both[1:, 0] != both[:-1, 0]
        target[both[first, 0]] = both[first, 1]
        labels = target[labels]
        area = np.bincount(labels.ravel(), weights=area_m2.ravel(), minlength=n + 1)
        small = area < params.min_instance_area_m2
        small[0] = False
    labels = np.where(small[labels], 0, labels)
    return _compact(labels, 0)


def grow_instances(labels, depth_m, chroma, candidates, table_chroma, params: ClusterParams) -> np.ndarray:
    """Extend instances into `candidates` pixels near them whose colour matches the instance."""
    n = int(labels.max())
    if n == 0 or not np.any(candidates):
        return labels
    distance, (iy, ix) = ndimage.distance_transform_edt(labels == 0, return_indices=True)
    near = candidates & (labels == 0) & (distance <= params.grow_radius_px)
    if not np.any(near):
        return labels
    means = _region_means(labels, n, chroma)
    ys, xs = np.nonzero(near)
    owner = labels[iy[ys, xs], ix[ys, xs]]
    pixel_chroma = chroma[ys, xs]
    to_instance = channel_sum(np.abs(pixel_chroma - means[owner]))
    ok = to_instance <= params.grow_chroma_threshold
    if table_chroma is not None:
        ok &= to_instance < hue_distance(pixel_chroma, table_chroma[ys, xs])
    z = depth_m[ys, xs]
    z_owner = depth_m[iy[ys, xs], ix[ys, xs]]
    ok &= (z <= 0) | (z_owner <= 0) | (np.abs(z - z_owner) <= depth_jump_limit(z_owner, params.grow_radius_px, params))
    out = labels.copy()
    out[ys[ok], xs[ok]] = owner[ok]
    return out


def seed_textured_regions(fragments: np.ndarray, smooth: np.ndarray, min_px: int) -> np.ndarray:
    """Fragments plus one new fragment per region of `smooth` (pixels between geometric edges) that
    holds none: a printed or striped surface is all colour edges and would otherwise be flooded
    from a neighbouring object."""
    regions, n = ndimage.label(smooth)
    if n == 0:
        return fragments
    seeded = np.bincount(regions[fragments > 0], minlength=n + 1) > 0
    size = np.bincount(regions.ravel(), minlength=n + 1)
    new = ~seeded & (size >= min_px)
    new[0] = False
    if not np.any(new):
        return fragments
    ids = np.zeros(n + 1, dtype=np.int64)
    ids[new] = int(fragments.max()) + np.arange(1, int(new.sum()) + 1)
    return np.where((fragments == 0) & new[regions], ids[regions], fragments)


def cluster_instances(
    points_camera: np.ndarray,
    normals_camera: np.ndarray,
    depth_m: np.ndarray,
    chroma: np.ndarray,
    object_mask: np.ndarray,
    candidate_mask: np.ndarray,
    normal_valid: np.ndarray,
    area_m2: np.ndarray,
    table_chroma: np.ndarray | None = None,
    params: ClusterParams = ClusterParams(),
    height_m: np.ndarray | None = None,
    scorer=None,
) -> np.ndarray:
    """Instance labels (uint16 HxW, 0 = not an object).

    height_m: HxW height of each pixel above its support level (m), for merge_geometric.
    scorer: merge_model.LearnedMerge on this grid: the learned merging of touching regions.
    object_mask: pixels with geometric evidence of an object (above a support plane).
    candidate_mask: further pixels that may belong to objects (no depth, or in the table band)
    but only count for an instance that has enough area of its own in object_mask.
    """
    mask = object_mask | candidate_mask
    edge, geometric = separating_edges(
        points_camera, normals_camera, depth_m, chroma if params.use_colour else None, mask, normal_valid, params
    )
    fragments, n = ndimage.label(mask & ~edge)
    if n == 0:
        return np.zeros(mask.shape, dtype=np.uint16)
    sizes = np.bincount(fragments.ravel(), minlength=n + 1)
    keep = sizes >= params.min_fragment_px
    keep[0] = False
    fragments = _compact(np.where(keep[fragments], fragments, 0), 0)
    if params.seed_textured_regions:
        fragments = seed_textured_regions(fragments, mask & ~geometric, params.small_fragment_px)
    # floods grow fragments by colour but never across a geometric edge (a depth jump or a concave
    # crease between two surfaces); the edge pixels then join a side
    inside = mask & ~geometric
    if params.flood_strict_chroma_threshold > 0:
        fragments = flood(fragments, inside, chroma, params.flood_iterations, params.flood_strict_chroma_threshold)
    # With the classifier, a second strict pass (from the grown regions' colours) instead of the loose
    # one: the classifier merges what a loose flood would have claimed, and tells objects apart.
    loose = params.flood_chroma_threshold if scorer is None else params.flood_strict_chroma_threshold
    fragments = flood(fragments, inside, chroma, params.flood_iterations, loose)
    leftover, n_left = ndimage.label(inside & (fragments == 0))
    if n_left:
        sizes = np.bincount(leftover.ravel(), minlength=n_left + 1)
        keep = sizes >= params.min_fragment_px
        keep[0] = False
        offset = int(fragments.max())
        fragments = np.where(keep[leftover], leftover + offset, fragments)
        fragments = _compact(fragments, 0)
    fragments = flood(fragments, mask & geometric, chroma, EDGE_FLOOD_ITERATIONS, np.inf)
    evidence = np.where(object_mask, area_m2, 0.0)
    r = params.geometric_edge_px
    near_edge = cv2.dilate(geometric.astype(np.uint8), np.ones((2 * r + 1, 2 * r + 1), np.uint8)) > 0
    smooth = object_mask & ~near_edge
    n = int(fragments.max())
    labels = merge_fragments(fragments, n, depth_m, chroma, evidence, params, smooth, height_m, area_m2, scorer)
    grow_table = table_chroma if params.use_colour else None
    labels = grow_instances(labels, depth_m, chroma, mask, grow_table, params)
    return _relabel_by_size(labels, params.max_instances)


def _compact(labels: np.ndarray, background: int) -> np.ndarray:
    """Renumber labels to 1..K (background -> 0) keeping their order."""
    used = np.flatnonzero(np.bincount(labels.ravel()))  # labels are non-negative ids
    used = used[used != background]
    remap = np.zeros(int(labels.max()) + 1 if labels.size else 1, dtype=np.int64)
    remap[used] = np.arange(1, len(used) + 1)
    return remap[labels]


def _relabel_by_size(labels: np.ndarray, max_instances: int) -> np.ndarray:
    """Consecutive ids 1..K, largest instance first; at most max_instances are kept."""
    counts = np.bincount(labels.ravel())
    counts[0] = 0
    order = np.argsort(-counts, kind="stable")
    order = order[counts[order] > 0][:max_instances]
    remap = np.zeros(len(counts), dtype=np.uint16)
    remap[order] = np.arange(1, len(order) + 1, dtype=np.uint16)
    return remap[labels]
