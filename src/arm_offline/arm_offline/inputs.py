"""The input folder of reconstruct_frames: frame discovery, intrinsics, poses and images.

Input layout (a frame is named by the file stem shared by its colour and depth images):

    DIR/color/<frame>.png|.jpg|.jpeg     colour (rgb/ is accepted as the folder name too)
    DIR/depth/<frame>.png                16-bit depth, millimetres unless --depth-scale says otherwise
    DIR/intrinsics.json                  {"fx", "fy", "cx", "cy", "width", "height"} (pixels)
      or DIR/camera_info.yaml            a ROS CameraInfo YAML as written by camera_calibration
    DIR/poses.json                       optional: {"<frame>": 4x4 T_world_camera (nested lists, metres)}

Flat names work too: DIR/rgb_<frame>.png (or color_<frame>.*) next to DIR/depth_<frame>.png.
The camera is the optical frame (x right, y down, z forward); the world frame of given poses should
have z up (gravity) so that the table is horizontal. Frames missing from poses.json get an estimated pose.
"""

import json
import pathlib
from dataclasses import dataclass

import cv2
import numpy as np
import yaml

from arm_core.frames import FrameInputError  # raised here for a missing, unreadable or inconsistent file

COLOUR_SUFFIXES = (".png", ".jpg", ".jpeg")
COLOUR_DIRS = ("color", "rgb")
COLOUR_PREFIXES = ("rgb_", "color_")
DEPTH_DIR, DEPTH_PREFIX = "depth", "depth_"
INTRINSICS_FILES = ("intrinsics.json", "camera_info.yaml", "camera_info.yml")
POSES_FILE = "poses.json"


@dataclass(frozen=True)
class Camera:
    """Pinhole intrinsics (K in pixels) of images width x height; distortion as in CameraInfo
    (arm_core.distortion undistorts); path: the file it was read from."""

    K: np.ndarray
    width: int
    height: int
    distortion_model: str = ""
    distortion: tuple[float, ...] = ()
    path: pathlib.Path | None = None


@dataclass
class FrameFiles:
    name: str
    colour: list[pathlib.Path]
    depth: list[pathlib.Path]


def find_frames(folder: pathlib.Path) -> list[FrameFiles]:
    """Every frame stem seen in either layout, sorted by name, with all files found for it."""
    frames: dict[str, FrameFiles] = {}

    def add(name: str, path: pathlib.Path, kind: str) -> None:
        getattr(frames.setdefault(name, FrameFiles(name, [], [])), kind).append(path)

    for directory in COLOUR_DIRS:
        for path in sorted((folder / directory).glob("*")):
            if path.suffix.lower() in COLOUR_SUFFIXES:
                add(path.stem, path, "colour")
    for path in sorted((folder / DEPTH_DIR).glob("*")):
        if path.suffix.lower() == ".png":
            add(path.stem, path, "depth")
    for path in sorted(folder.glob("*")):
        stem, suffix = path.stem, path.suffix.lower()
        for prefix in COLOUR_PREFIXES:
            if stem.startswith(prefix) and suffix in COLOUR_SUFFIXES:
                add(stem[len(prefix) :], path, "colour")
        if stem.startswith(DEPTH_PREFIX) and suffix == ".png":
            add(stem[len(DEPTH_PREFIX) :], path, "depth")
    return [frames[name] for name in sorted(frames)]


def find_intrinsics(folder: pathlib.Path) -> pathlib.Path:
    for name in INTRINSICS_FILES:
        if (folder / name).is_file():
            return folder / name
    raise FrameInputError(f"no intrinsics in {folder}: expected one of {', '.join(INTRINSICS_FILES)}")


def _pinhole(fx, fy, cx, cy, width, height, source: pathlib.Path) -> tuple[np.ndarray, int, int]:
    try:
        K = np.array([[fx, 0.0, cx], [0.0, fy, cy], [0.0, 0.0, 1.0]], dtype=np.float64)
        width, height = int(width), int(height)
    except (TypeError, ValueError) as error:
        raise FrameInputError(f"{source}: intrinsics are not numbers ({error})") from error
    if not np.all(np.isfinite(K)) or K[0, 0] <= 0 or K[1, 1] <= 0 or width <= 0 or height <= 0:
        raise FrameInputError(f"{source}: invalid intrinsics fx={fx} fy={fy} cx={cx} cy={cy} {width}x{height}")
    return K, width, height


