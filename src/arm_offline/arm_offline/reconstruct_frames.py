"""reconstruct_frames: a folder of RGB-D frames -> per-frame segmentation, object meshes, convex parts
and an MJCF scene, without a ROS graph.

    reconstruct_frames --input DIR --output OUT [--depth-scale S] [--mesh-format ply|obj|stl] [--overwrite]

Per frame, OUT/<frame>/ receives overlay.png (segmentation), labels.png (uint16 instance labels),
object_<id>.<fmt> and object_<id>_part_<j>.<fmt> (world frame, metres), scene.xml (MJCF: table +
objects as free bodies) and result.json; OUT/summary.json lists every frame (objects, sizes, timings,
pose source, errors). A frame whose result.json exists is skipped unless --overwrite.
Exit status: 0 if any frame succeeded, 1 if none did, 2 for bad arguments.
"""

import argparse
import json
import pathlib
import sys
import time
from dataclasses import dataclass, field

import cv2
import numpy as np
from tqdm import tqdm

from arm_core.atomic_io import atomic_write_json
from arm_core.distortion import DistortionError, Undistorter
from arm_core.frames import FrameInputError
from arm_offline import inputs
from arm_offline.export import (
    MESH_FORMATS,
    ExportedObject,
    SceneError,
    exported_objects,
    scene_mjcf,
    write_object_meshes,
)
from arm_offline.inputs import (
    POSES_FILE,
    Camera,
    FrameFiles,
    find_frames,
    find_intrinsics,
    load_camera,
    load_frame,
    load_poses,
)
from arm_reconstruction.checkpoint import CheckpointError
from arm_reconstruction.messages import main_table_height
from arm_reconstruction.pipeline import ReconstructedObject, ReconstructionSettings, Reconstructor
from arm_segmentation.camera_pose_estimate import CameraPoseError, estimate_camera_pose
from arm_segmentation.segmentation import SegmentationParams, segment_detailed
from arm_segmentation.table_plane import SupportLevel
from arm_segmentation.visualization import overlay

RESULT_FILE, SUMMARY_FILE, SCENE_FILE = "result.json", "summary.json", "scene.xml"
OVERLAY_FILE, LABELS_FILE = "overlay.png", "labels.png"
FRAME_ERRORS = (FrameInputError, CameraPoseError, SceneError)  # FrameInputError covers GridInputError


@dataclass(frozen=True)
class OfflineSettings:
    metres_per_depth_unit: float = 0.001
    mesh_format: str = "ply"
    overwrite: bool = False
    segmentation: SegmentationParams = field(default_factory=SegmentationParams)
    reconstruction: ReconstructionSettings = field(default_factory=ReconstructionSettings)

    def __post_init__(self):
        if self.mesh_format not in MESH_FORMATS:
            raise ValueError(f"mesh format must be one of {MESH_FORMATS}, got {self.mesh_format!r}")
        if not np.isfinite(self.metres_per_depth_unit) or self.metres_per_depth_unit <= 0:
            raise ValueError(f"depth scale must be > 0 metres per unit, got {self.metres_per_depth_unit}")


def camera_pose(depth_m: np.ndarray, K: np.ndarray, given: np.ndarray | None) -> tuple[np.ndarray, dict]:
    """(T_world_camera, summary fields): the given pose, else the gravity-aligned estimate from the
    depth's dominant plane. Raises CameraPoseError when no pose can be estimated."""
    if given is not None:
        return given, {"pose_source": "given"}
    estimate = estimate_camera_pose(depth_m, K)
    fields = {"pose_source": "estimated", "pose_inlier_fraction": float(estimate.inlier_fraction)}
    return estimate.T_world_camera, fields


def table_support(objects: list[ReconstructedObject], levels: list[SupportLevel]) -> tuple[float, np.ndarray | None]:
    """(table height in metres, its footprint xy or None): the segmentation's table level (the one
    the objects stand on; higher levels stand on it), else the table height the reconstruction saw
    under its objects."""
    if levels:
        return float(levels[0].height_m), levels[0].hull_xy
    return main_table_height(objects), None


def object_entry(
    obj: ReconstructedObject, pixels: int, exported: ExportedObject | None, files: dict, body: str | None
) -> dict:
    """The object's entry in result.json (pixels: its count in the label image; exported: None when it
    was not reconstructed)."""
    entry = {"id": obj.id, "ok": obj.ok, "error": obj.error, "pixels": pixels}
    if exported is not None:
        mesh = exported.world_mesh
        entry |= files | {
            "body": body,
            "centre_world_m": [round(float(v), 5) for v in obj.T_world_object[:3, 3]],
            "extents_m": [round(float(v), 5) for v in mesh.extents],
            "volume_m3": float(mesh.volume) if mesh.is_watertight else None,
            "watertight": bool(mesh.is_watertight),
            "visible_fraction": round(float(obj.visible_fraction), 4),
        }
    return entry


def _own_files(folder: pathlib.Path) -> list[pathlib.Path]:
    names = (RESULT_FILE, SCENE_FILE, OVERLAY_FILE, LABELS_FILE)
    return [folder / n for n in names if (folder / n).exists()] + sorted(folder.glob("object_*"))


