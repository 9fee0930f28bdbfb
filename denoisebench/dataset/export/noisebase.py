"""Export a dataset with per-sample data into Noisebase's sample-dataset format (PyPI ``noisebase`` 1.1.1).

Two layouts, as Noisebase's two loaders read them (``noisebase/loaders/torch/``):

* ``train`` (``TrainingSampleLoader_v1``): one Zarr group in a zip store per sequence,
  ``OUT/<split>/seq0000.zip``..., frames along the first axis, one uncompressed chunk per frame
  (written frame by frame: memory holds one frame)::

      color           uint8   F×4×H×W×S   per-sample radiance, RGBE (see below)
      exposure        float32 F×2         [min, max] log radiance of the frame's RGBE code
      reference       float32 F×3×H×W     the reference color
      position        float32 F×3×H×W×S   world-space first-hit position
      motion          float32 F×3×H×W×S   world-space motion: the point's previous position − position
      normal          float16 F×3×H×W×S   world-space shading normal at the first hit
      diffuse         float16 F×3×H×W×S   diffuse colour (our albedo) at the first non-delta hit
      camera_position, camera_target, camera_up   float32 F×3
      proj_mat        float32 F×4×4       projection (column vectors, DirectX depth)
      view_proj_mat   float32 F×4×4       view-projection, row vectors (what the test loader reads)
      crop_offset     int32   F×2         [0, 0]: the whole frame

* ``test`` (``TestSampleLoader_v1``): one zip store per frame, ``OUT/<split>/<scene>/frame0000.zip``,
  the same arrays without the frame axis. That loader crops rows ``28:-28`` unconditionally (its
  test frames are 1080 rows shown as 1024), so each frame is written with 28 rows of zeros above and
  below, and its projection is that of the taller frame: ``tan_y' = tan_y · (H + 56) / H``. Cropped
  by the loader, the image and the projection are ours; pass ``rendering_height = H + 56``.

Notes
-----
Conventions, taken from Noisebase's own code (``noisebase/projective.py``):

* Camera: ``forward = normalize(target − position)``, ``right = normalize(forward × up)``,
  ``up' = right × forward``; view coordinates are (right, up, forward). Our ``camera_pose`` (USD
  convention, looks down −Z) gives ``position`` = its translation, ``target = position − Z axis``,
  ``up`` = its Y axis.
* ``proj_mat`` maps view coordinates to clip space with column vectors:
  ``[[1/tan_x, 0, 0, 0], [0, 1/tan_y, 0, 0], [0, 0, f/(f−n), −n f/(f−n)], [0, 0, 1, 0]]``
  (``tan_x = tan(fov_x/2)``, ``tan_y = tan_x · H / W``, near 0.01 m, far 10 km: depth is unused by
  the loaders). Noisebase projects with ``pv = (P V)ᵀ`` on row vectors and maps NDC to pixels by
  ``x·W/2 + W/2``, ``−y·H/2 + H/2``: exactly our renderer's pinhole projection, so the motion the
  loader derives (``motion_vectors``: screen position in the previous frame minus the current one,
  in pixels, (row, column) order) is our ``motion`` buffer with its channels swapped.
* Background: a sample that misses every surface has position 0 (our convention), so the motion
  Noisebase derives there is that of the world origin; ours is that of the direction.
* ``motion`` (world space) is zero for static geometry; camera motion lives in the camera arrays.
  We store screen-space motion only, so a scene whose objects move cannot be exported: the export
  checks, per pixel, that reprojecting the positions with the two frames' cameras reproduces our
  motion buffer, and refuses the scene otherwise (one line, exit 2).
* RGBE (``noisebase.compression.decompress_RGBE``): a sample's colour is
  ``rgb / 255 · exp((e + 1) / 256 · (max − min) + min)`` with ``[min, max]`` the frame's
  ``exposure``, the range of log radiance over its positive values. We encode it ourselves,
  deterministically: ``e`` is the smallest code whose exponent is at least the sample's brightest
  channel, and ``rgb`` is rounded to the nearest level (Noisebase's own encoder dithers), so the
  decoded colour is within half a level, ``exponent / 510``, of ours. A frame with no positive
  value stores zeros and ``exposure = [0, 0]``.
* Depth of field: the lens offset of each sample is not in Noisebase's format; the position and
  colour of each sample are. Through a thin lens our motion buffer follows each sample's lens
  point, while Noisebase reprojects through the lens center: the two differ by the change of
  defocus between frames. Motion blur: our samples' time is not stored, and each sample's motion
  follows the camera at its own time. In both cases the object-motion check cannot run; such
  scenes are exported with zero world-space motion and listed as ``unchecked_object_motion`` in
  ``denoisebench_export.json`` (the command warns).
"""