def load_camera(path: pathlib.Path) -> Camera:
    """intrinsics.json or a CameraInfo YAML -> Camera. Raises FrameInputError naming the file."""
    try:
        text = path.read_text()
        data = json.loads(text) if path.suffix == ".json" else yaml.safe_load(text)
    except (OSError, ValueError, yaml.YAMLError) as error:
        raise FrameInputError(f"{path}: cannot read intrinsics ({error})") from error
    if not isinstance(data, dict):
        raise FrameInputError(f"{path}: intrinsics must be a mapping")
    if path.suffix == ".json":
        missing = [key for key in ("fx", "fy", "cx", "cy", "width", "height") if key not in data]
        if missing:
            raise FrameInputError(f"{path}: missing {', '.join(missing)}")
        return Camera(*_pinhole(*(data[k] for k in ("fx", "fy", "cx", "cy", "width", "height")), path), path=path)
    try:
        matrix = np.asarray(data["camera_matrix"]["data"], dtype=np.float64).reshape(3, 3)
        width, height = data["image_width"], data["image_height"]
        distortion = tuple(float(d) for d in (data.get("distortion_coefficients") or {}).get("data") or ())
    except (KeyError, TypeError, ValueError) as error:
        raise FrameInputError(
            f"{path}: not a CameraInfo YAML (needs image_width, image_height, camera_matrix.data: 9 numbers; {error!r})"
        ) from error
    K, width, height = _pinhole(matrix[0, 0], matrix[1, 1], matrix[0, 2], matrix[1, 2], width, height, path)
    return Camera(K, width, height, str(data.get("distortion_model") or ""), distortion, path)


def load_poses(path: pathlib.Path) -> dict[str, np.ndarray]:
    """poses.json -> {frame: T_world_camera}. Raises FrameInputError for a malformed file or pose."""
    try:
        data = json.loads(path.read_text())
    except (OSError, ValueError) as error:
        raise FrameInputError(f"{path}: cannot read poses ({error})") from error
    if not isinstance(data, dict):
        raise FrameInputError(f"{path}: poses must be a mapping frame -> 4x4 T_world_camera")
    poses = {}
    for name, value in data.items():
        try:
            T = np.asarray(value, dtype=np.float64)
        except (TypeError, ValueError):
            T = np.empty(0)
        R = T[:3, :3] if T.shape == (4, 4) else np.eye(3)
        if (
            T.shape != (4, 4)
            or not np.all(np.isfinite(T))
            or not np.allclose(T[3], [0, 0, 0, 1])
            or not np.allclose(R @ R.T, np.eye(3), atol=1e-4)
            or np.linalg.det(R) < 0
        ):
            raise FrameInputError(f"{path}: pose of frame '{name}' is not a rigid 4x4 transform")
        poses[str(name)] = T
    return poses


def _single(paths: list[pathlib.Path], what: str, name: str, partners: list[pathlib.Path]) -> pathlib.Path:
    if not paths:
        raise FrameInputError(f"{', '.join(map(str, partners))}: no {what} image for frame '{name}'")
    if len(paths) > 1:
        raise FrameInputError(f"{len(paths)} {what} images for frame '{name}': {', '.join(map(str, paths))}")
    return paths[0]


def load_rgb(path: pathlib.Path) -> np.ndarray:
    image = cv2.imread(str(path), cv2.IMREAD_COLOR)
    if image is None:
        raise FrameInputError(f"{path}: cannot read or decode the colour image")
    return np.ascontiguousarray(image[..., ::-1])


def load_depth_m(path: pathlib.Path, metres_per_unit: float) -> np.ndarray:
    image = cv2.imread(str(path), cv2.IMREAD_UNCHANGED)
    if image is None:
        raise FrameInputError(f"{path}: cannot read or decode the depth image")
    if image.dtype != np.uint16 or image.ndim != 2:
        channels = 1 if image.ndim == 2 else image.shape[2]
        raise FrameInputError(
            f"{path}: depth must be a single-channel 16-bit PNG, got {image.dtype} with {channels} channel(s)"
        )
    return image.astype(np.float32) * np.float32(metres_per_unit)


def load_frame(files: FrameFiles, camera: Camera, metres_per_unit: float) -> tuple[np.ndarray, np.ndarray]:
    """(rgb uint8 HxWx3, depth float32 HxW metres, 0 = no return) of one frame, checked against the
    camera's image size. Raises FrameInputError naming the file at fault."""
    colour_path = _single(files.colour, "colour", files.name, files.depth)
    depth_path = _single(files.depth, "depth", files.name, files.colour)
    rgb, depth_m = load_rgb(colour_path), load_depth_m(depth_path, metres_per_unit)
    if rgb.shape[:2] != depth_m.shape:
        raise FrameInputError(
            f"colour {colour_path} is {rgb.shape[1]}x{rgb.shape[0]} but depth {depth_path} "
            f"is {depth_m.shape[1]}x{depth_m.shape[0]}"
        )
    if depth_m.shape != (camera.height, camera.width):
        raise FrameInputError(
            f"{depth_path} is {depth_m.shape[1]}x{depth_m.shape[0]} but the intrinsics are for "
            f"{camera.width}x{camera.height}"
        )
    return rgb, depth_m