def _completed(folder: pathlib.Path) -> dict | None:
    """The frame's result if a previous run finished it and its files are still there."""
    try:
        result = json.loads((folder / RESULT_FILE).read_text())
    except (OSError, ValueError):
        return None
    names = [result.get("scene"), result.get("overlay")]
    names += [n for o in result.get("objects", []) for n in [o.get("mesh"), *o.get("convex_parts", [])] if o.get("ok")]
    return result if all(n and (folder / n).is_file() for n in names) else None


class FrameReconstructor:
    """Segments and reconstructs frames with one loaded network; writes each frame's outputs."""

    def __init__(self, settings: OfflineSettings, reconstructor: Reconstructor | None = None):
        self.settings = settings
        self.reconstructor = reconstructor or Reconstructor(settings.reconstruction)
        self.undistorter = Undistorter()

    def undistorted(self, rgb: np.ndarray, depth_m: np.ndarray, camera: Camera) -> tuple[np.ndarray, np.ndarray]:
        """The images resampled to the camera's pinhole K (as given when the distortion is all zero)."""
        try:
            return self.undistorter.undistort(rgb, depth_m, camera.distortion_model, camera.distortion, camera.K)
        except DistortionError as error:
            model = f"{camera.distortion_model} {list(camera.distortion)}"
            raise FrameInputError(f"{camera.path}: cannot undistort with {model}: {error}") from error

    def __call__(self, files: FrameFiles, camera: Camera, pose: np.ndarray | None, folder: pathlib.Path) -> dict:
        """Process one frame into folder; returns its summary entry (ok False with error on failure)."""
        entry = {"frame": files.name, "ok": False, "error": "", "skipped": False}
        entry |= {"colour": [str(p) for p in files.colour], "depth": [str(p) for p in files.depth]}
        timings, start = {}, time.perf_counter()
        try:
            rgb, depth_m = load_frame(files, camera, self.settings.metres_per_depth_unit)
            rgb, depth_m = self.undistorted(rgb, depth_m, camera)
            timings["load"] = time.perf_counter() - start
            T_world_camera, pose_fields = camera_pose(depth_m, camera.K, pose)
            entry |= pose_fields | {"T_world_camera": np.round(T_world_camera, 6).tolist()}
            timings["pose"] = time.perf_counter() - start - sum(timings.values())
            segmentation = segment_detailed(rgb, depth_m, camera.K, T_world_camera, self.settings.segmentation)
            labels = segmentation.labels
            timings["segmentation"] = time.perf_counter() - start - sum(timings.values())
            objects = self.reconstructor(rgb, depth_m, camera.K, T_world_camera, labels)
            timings["reconstruction"] = time.perf_counter() - start - sum(timings.values())
            entry |= self._write(folder, files.name, rgb, labels, segmentation, objects)
            timings["export"] = time.perf_counter() - start - sum(timings.values())
        except FRAME_ERRORS as error:
            entry["error"] = str(error)
        except Exception as error:  # an unforeseen failure on one frame must not stop the others
            entry["error"] = f"unexpected {type(error).__name__}: {error}"
        else:
            entry["ok"] = True
        timings["total"] = time.perf_counter() - start
        entry["timings_s"] = {k: round(v, 4) for k, v in timings.items()}
        if entry["ok"]:
            entry["timings_s"]["reconstruction_stages"] = {
                k: round(v, 4) for k, v in self.reconstructor.last_timings_s.items()
            }
            atomic_write_json(folder / RESULT_FILE, entry, indent=1)
        return entry

    def _write(self, folder: pathlib.Path, name: str, rgb, labels, segmentation, objects) -> dict:
        for path in _own_files(folder):
            path.unlink()
        folder.mkdir(parents=True, exist_ok=True)
        cv2.imwrite(str(folder / OVERLAY_FILE), overlay(rgb, labels)[..., ::-1])
        cv2.imwrite(str(folder / LABELS_FILE), labels.astype(np.uint16))
        table_height_m, support_xy = table_support(objects, segmentation.levels)
        exported = {e.obj.id: e for e in exported_objects(objects)}
        xml, bodies = scene_mjcf(
            list(exported.values()), rgb, labels, segmentation.table_mask, table_height_m, support_xy, name
        )
        (folder / SCENE_FILE).write_text(xml)
        pixels = np.bincount(labels.ravel(), minlength=int(labels.max()) + 1)
        entries = []
        for obj in objects:
            done = exported.get(obj.id)
            files = write_object_meshes(done, folder, self.settings.mesh_format) if done is not None else {}
            count = int(pixels[obj.id]) if 0 <= obj.id < len(pixels) else 0
            entries.append(object_entry(obj, count, done, files, bodies.get(obj.id)))
        return {
            "table_height_m": round(table_height_m, 5),
            "n_segmented": len(objects),
            "empty_reason": segmentation.empty_reason,
            "n_reconstructed": sum(o.ok for o in objects),
            "overlay": OVERLAY_FILE,
            "labels": LABELS_FILE,
            "scene": SCENE_FILE,
            "objects": entries,
        }