from __future__ import annotations

import json
import math
import os
import zipfile
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from tqdm import tqdm

from denoisebench.dataset.atomic import atomic_write_bytes, temporary_path
from denoisebench.dataset.export.oidn import split_of
from denoisebench.dataset.manifest import SPLITS
from denoisebench.dataset.reader import Dataset
from denoisebench.errors import UserInputError

# Lazy imports: zarr is optional (only this export format needs it) and imported where the
# stores are written.

NEAR = 0.01
FAR = 1.0e4
TEST_PAD = 28  # rows TestSampleLoader_v1 crops from the top and the bottom
LAYOUTS = ("train", "test")
#: Largest |our motion − motion reprojected from positions| (pixels) at the 99th percentile of pixels
#: before a frame counts as having moving objects.
MOTION_TOLERANCE = 0.05


# --------------------------------------------------------------------------- RGBE


def encode_rgbe(color: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Per-sample radiance 3×…  -> (uint8 4×… RGBE code, float32 [min, max] exposure).

    Decoding (Noisebase's ``decompress_RGBE``) returns each channel within ``exponent / 510``.
    """
    color = np.maximum(np.asarray(color, dtype=np.float64), 0.0)
    positive = color[color > 0]
    if positive.size == 0:
        return np.zeros((4, *color.shape[1:]), np.uint8), np.zeros(2, np.float32)
    low, high = np.float32(np.log(positive.min())), np.float32(np.log(positive.max()))
    span = float(high) - float(low)
    brightest = color.max(axis=0)
    with np.errstate(divide="ignore"):
        log_b = np.where(brightest > 0, np.log(np.maximum(brightest, 1e-300)), -np.inf)
    if span > 0:
        code = np.ceil((log_b - float(low)) / span * 256.0 - 1.0)
    else:
        code = np.zeros_like(log_b)
    code = np.clip(np.nan_to_num(code, neginf=0.0), 0, 255)

    def exponent(e):
        # float32 arithmetic, as the decoder's
        e = e.astype(np.float32)
        return np.exp((e + np.float32(1)) / np.float32(256) * (high - low) + low)

    # float rounding may leave the exponent a hair under the brightest channel: step up
    short = (exponent(code) < brightest) & (code < 255)
    code = np.where(short, code + 1, code)
    exp = exponent(code).astype(np.float64)
    rgb = np.clip(np.rint(color / exp[None] * 255.0), 0, 255)
    rgb = np.where(brightest[None] > 0, rgb, 0)
    packed = np.concatenate([rgb, code[None]]).astype(np.uint8)
    return packed, np.array([low, high], np.float32)


def decode_rgbe(packed: np.ndarray, exposure: np.ndarray) -> np.ndarray:
    """Inverse of :func:`encode_rgbe`, in Noisebase's float32 arithmetic (for our own checks)."""
    e = (packed[3].astype(np.float32) + 1) / 256
    scale = np.exp(e * (exposure[1] - exposure[0]) + exposure[0])
    return packed[:3].astype(np.float32) / 255 * scale[None]


# --------------------------------------------------------------------------- camera


@dataclass(frozen=True)
class NoisebaseCamera:
    position: np.ndarray  # 3
    target: np.ndarray  # 3
    up: np.ndarray  # 3
    proj: np.ndarray  # 4×4, column vectors
    view_proj: np.ndarray  # 4×4, row vectors (Noisebase's pv)


def camera_arrays(pose, fov_x_deg: float, width: int, height: int, pad_rows: int = 0) -> NoisebaseCamera:
    """Noisebase's camera arrays for our ``camera_pose`` (USD camera-to-world, looks down −Z)."""
    pose = np.asarray(pose, dtype=np.float64)
    position = pose[:3, 3]
    axes = pose[:3, :3] / np.linalg.norm(pose[:3, :3], axis=0)
    forward = -axes[:, 2]
    up = axes[:, 1]
    tan_x = math.tan(math.radians(fov_x_deg) / 2.0)
    tan_y = tan_x * (height + 2 * pad_rows) / width
    proj = np.zeros((4, 4))
    proj[0, 0] = 1.0 / tan_x
    proj[1, 1] = 1.0 / tan_y
    proj[2, 2] = FAR / (FAR - NEAR)
    proj[2, 3] = -NEAR * FAR / (FAR - NEAR)
    proj[3, 2] = 1.0
    right = np.cross(forward, up)
    right /= np.linalg.norm(right)
    true_up = np.cross(right, forward)
    view = np.eye(4)
    view[:3, :3] = np.stack([right, true_up, forward])
    view[:3, 3] = -view[:3, :3] @ position
    return NoisebaseCamera(
        position=position.astype(np.float32),
        target=(position + forward).astype(np.float32),
        up=up.astype(np.float32),
        proj=proj.astype(np.float32),
        view_proj=(proj @ view).T.astype(np.float32),
    )


def project(points: np.ndarray, view_proj: np.ndarray, width: int, height: int) -> np.ndarray:
    """Pixel (x, y) of world points ``…×3`` under a row-vector view-projection (Noisebase's mapping)."""
    homogeneous = np.concatenate([points, np.ones_like(points[..., :1])], axis=-1).astype(np.float64)
    clip = homogeneous @ view_proj.astype(np.float64)
    w = np.where(clip[..., 3] != 0, clip[..., 3], 1.0)
    x = clip[..., 0] / w * 0.5 * width + 0.5 * width
    y = -clip[..., 1] / w * 0.5 * height + 0.5 * height
    return np.stack([x, y], axis=-1)


def check_static_geometry(
    scene: str, frame: int, samples_position, motion, cam, prev_cam, width, height, hit=None
) -> None:
    """UserInputError unless reprojected positions reproduce our motion buffer (no moving objects).

    ``hit`` (H×W bool): the pixels whose every sample hit a surface; only those are compared (a miss
    has position 0 by our convention, and its motion is that of the direction, not of a point).
    """
    if prev_cam is None:
        return
    now = project(samples_position, cam.view_proj, width, height)
    before = project(samples_position, prev_cam.view_proj, width, height)
    derived = np.mean(before - now, axis=0)  # mean over samples, H×W×2
    error = np.abs(derived - motion)
    finite = np.isfinite(error).all(axis=-1)
    if hit is not None:
        finite &= hit
    worst = float(np.percentile(error[finite].max(axis=-1), 99)) if finite.any() else math.inf
    if worst > MOTION_TOLERANCE:
        raise UserInputError(
            f"scene {scene!r} frame {frame}: its motion is not the camera's alone (reprojection differs by "
            f"{worst:.3g} px); Noisebase's world-space motion of moving objects cannot be derived from our "
            "screen-space motion: leave the scene out"
        )


# --------------------------------------------------------------------------- zarr


def write_zip_group(path: Path, arrays: dict[str, np.ndarray]) -> Path:
    """Write a Zarr (v2) group holding ``arrays`` as a zip store at ``path`` (temporary name, then rename).

    Each array is one uncompressed chunk (``compressor=None``, ``ZIP_STORED``): Noisebase reads whole
    frames, and the bytes are then the same for the same arrays.
    """
    import zarr

    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = temporary_path(path)
    store = zarr.ZipStore(str(tmp), mode="w", compression=zipfile.ZIP_STORED)
    try:
        group = zarr.group(store=store)
        for name in sorted(arrays):
            array = np.ascontiguousarray(arrays[name])
            group.create_dataset(name, data=array, chunks=array.shape, compressor=None)
        store.close()
        os.replace(tmp, path)
    except BaseException:
        store.close()
        tmp.unlink(missing_ok=True)
        raise
    return path


class SequenceZipWriter:
    """A sequence's zip store for the training layout, written one frame at a time.

    Each array is ``F×…`` with one uncompressed chunk per frame (``chunks=(1, …)``), so memory holds
    one frame whatever the sequence length, and Noisebase's ``ds[name][frame_idx]`` reads one chunk.
    Written under a temporary name and renamed by :meth:`close`; :meth:`abort` removes it.
    """

    def __init__(self, path: Path, frames: int):
        import zarr

        self.path, self.frames = path, int(frames)
        path.parent.mkdir(parents=True, exist_ok=True)
        self.tmp = temporary_path(path)
        self.store = zarr.ZipStore(str(self.tmp), mode="w", compression=zipfile.ZIP_STORED)
        self.group = zarr.group(store=self.store)

    def add(self, index: int, arrays: dict[str, np.ndarray]) -> None:
        for name in sorted(arrays):
            array = np.ascontiguousarray(arrays[name])
            if name not in self.group:
                self.group.create_dataset(
                    name,
                    shape=(self.frames, *array.shape),
                    chunks=(1, *array.shape),
                    dtype=array.dtype,
                    compressor=None,
                )
            self.group[name][index] = array

    def close(self) -> Path:
        self.store.close()
        os.replace(self.tmp, self.path)
        return self.path

    def abort(self) -> None:
        self.store.close()
        self.tmp.unlink(missing_ok=True)


def static_check_applies(info) -> bool:
    """The object-motion check needs a pinhole at the frame's time: through a thin lens our motion follows
    each sample's lens point (Noisebase reprojects through the lens center: they differ by the change of
    defocus), and with time sampling each sample's own camera pose (Noisebase uses the frame's)."""
    plan = info.plan
    return plan.get("camera_model", "pinhole") == "pinhole" and not plan.get("time_sampling", False)


def _frame_arrays(dataset: Dataset, scene: str, spp: int, index: int, pad: int, prev_cam):
    info = dataset.scene(scene)
    loaded = dataset.frame(scene, spp, index, reference=info.has_reference, samples=True)
    samples = loaded.samples
    record = info.record["renders"][f"spp{spp:04d}"][f"{index:04d}"]
    pose = record.get("camera_pose")
    if pose is None:
        raise UserInputError(f"scene {scene!r} frame {index} has no camera_pose in the manifest (not rendered?)")
    cam = camera_arrays(pose, float(info.camera["fov_x_deg"]), info.width, info.height, pad)
    flat_cam = cam if pad == 0 else camera_arrays(pose, float(info.camera["fov_x_deg"]), info.width, info.height)
    if static_check_applies(info):
        hit = (samples["depth"][..., 0] > 0).all(axis=0) if "depth" in samples else None
        check_static_geometry(
            scene,
            index,
            samples["position"],
            loaded.buffers["motion"],
            flat_cam,
            prev_cam,
            info.width,
            info.height,
            hit,
        )

    def per_sample(name, dtype):
        return np.transpose(samples[name], (3, 1, 2, 0)).astype(dtype)  # S×H×W×C -> C×H×W×S

    color = per_sample("color", np.float32)
    rgbe, exposure = encode_rgbe(color)
    position = per_sample("position", np.float32)
    arrays = {
        "color": rgbe,
        "exposure": exposure,
        "position": position,
        "motion": np.zeros_like(position),
        "normal": per_sample("normal", np.float16),
        "diffuse": per_sample("albedo", np.float16),
        "camera_position": cam.position,
        "camera_target": cam.target,
        "camera_up": cam.up,
        "proj_mat": cam.proj,
        "view_proj_mat": cam.view_proj,
        "crop_offset": np.zeros(2, np.int32),
    }
    if loaded.reference is not None:
        arrays["reference"] = np.transpose(loaded.reference, (2, 0, 1)).astype(np.float32)
    if pad:
        for name in ("color", "position", "motion", "normal", "diffuse", "reference"):
            if name in arrays:
                widths = [(0, 0)] * arrays[name].ndim
                widths[1] = (pad, pad)
                arrays[name] = np.pad(arrays[name], widths)
    return arrays, flat_cam


def _samples_spp(dataset: Dataset, scene: str, spp: int | None) -> int:
    info = dataset.scene(scene)
    with_samples = [
        s
        for s in info.spp
        if all(rec.get("samples") for rec in info.record.get("renders", {}).get(f"spp{s:04d}", {}).values())
        and info.record.get("renders", {}).get(f"spp{s:04d}")
    ]
    if not with_samples:
        raise UserInputError(
            f"scene {scene!r} has no per-sample data, which Noisebase's format needs: generate with --samples"
        )
    if spp is None:
        return max(with_samples)
    if spp not in with_samples:
        raise UserInputError(f"scene {scene!r} has per-sample data at spp {with_samples}, not --spp {spp}")
    return spp


def plan_export(dataset: Dataset, spp: int | None, layout: str) -> dict[str, list[tuple[str, int]]]:
    """Split -> [(scene, spp)], checked before anything is written (UserInputError)."""
    if layout not in LAYOUTS:
        raise UserInputError(f"--layout must be one of {', '.join(LAYOUTS)} (got {layout!r})")
    if not dataset.scenes:
        raise UserInputError(f"{dataset.root}: the dataset has no scenes")
    splits = split_of(dataset)
    plan: dict[str, list[tuple[str, int]]] = {}
    for scene in dataset.scenes:
        info = dataset.scene(scene)
        if not info.has_reference:
            raise UserInputError(f"scene {scene!r} has no reference; Noisebase's format needs one")
        chosen = _samples_spp(dataset, scene, spp)
        if "fov_x_deg" not in info.camera:
            raise UserInputError(f"scene {scene!r} has no camera field of view in the manifest")
        if info.camera.get("projection", "perspective") != "perspective":
            raise UserInputError(
                f"scene {scene!r} has an {info.camera['projection']} camera; Noisebase's format holds perspective ones"
            )
        plan.setdefault(splits[scene], []).append((scene, chosen))
    if layout == "train":
        for split, entries in plan.items():
            shapes = {
                (dataset.scene(s).frame_count, dataset.scene(s).height, dataset.scene(s).width, n) for s, n in entries
            }
            if len(shapes) > 1:
                raise UserInputError(
                    f"split {split}: Noisebase's training loader needs one frame count, size and spp per dataset, "
                    f"got (frames, height, width, spp) {sorted(shapes)}; use --layout test or export scenes alike"
                )
    return plan


def export_noisebase(
    dataset: Dataset, out: Path, spp: int | None = None, layout: str = "train", progress: bool = True
) -> dict:
    """Write the Noisebase layout of ``dataset`` into the (empty, staging) folder ``out``; return a summary.

    Call :func:`plan_export` first to refuse bad input before writing (the command does).
    """
    plan = plan_export(dataset, spp, layout)
    pad = TEST_PAD if layout == "test" else 0
    total = sum(dataset.scene(s).frame_count for entries in plan.values() for s, _ in entries)
    bar = tqdm(total=total, desc=f"export noisebase ({layout})", unit="frame", disable=not progress)
    sources: dict[str, dict] = {}
    try:
        for split in SPLITS:
            entries = plan.get(split, [])
            for number, (scene, scene_spp) in enumerate(entries):
                info = dataset.scene(scene)
                prev_cam = None
                sequence = None
                if layout == "train":
                    sequence = SequenceZipWriter(out / split / f"seq{number:04d}.zip", info.frame_count)
                try:
                    for index in range(info.frame_count):
                        arrays, prev_cam = _frame_arrays(dataset, scene, scene_spp, index, pad, prev_cam)
                        if sequence is None:
                            write_zip_group(out / split / scene / f"frame{index:04d}.zip", arrays)
                        else:
                            sequence.add(index, arrays)
                        bar.update(1)
                except BaseException:
                    if sequence is not None:
                        sequence.abort()
                    raise
                if sequence is not None:
                    sequence.close()
            if entries:
                first = dataset.scene(entries[0][0])
                src = {
                    "samples": entries[0][1],
                    "rendering_height": first.height + 2 * pad,
                    "rendering_width": first.width,
                }
                if layout == "train":
                    src.update(
                        files=f"{split}/seq{{index:04d}}.zip",
                        sequences=len(entries),
                        frames_per_sequence=first.frame_count,
                        crop=min(first.height, first.width),
                    )
                    src["scenes"] = [scene for scene, _ in entries]
                else:
                    src.update(
                        files=f"{split}/{{sequence_name}}/frame{{index:04d}}.zip",
                        sequences=[{"name": s, "frames": dataset.scene(s).frame_count} for s, _ in entries],
                    )
                sources[split] = src
    finally:
        bar.close()
    unchecked = [s for entries in plan.values() for s, _ in entries if not static_check_applies(dataset.scene(s))]
    summary = {
        "format": "noisebase",
        "layout": layout,
        "unchecked_object_motion": unchecked,
        "source": str(dataset.root.resolve()),
        "config_hash": dataset.config_hash,
        "src": sources,
        "data_path": "OUT (pass data_path=<this folder> to the loader)",
    }
    atomic_write_bytes(out / "denoisebench_export.json", (json.dumps(summary, indent=2) + "\n").encode())
    return summary
