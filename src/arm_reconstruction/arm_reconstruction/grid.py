"""Four-channel voxel grids (paper Section 3.1) and ground-truth voxelization.

For object o the grid F_o has four channels: F1 the voxels of o's own points, F2 the voxels of all
other segmented objects' points, F3 voxels observed to be empty (the camera ray through the voxel
ends behind it), F4 voxels that are unobserved (occluded, outside the image or without a depth return).
Voxels holding points are in F1 or F2 and in neither F3 nor F4.

The grid is axis-aligned with the gravity-aligned world frame, centred horizontally at o's observed
centre of mass, has side k * delta_o (delta_o: largest distance between o's points), or TOP_MARGIN x
the height of o's seen top above the table when that is more, and its bottom face lies on the table
plane under o, so that the table is the z = 0 plane in voxel coordinates.
Voxel (i, j, l) covers [origin + (i, j, l) * voxel_size_m, origin + (i + 1, j + 1, l + 1) * voxel_size_m).
"""

from dataclasses import dataclass

import numpy as np
import scipy.sparse
import scipy.sparse.csgraph
from scipy import ndimage
from scipy.spatial import ConvexHull, QhullError

from arm_core.camera import backproject_image, backproject_pixels, organized_normals, pixel_coordinates
from arm_core.frames import FrameInputError, validate_frame

from .object_depth import object_depth_average

CHANNELS = ("own", "others", "observed_empty", "unobserved")
DEFAULT_RESOLUTION = 32
DEFAULT_K = 2.0  # grids of new training data and checkpoints; see CHECKPOINT_DEFAULT_K
CHECKPOINT_DEFAULT_K = 4.0  # the grid of checkpoints that do not record theirs (trained before grid_k was saved)
MIN_OBJECT_POINTS = 10
MIN_DIAMETER_M = 0.01
SUPPORT_BIN_M = 0.005
SUPPORT_TOLERANCE_M = 0.01
SUPPORT_REACH = 2.0  # a support lies at most this many seen diameters below the seen bottom
TOP_MARGIN = 1.15  # the grid is at least this many times the seen top's height above the support
MAX_HULL_POINTS = 8192
EDGE_INTERIOR_PX = 2
EDGE_WINDOW_PX = 7
EDGE_TOLERANCE_M = 0.01
EDGE_TOLERANCE_PER_M = 0.02
JUMP_M = 0.03  # neighbouring pixels of one surface differ in depth by less than this
JUMP_PER_M = 0.03  # plus this share of their depth
BEHIND_SHARE = 0.2  # a piece cut off by depth jumps, behind the rest, below this share of the mask
BEHIND_WINDOW_PX = 15  # such a piece lies behind the pixels of the rest this near it
NORMAL_WINDOW_PX = 5


class GridInputError(FrameInputError):
    """The frame cannot be turned into grids: a bad frame (see validate_frame) or bad grid settings."""


class EmptyObjectError(GridInputError):
    """The object has too few valid depth points to build a grid."""