def reconstruct_folder(
    input_dir: pathlib.Path,
    output_dir: pathlib.Path,
    settings: OfflineSettings,
    intrinsics_path: pathlib.Path | None = None,
    poses_path: pathlib.Path | None = None,
    progress: bool = False,
    reconstructor: Reconstructor | None = None,
) -> dict:
    """Process every frame of input_dir into output_dir; returns (and writes) the summary.
    reconstructor: a loaded network to reuse (default: one built from settings.reconstruction)."""
    processor = FrameReconstructor(settings, reconstructor)
    input_dir, output_dir = pathlib.Path(input_dir), pathlib.Path(output_dir)
    output_dir.mkdir(parents=True, exist_ok=True)
    summary = {"input": str(input_dir), "output": str(output_dir), "error": "", "frames": []}
    frames = find_frames(input_dir)
    try:
        camera = load_camera(intrinsics_path or find_intrinsics(input_dir))
        poses_path = poses_path or (input_dir / POSES_FILE if (input_dir / POSES_FILE).is_file() else None)
        poses = load_poses(poses_path) if poses_path else {}
    except FrameInputError as error:
        summary["error"] = str(error)
        _report(str(error))
        return _finish(summary, output_dir)
    if not frames:
        summary["error"] = f"no frames in {input_dir} (expected color/<frame>.png + depth/<frame>.png)"
        _report(summary["error"])
        return _finish(summary, output_dir)
    for files in tqdm(frames, desc="frames", unit="frame", disable=not progress, file=sys.stderr):
        folder = output_dir / files.name
        done = None if settings.overwrite else _completed(folder)
        if done is not None:
            entry = done | {"skipped": True}
        else:
            entry = processor(files, camera, poses.get(files.name), folder)
        if entry["error"]:
            _report(f"frame '{files.name}': {entry['error']}")
        summary["frames"].append(entry)
        _finish(summary, output_dir)
    return summary


def _report(message: str) -> None:
    tqdm.write(f"reconstruct_frames: {message}", file=sys.stderr)


def _finish(summary: dict, output_dir: pathlib.Path) -> dict:
    frames = summary["frames"]
    summary["n_frames"] = len(frames)
    summary["n_ok"] = sum(f["ok"] for f in frames)
    summary["n_skipped"] = sum(f["skipped"] for f in frames)
    summary["n_failed"] = len(frames) - summary["n_ok"]
    atomic_write_json(output_dir / SUMMARY_FILE, summary, indent=1)
    return summary


def parse_args(argv=None) -> argparse.Namespace:
    parser = argparse.ArgumentParser(
        prog="reconstruct_frames",
        description=__doc__.split("\n\n")[0] + "\n\n" + __doc__.split("\n\n")[2],
        epilog=inputs.__doc__.split("\n\n", 1)[1],
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    parser.add_argument("--input", type=pathlib.Path, required=True, metavar="DIR", help="frames (layout below)")
    parser.add_argument("--output", type=pathlib.Path, required=True, metavar="OUT", help="output folder")
    parser.add_argument("--depth-scale", type=float, default=0.001, metavar="S", help="metres per unit (0.001: mm)")
    parser.add_argument("--intrinsics", type=pathlib.Path, help="intrinsics.json or CameraInfo YAML")
    parser.add_argument("--poses", type=pathlib.Path, help=f"poses JSON (default: input/{POSES_FILE} if present)")
    parser.add_argument("--mesh-format", choices=MESH_FORMATS, default="ply")
    parser.add_argument("--method", default="arm", help="reconstruction method (arm_reconstruction.network.METHODS)")
    parser.add_argument("--checkpoint", default="", help="network checkpoint (default: the method's shipped one)")
    parser.add_argument("--device", default="cpu", help="cpu, cuda or auto")
    parser.add_argument("--overwrite", action="store_true", help="redo frames whose outputs exist")
    parser.add_argument("--no-progress", action="store_true", help="no progress bar")
    args = parser.parse_args(argv)
    if not args.input.is_dir():
        parser.error(f"input folder {args.input} does not exist")
    for path in (args.intrinsics, args.poses):
        if path is not None and not path.is_file():
            parser.error(f"{path} does not exist")
    args.parser = parser
    return args


def main(argv=None) -> int:
    args = parse_args(argv)
    try:
        reconstruction = ReconstructionSettings(method=args.method, checkpoint_path=args.checkpoint, device=args.device)
        settings = OfflineSettings(args.depth_scale, args.mesh_format, args.overwrite, reconstruction=reconstruction)
        reconstructor = Reconstructor(reconstruction)
    except (ValueError, CheckpointError) as error:
        args.parser.error(str(error))
    summary = reconstruct_folder(
        args.input, args.output, settings, args.intrinsics, args.poses, not args.no_progress, reconstructor
    )
    print(f"{summary['n_ok']}/{summary['n_frames']} frames reconstructed -> {args.output / SUMMARY_FILE}")
    return 0 if summary["n_ok"] > 0 else 1


if __name__ == "__main__":
    sys.exit(main())