@dataclass(frozen=True, eq=False)
class GridFrame:
    """Placement of a d^3 grid in the world frame (metres). table_source says where the table
    height came from: 'local' (support plane under the object), 'frame' (frame-wide table),
    'given' (caller's value) or 'object' (lowest observed object point; no table seen)."""

    origin_world: np.ndarray
    voxel_size_m: float
    resolution: int
    table_height_m: float
    table_source: str = "local"

    def __eq__(self, other) -> bool:
        if not isinstance(other, GridFrame):
            return NotImplemented
        return (
            np.array_equal(np.asarray(self.origin_world), np.asarray(other.origin_world))
            and self.voxel_size_m == other.voxel_size_m
            and self.resolution == other.resolution
            and self.table_height_m == other.table_height_m
        )

    __hash__ = None

    @property
    def side_m(self) -> float:
        return self.voxel_size_m * self.resolution

    def voxel_centers_world(self) -> np.ndarray:
        """(d, d, d, 3) world coordinates of the voxel centres, metres."""
        axis = (np.arange(self.resolution) + 0.5) * self.voxel_size_m
        x, y, z = np.meshgrid(axis, axis, axis, indexing="ij")
        return np.stack([x, y, z], -1) + np.asarray(self.origin_world, dtype=np.float64)

    def world_to_voxel(self, points_world: np.ndarray) -> np.ndarray:
        """(N, 3) world points -> (N, 3) continuous voxel coordinates; voxel (i, j, l) spans
        [i, i + 1) x [j, j + 1) x [l, l + 1), so floor() gives the index and centres sit at +0.5."""
        points_world = np.asarray(points_world, dtype=np.float64).reshape(-1, 3)
        return (points_world - np.asarray(self.origin_world)) / self.voxel_size_m

    def voxel_to_world(self, voxel_coords: np.ndarray) -> np.ndarray:
        """(N, 3) continuous voxel coordinates -> (N, 3) world points, metres."""
        voxel_coords = np.asarray(voxel_coords, dtype=np.float64).reshape(-1, 3)
        return voxel_coords * self.voxel_size_m + np.asarray(self.origin_world)

    def voxel_indices(self, points_world: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(N, 3) world points -> ((M, 3) int64 indices of the points inside, (N,) inside mask)."""
        index = np.floor(self.world_to_voxel(points_world)).astype(np.int64)
        inside = np.all((index >= 0) & (index < self.resolution), axis=1)
        return index[inside], inside


@dataclass
class FrameGrids:
    """Grids of the objects of one frame: grids[n] belongs to object_ids[n]; objects that could not
    be gridded are in errors (id -> reason) and have no grid. observation: the back-projected frame
    they were built from (object points and normals)."""

    grids: np.ndarray
    frames: list[GridFrame]
    object_ids: list[int]
    errors: dict[int, str]
    observation: "FrameObservation | None" = None


def point_set_diameter(points: np.ndarray) -> float:
    """Largest distance between two points (exact for <= MAX_HULL_POINTS points: pairwise distances
    of the convex hull's vertices; larger sets are subsampled with a fixed stride)."""
    points = np.asarray(points, dtype=np.float64)
    if len(points) < 2:
        return 0.0
    if len(points) > MAX_HULL_POINTS:
        points = points[:: int(np.ceil(len(points) / MAX_HULL_POINTS))]
    try:
        candidates = points[ConvexHull(points).vertices]
    except (QhullError, ValueError):
        candidates = points
        if len(candidates) > 512:
            extent = candidates.max(0) - candidates.min(0)
            return float(np.linalg.norm(extent))
    diff = candidates[:, None, :] - candidates[None, :, :]
    return float(np.sqrt(np.max(np.einsum("ijk,ijk->ij", diff, diff))))


def support_height(z_values: np.ndarray, max_height_m: float, min_points: int = 20) -> float | None:
    """Height of the highest horizontal support level at or below max_height_m.

    z_values are heights of table/background points. A level is a SUPPORT_BIN_M histogram bin (summed
    with its neighbours) holding at least min_points and at least a quarter of the best bin's count;
    the highest such level wins (objects on a shelf rest on the shelf, not on the floor), refined to
    the median height of its points. None when no level qualifies."""
    z = np.asarray(z_values, dtype=np.float64)
    z = z[z <= max_height_m]
    if len(z) < min_points:
        return None
    lo = z.min()
    bins = np.floor((z - lo) / SUPPORT_BIN_M).astype(np.int64)
    counts = np.bincount(bins)
    smoothed = counts + np.concatenate([[0], counts[:-1]]) + np.concatenate([counts[1:], [0]])
    threshold = max(min_points, 0.25 * smoothed.max())
    good = np.nonzero(smoothed >= threshold)[0]
    if len(good) == 0:
        return None
    top = good[-1]
    near = np.abs(bins - top) <= 1
    return float(np.median(z[near]))


def consistent_object_pixels(depth_m: np.ndarray, labels: np.ndarray) -> np.ndarray:
    """HxW bool: object pixels (label > 0, depth > 0) whose depth belongs to their object.

    Along a mask's outline a real sensor returns mixed ("flying") depths between the object and what
    is behind it, and depth registered a pixel off the colour image gives outline pixels the
    background's depth: back-projected, they lie centimetres to metres behind the object, swell its
    diameter (the grid's size) and add far-off observed voxels. A pixel further than EDGE_INTERIOR_PX
    from its mask's border is kept; one nearer is kept when its depth lies within the range of the
    object's interior depths in the EDGE_WINDOW_PX window around it (widened by EDGE_TOLERANCE_M +
    EDGE_TOLERANCE_PER_M * depth) or, with no interior pixel in that window (a thin part), within the
    object's interior depth range over the whole mask, equally widened; with no interior at all, kept.
    Depth registered several pixels off leaves a wider band: background_behind finds it, and it is
    left out wherever it lies."""
    depth_m, labels = np.asarray(depth_m), np.asarray(labels)
    valid = (labels > 0) & (depth_m > 0)
    keep = valid.copy()
    margin = EDGE_WINDOW_PX + EDGE_INTERIOR_PX
    ids = np.unique(labels[valid])
    dense = np.zeros(labels.shape, dtype=np.int32)
    dense[valid] = np.searchsorted(ids, labels[valid]) + 1
    for object_id, box in zip(ids, ndimage.find_objects(dense, len(ids)), strict=True):
        if box is None:
            continue
        crop = tuple(slice(max(0, b.start - margin), b.stop + margin) for b in box)
        mask = valid[crop] & (labels[crop] == object_id)
        interior = ndimage.binary_erosion(mask, iterations=EDGE_INTERIOR_PX)
        if not interior.any():
            continue
        depth = depth_m[crop]
        tolerance = EDGE_TOLERANCE_M + EDGE_TOLERANCE_PER_M * depth
        low = ndimage.minimum_filter(np.where(interior, depth, np.inf), EDGE_WINDOW_PX)
        high = ndimage.maximum_filter(np.where(interior, depth, -np.inf), EDGE_WINDOW_PX)
        no_interior_near = ~np.isfinite(low)
        low = np.where(no_interior_near, depth[interior].min(), low)
        high = np.where(no_interior_near, depth[interior].max(), high)
        consistent = (depth >= low - tolerance) & (depth <= high + tolerance)
        behind = background_behind(depth, mask, labels[crop] == object_id)
        keep[crop] &= ~mask | (interior | consistent) & ~behind
    return keep


def background_behind(depth_m: np.ndarray, mask: np.ndarray, region: np.ndarray) -> np.ndarray:
    """HxW bool: the pixels of mask (an object's pixels with depth; region: all its pixels) in pieces
    that carry the depth of the surface outside the object beside them: a band that the mask took
    where the sensor registers depth several pixels off the colour image (on a RealSense frame the
    side of a bottle carried the table's depth 35 cm behind over up to 6 px, at times past pixels
    without a return), wider than the outline the window test looks at.

    Pieces are 4-connected pixels whose depths differ by under JUMP_M + JUMP_PER_M x depth. A piece
    other than the largest, on the mask's border and under BEHIND_SHARE of the mask, is such a band
    when most of its pixels near the largest piece lie behind it by more than a jump and most of its
    pixels near the outside surface (pixels of other objects or of none, within BEHIND_WINDOW_PX) lie
    on it (within EDGE_TOLERANCE_M + EDGE_TOLERANCE_PER_M x depth of its mean there). A part of the
    object that it hides from itself (a lamp's stem under its shade) lies in front of what is behind
    it and stays."""
    n = int(mask.sum())
    index = np.full(mask.shape, -1, dtype=np.int64)
    index[mask] = np.arange(n)
    pairs = []
    for a, b, da, db in (
        (index[:, :-1], index[:, 1:], depth_m[:, :-1], depth_m[:, 1:]),
        (index[:-1, :], index[1:, :], depth_m[:-1, :], depth_m[1:, :]),
    ):
        joined = (a >= 0) & (b >= 0) & (np.abs(da - db) < JUMP_M + JUMP_PER_M * np.minimum(da, db))
        pairs.append(np.stack([a[joined], b[joined]], 1))
    pairs = np.concatenate(pairs)
    graph = scipy.sparse.coo_matrix((np.ones(len(pairs)), (pairs[:, 0], pairs[:, 1])), shape=(n, n))
    count, piece = scipy.sparse.csgraph.connected_components(graph, directed=False)
    if count < 2:
        return np.zeros(mask.shape, dtype=bool)
    sizes = np.bincount(piece, minlength=count)
    largest = np.zeros(mask.shape)
    largest[mask] = piece == np.argmax(sizes)
    outside = (~region & (depth_m > 0)).astype(np.float64)
    depth = depth_m[mask]

    def near_and_mean_m(weights):
        """Per mask pixel: whether weighted pixels lie in its window, and their mean depth (m)."""
        weight = ndimage.uniform_filter(weights, BEHIND_WINDOW_PX, mode="constant")[mask]
        total = ndimage.uniform_filter(weights * depth_m, BEHIND_WINDOW_PX, mode="constant")[mask]
        return weight > 1e-9, total / np.maximum(weight, 1e-12)

    near_largest, largest_m = near_and_mean_m(largest)
    near_largest &= largest[mask] == 0
    near_outside, outside_m = near_and_mean_m(outside)
    behind = near_largest & (depth - largest_m > JUMP_M + JUMP_PER_M * depth)
    on_outside = near_outside & (np.abs(depth - outside_m) < EDGE_TOLERANCE_M + EDGE_TOLERANCE_PER_M * depth)

    def most(flags, of):
        """Per piece: whether flags hold for more than half of its pixels that `of` marks."""
        hits = np.bincount(piece, weights=flags, minlength=count)
        return hits > 0.5 * np.maximum(np.bincount(piece, weights=of, minlength=count), 1)

    border = mask & ~ndimage.binary_erosion(mask, border_value=0)
    on_border = np.bincount(piece[index[border]], minlength=count) > 0
    cut = most(behind, near_largest) & most(on_outside, near_outside) & on_border & (sizes < BEHIND_SHARE * n)
    out = np.zeros(mask.shape, dtype=bool)
    out[mask] = cut[piece]
    return out


class FrameObservation:
    """One RGB-D frame back-projected once and shared by the grids of all its objects."""

    def __init__(self, depth_m, K, T_world_camera, labels, background_stride: int = 2):
        frame = validate_frame(depth_m, K, T_world_camera, labels=labels)
        self.depth_m, self.K, self.T_world_camera, labels = frame.depth_m, frame.K, frame.T_world_camera, frame.labels
        self.height, self.width = self.depth_m.shape
        self.T_camera_world = np.linalg.inv(self.T_world_camera)
        valid = self.depth_m > 0
        v, u = np.nonzero(consistent_object_pixels(self.depth_m, labels))
        object_labels = labels[v, u].astype(np.int64)
        order = np.argsort(object_labels, kind="stable")
        v, u = v[order], u[order]
        self._object_pixels = (v, u)
        self._object_normals = None
        self._labels = labels
        self.object_points = self._backproject(v, u)
        self.object_point_labels = object_labels[order]
        s = int(background_stride)
        vb, ub = np.nonzero(valid[::s, ::s] & (labels[::s, ::s] == 0))
        background = self._backproject(vb * s, ub * s)
        self.background_x, self.background_y = background[:, 0].copy(), background[:, 1].copy()
        self.background_z = background[:, 2].copy()
        ids, starts, counts = np.unique(self.object_point_labels, return_index=True, return_counts=True)
        self._slices = {int(i): slice(int(a), int(a + c)) for i, a, c in zip(ids, starts, counts, strict=True)}
        self.object_ids = [int(i) for i in ids]

    def _backproject(self, v: np.ndarray, u: np.ndarray) -> np.ndarray:
        """Pixels (rows v, columns u) with valid depth -> (N, 3) float64 world points, metres."""
        return backproject_pixels(self.depth_m, v, u, self.K, self.T_world_camera)

    def points_of(self, object_id: int) -> np.ndarray:
        sl = self._slices.get(int(object_id))
        return self.object_points[sl] if sl is not None else np.zeros((0, 3))

    def normals_of(self, object_id: int) -> np.ndarray:
        """(N, 3) world-frame unit surface normals (towards the camera) at points_of(object_id), from
        the organized depth image with each object's holes filled from its own pixels
        (NORMAL_WINDOW_PX box); zero where that leaves a neighbour without depth."""
        if self._object_normals is None:
            filled = object_depth_average(
                self.depth_m, self._labels, self.object_ids, NORMAL_WINDOW_PX, fill_holes=True
            )
            normals_camera = organized_normals(backproject_image(filled, self.K))
            v, u = self._object_pixels
            self._object_normals = normals_camera[v, u].astype(np.float64) @ self.T_world_camera[:3, :3].T
        sl = self._slices.get(int(object_id))
        return self._object_normals[sl] if sl is not None else np.zeros((0, 3))

    def hidden_by_others(self, points_world: np.ndarray, object_id: int) -> np.ndarray:
        """(N,) bool: the camera cannot see each world point (N, 3) for another segmented object in
        front of it, or for lying outside the image (no depth return alone hides nothing)."""
        points_world = np.asarray(points_world, dtype=np.float64).reshape(-1, 3)
        camera = points_world @ self.T_camera_world[:3, :3].T + self.T_camera_world[:3, 3]
        z = camera[:, 2]
        u, v = (np.floor(c) for c in pixel_coordinates(np.where(z[:, None] > 1e-6, camera, 1.0), self.K))
        in_image = (z > 1e-6) & (u >= 0) & (u < self.width) & (v >= 0) & (v < self.height)
        ui, vi = np.where(in_image, u, 0).astype(np.int64), np.where(in_image, v, 0).astype(np.int64)
        depth, label = self.depth_m[vi, ui], self._labels[vi, ui]
        in_front = (depth > 0) & (depth < z) & (label != 0) & (label != object_id)
        return ~in_image | in_front

    def frame_table_height(self, max_height_m: float) -> float | None:
        return support_height(self.background_z, max_height_m, min_points=50)

    def grid_frame(self, object_id: int, resolution: int, k: float, table_height_m: float | None) -> GridFrame:
        own = self.points_of(object_id)
        if len(own) < MIN_OBJECT_POINTS:
            raise EmptyObjectError(
                f"object {object_id} has {len(own)} valid depth points (< {MIN_OBJECT_POINTS}); cannot build a grid"
            )
        centre = own.mean(0)
        diameter = max(point_set_diameter(own), MIN_DIAMETER_M)
        side = k * diameter
        bottom = float(np.percentile(own[:, 2], 2.0))
        max_support = bottom + SUPPORT_TOLERANCE_M
        source = "given"
        table = table_height_m

        def plausible(height: float | None) -> float | None:
            # A support more than SUPPORT_REACH x the object's seen diameter below its seen bottom (the
            # floor past a table edge, say) is not this object's.
            reach = SUPPORT_REACH * diameter
            return height if height is not None and np.isfinite(height) and bottom - height <= reach else None

        if table is None:
            # The support is looked for within SUPPORT_REACH seen diameters around the object.
            x, y = self.background_x, self.background_y
            low, high = centre[:2] - SUPPORT_REACH * diameter, centre[:2] + SUPPORT_REACH * diameter
            inside = (x >= low[0]) & (x < high[0]) & (y >= low[1]) & (y < high[1])
            table, source = plausible(support_height(self.background_z[inside], max_support, min_points=10)), "local"
        if table is None:
            table, source = plausible(self.frame_table_height(max_support)), "frame"
        if table is None:
            table, source = float(own[:, 2].min()), "object"
        # The grid reaches from the support to above the seen top: an object seen only above its hidden
        # lower part is not cut off at k x its seen diameter.
        seen_height = float(np.percentile(own[:, 2], 98.0)) - table
        side = max(side, TOP_MARGIN * seen_height)
        xy_min = centre[:2] - side / 2
        origin = np.array([xy_min[0], xy_min[1], table], dtype=np.float64)
        return GridFrame(origin, float(side / resolution), int(resolution), float(table), source)

    def grid(self, object_id: int, frame: GridFrame) -> np.ndarray:
        d = frame.resolution
        grid = np.zeros((4, d, d, d), dtype=np.float32)
        index, inside = frame.voxel_indices(self.object_points)
        is_own = self.object_point_labels[inside] == object_id
        own_idx, other_idx = index[is_own], index[~is_own]
        grid[0][own_idx[:, 0], own_idx[:, 1], own_idx[:, 2]] = 1.0
        grid[1][other_idx[:, 0], other_idx[:, 1], other_idx[:, 2]] = 1.0
        observed_empty = self.observed_empty(frame)
        occupied = (grid[0] > 0) | (grid[1] > 0)
        grid[2] = observed_empty & ~occupied
        grid[3] = ~observed_empty & ~occupied
        return grid

    def observed_empty(self, frame: GridFrame) -> np.ndarray:
        """(d, d, d) bool: the camera ray through the voxel centre returned a depth beyond it, i.e. the
        ray traversed the voxel before hitting a surface (per-voxel form of pixel-ray traversal)."""
        d = frame.resolution
        axis = (np.arange(d) + 0.5) * frame.voxel_size_m
        R, t = self.T_camera_world[:3, :3], self.T_camera_world[:3, 3]
        base = R @ np.asarray(frame.origin_world) + t
        cam = (
            base
            + (axis[:, None] * R[:, 0])[:, None, None, :]
            + (axis[:, None] * R[:, 1])[None, :, None, :]
            + (axis[:, None] * R[:, 2])[None, None, :, :]
        )
        z = cam[..., 2]
        in_front = z > 1e-6
        u, v = (np.floor(c) for c in pixel_coordinates(np.where(in_front[..., None], cam, 1.0), self.K))
        in_image = in_front & (u >= 0) & (u < self.width) & (v >= 0) & (v < self.height)
        ui = np.where(in_image, u, 0).astype(np.int64)
        vi = np.where(in_image, v, 0).astype(np.int64)
        depth = self.depth_m[vi, ui]
        return in_image & (depth > 0) & (z < depth)


def four_channel_grid(
    depth_m,
    K,
    T_world_camera,
    labels,
    object_id: int,
    resolution: int = DEFAULT_RESOLUTION,
    k: float = DEFAULT_K,
    table_height_m: float | None = None,
) -> tuple[np.ndarray, GridFrame]:
    """Four-channel grid of one object -> (float32 [4, d, d, d], GridFrame).

    depth_m: HxW metres along the optical axis (0/NaN = no return); K: 3x3 pixels; T_world_camera:
    4x4 optical-frame pose; labels: HxW instance ids (0 = table/background). table_height_m=None
    estimates the support plane under the object. Raises GridInputError / EmptyObjectError."""
    _check_settings(resolution, k)
    observation = FrameObservation(depth_m, K, T_world_camera, labels)
    frame = observation.grid_frame(int(object_id), int(resolution), float(k), table_height_m)
    return observation.grid(int(object_id), frame), frame


def frame_grids(
    depth_m,
    K,
    T_world_camera,
    labels,
    object_ids=None,
    resolution: int = DEFAULT_RESOLUTION,
    k: float = DEFAULT_K,
    table_height_m: float | None = None,
) -> FrameGrids:
    """Grids of all objects of one frame (object_ids=None: every label > 0 with depth points), sharing
    the back-projection. Per-object failures (too few points) go to errors instead of raising."""
    _check_settings(resolution, k)
    observation = FrameObservation(depth_m, K, T_world_camera, labels)
    ids = observation.object_ids if object_ids is None else [int(i) for i in object_ids]
    grids, frames, ok_ids, errors = [], [], [], {}
    for object_id in ids:
        if object_id <= 0:
            errors[object_id] = "label 0 is the table/background, not an object"
            continue
        try:
            frame = observation.grid_frame(object_id, int(resolution), float(k), table_height_m)
        except EmptyObjectError as error:
            errors[object_id] = str(error)
            continue
        grids.append(observation.grid(object_id, frame))
        frames.append(frame)
        ok_ids.append(object_id)
    d = int(resolution)
    stacked = np.stack(grids) if grids else np.zeros((0, 4, d, d, d), dtype=np.float32)
    return FrameGrids(stacked, frames, ok_ids, errors, observation)


def _check_settings(resolution, k):
    if int(resolution) < 8 or int(resolution) % 8:
        raise GridInputError(f"resolution must be a positive multiple of 8, got {resolution}")
    if not np.isfinite(k) or k <= 1.0:
        raise GridInputError(f"k must be a finite number > 1, got {k}")


def voxelize_mesh(mesh_world, frame: GridFrame) -> np.ndarray:
    """bool [d, d, d]: voxel centres inside a watertight world-frame mesh (ray parity along +z).

    Every triangle is intersected with the vertical lines through the voxel-centre columns its xy
    bounding box covers; a centre is inside when an odd number of crossings lies below it."""
    d = frame.resolution
    vertices = frame.world_to_voxel(np.asarray(mesh_world.vertices)) - 0.5
    triangles = vertices[np.asarray(mesh_world.faces, dtype=np.int64)]
    occupancy = np.zeros((d, d, d), dtype=bool)
    if len(triangles) == 0:
        return occupancy
    jitter = np.array([1.234567e-6, 2.345678e-6])
    xy = triangles[:, :, :2] - jitter
    lo = np.clip(np.ceil(xy.min(1)), 0, d).astype(np.int64)
    hi = np.clip(np.floor(xy.max(1)), -1, d - 1).astype(np.int64)
    n_i = np.maximum(hi[:, 0] - lo[:, 0] + 1, 0)
    n_j = np.maximum(hi[:, 1] - lo[:, 1] + 1, 0)
    per_triangle = n_i * n_j
    total = int(per_triangle.sum())
    if total == 0:
        return occupancy
    tri = np.repeat(np.arange(len(triangles)), per_triangle)
    offset = np.arange(total) - np.repeat(np.cumsum(per_triangle) - per_triangle, per_triangle)
    col_i = lo[tri, 0] + offset // n_j[tri]
    col_j = lo[tri, 1] + offset % n_j[tri]
    a, b, c = xy[tri, 0], xy[tri, 1], xy[tri, 2]
    p = np.stack([col_i, col_j], 1).astype(np.float64)
    v0, v1, v2 = b - a, c - a, p - a
    den = v0[:, 0] * v1[:, 1] - v1[:, 0] * v0[:, 1]
    nondegenerate = np.abs(den) > 1e-12
    den = np.where(nondegenerate, den, 1.0)
    w1 = (v2[:, 0] * v1[:, 1] - v1[:, 0] * v2[:, 1]) / den
    w2 = (v0[:, 0] * v2[:, 1] - v2[:, 0] * v0[:, 1]) / den
    w0 = 1.0 - w1 - w2
    hit = nondegenerate & (w0 >= 0) & (w1 >= 0) & (w2 >= 0)
    z = triangles[tri, :, 2]
    z_hit = (w0 * z[:, 0] + w1 * z[:, 1] + w2 * z[:, 2])[hit]
    first_above = np.clip(np.floor(z_hit) + 1, 0, d).astype(np.int64)
    crossings = np.zeros((d, d, d + 1), dtype=np.int32)
    np.add.at(crossings, (col_i[hit], col_j[hit], first_above), 1)
    occupancy[:] = (np.cumsum(crossings, axis=2)[:, :, :d] % 2) == 1
    return occupancy
