"""The headline sections of ``make bench``: data sr3d was not built on.

- ``realdata``: ../shared/realdata (real D4xx frames, painted-object or CAD ground truth), the
  whole default ``repair-depth`` from the raw frame, no masks given: segmentation against the
  true objects, invented depth off the objects, object depth beside raw depth and OpenCV
  inpainting given the true masks, seconds per frame on one core, the pose error of the placed
  objects where the frames give true poses (Tracebot), the peak memory of one
  ``sr3d repair-depth`` worker over the frames, and segmentation on the same frames with a
  white cloth that returns no readings under their objects (a simulated dropout) and, on the
  one-object frames, with the object copied beside itself (two alike side by side), and with
  the colour as another exposure or a noisier sensor gives it (toned), with the depth rounded
  to millimetres as a camera writing 16-bit depth stores it (stored), and cropped so that the
  image's border cuts an object (border_cut); the whole pipeline also runs on the frames moved
  by one pixel (moved).
- ``extsim``: ../shared/extsim (an independent renderer, scanned household meshes), the same
  pipeline plus the pose error and grasps judged on the true meshes, and the whole pipeline on
  the frames resampled to a narrower stream of the same field of view (narrower).
"""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
import time
from pathlib import Path

import cv2
import numpy as np

from sr3d_cli import stages
from sr3d_cli.config import Config, IOConfig
from sr3d_cli.evaluate import depth_metrics, instance_ious, mean_metrics
from sr3d_cli.io.formats import discover_scenes
from sr3d_cli.io.images import write_depth
from sr3d_cli.pipeline import Pipeline
from sr3d_cli.pose_error import MATCH_IOU, evaluate_frame_poses, summarise
from sr3d_cli.repair import inpaint_fill, plane_fill
from sr3d_cli.segment import Segmenter

from common import SHARED, grasp_planners, one_core, staged, timed_repair

DETECTED_IOU = 0.5  # a true object is found when an instance overlaps it this well
GRASP_DRAWS = 8  # extsim grasps: the random draws of seed points (grasp.seed 0, 1, ...) averaged
FALSE_IOU, FALSE_AREA = 0.2, 300  # an instance this large overlapping no object this well
INVENTED_REACH, INVENTED_CHANGE = 15, 0.01  # px from every object; metres of change
STAGES = ("segment", "reconstruct", "align", "render", "total")
CLOTH_REACH = (150, 100, 80)  # px at 1280 wide: the cloth beside, above and below the objects
CLOTH_WHITE = 0.35  # share of each pixel's distance to white kept under the cloth
PAIR_GAPS = (40, 100)  # px at 1280 wide between a one-object frame's object and its copy
PAIR_BAND = 15  # px at 1280 wide around the object copied with it (its holes, its shadow)
SHIFTS = ((0, 1), (1, 0), (1, 1))  # (down, right) px: the frame moved by a pixel (shifted)
MOVES = ((0, 1), (1, 0))  # (down, right) px: the moves the whole pipeline is run on (moved)
VGA = (640, 480)  # (width, height) px: the size the real frames are also resampled to (resampled)
NARROW_WIDTH = 640  # px: the width extsim's 848 px frames are also resampled to (narrower)
BORDER_SHARE = 0.25  # share of an object's height (foot) or width (side) a border-cut crop drops
BORDER_SIDES = ("foot", "side")  # where border_cut cuts: an object's foot or its left side
STORED_STEP = 0.001  # m: the step of a RealSense's 16-bit depth at its default scale (millimetres)
TONES = {  # the colour as another camera or light gives it (toned): how, in words for reports
    "darker": "every value times 0.55 (a shorter exposure)",
    "paler": "every value's distance to white times 0.6 (a longer exposure, less contrast)",
    "noisier": "Gaussian noise of 2% of the range added to each value (a dimmer room)",
}


def segmentation_scores(pred: np.ndarray, truth: np.ndarray) -> dict:
    """Each true object's best IoU ``{id: iou}`` with a predicted instance, and the predicted
    instances of at least :data:`FALSE_AREA` px whose IoU with every true object is below
    :data:`FALSE_IOU`. pred, truth : (H, W) int instance ids, 0 = background."""
    best = instance_ious(pred, truth)
    against_truth = instance_ious(truth, pred)  # each instance's best IoU with a true object
    false = sum(1 for b, iou in against_truth.items()
                if iou < FALSE_IOU and (pred == b).sum() >= FALSE_AREA)
    return {"best_iou": best, "false": false}


def invented_share(repaired: np.ndarray, raw: np.ndarray, truth: np.ndarray) -> float:
    """Share of the frame's pixels farther than :data:`INVENTED_REACH` px from every true object
    where the repaired depth differs from the raw by more than :data:`INVENTED_CHANGE` m."""
    far = cv2.distanceTransform((truth == 0).astype(np.uint8), cv2.DIST_L2, 3) > INVENTED_REACH
    changed = np.abs(repaired.astype(np.float64) - raw.astype(np.float64)) > INVENTED_CHANGE
    return float((far & changed).sum() / truth.size)


def frame_poses(scene, fid: str) -> list[dict]:
    """Pose error rows (:func:`~sr3d_cli.pose_error.evaluate_frame_poses`) of a frame's true
    objects; a true object counts as not placed where the pipeline placed nothing. Empty where
    the frame gives no true poses (ClearGrasp)."""
    truth = scene.load_gt_objects(fid)
    if not truth or not truth.get("objects"):
        return []
    found = evaluate_frame_poses(scene, fid)
    if found is None:
        return [{"id": int(o["id"]), "label": o.get("label", ""), "pred_id": None}
                for o in truth["objects"]]
    return found["objects"]


def peak_memory_mib(root: Path, out: Path) -> float:
    """Peak resident memory (MiB) of one ``sr3d repair-depth --workers 1`` process (a batch
    worker) run on every frame below ``root``, outputs written to ``out`` (emptied first)."""
    shutil.rmtree(out, ignore_errors=True)
    sr3d = Path(sys.executable).with_name("sr3d")
    proc = subprocess.Popen([str(sr3d), "repair-depth", str(root), "--out", str(out),
                             "--workers", "1", "-q"])
    _, status, usage = os.wait4(proc.pid, 0)
    code = os.waitstatus_to_exitcode(status)
    if code != 0:
        raise RuntimeError(f"sr3d repair-depth {root} failed (exit code {code})")
    return usage.ru_maxrss / 1024  # KiB on Linux


def under_white_cloth(rgb: np.ndarray, depth: np.ndarray, truth: np.ndarray
                      ) -> tuple[np.ndarray, np.ndarray]:
    """The frame with a white cloth that returns no readings laid under its true objects: over
    their box widened by :data:`CLOTH_REACH`, every reading but the objects' own is dropped and
    every pixel moved towards white (:data:`CLOTH_WHITE`; a glass shows the cloth through
    itself, its edges and highlights kept). rgb (H, W, 3) uint8, depth (H, W) metres, truth
    (H, W) int ids; returns the new rgb and depth."""
    ys, xs = np.nonzero(truth > 0)
    s = truth.shape[1] / 1280
    side, above, below = (int(round(r * s)) for r in CLOTH_REACH)
    cloth = np.zeros(truth.shape, bool)
    cloth[max(ys.min() - above, 0):ys.max() + below + 1,
          max(xs.min() - side, 0):xs.max() + side + 1] = True
    out = rgb.astype(np.float32)
    out[cloth] = 255 - (255 - out[cloth]) * CLOTH_WHITE
    return out.astype(np.uint8), np.where(cloth & (truth == 0), 0.0, depth)


def segment_modified(root: Path, cfg: Config, make, label: str) -> dict:
    """Segmentation alone (the default segmenter) on every frame below ``root`` as ``make``
    changes it: ``make(frame, truth)`` returns (rgb, depth, true ids), with the frame's K
    (3, 3) after them where it changes too, or None to skip the frame. Totals as
    :func:`segmentation_scores` counts them: frames, objects, detection, mean best IoU, false
    instances per frame."""
    segmenter = Segmenter(cfg.segment, cfg.plane)
    ious, false = [], []
    for scene in discover_scenes(root, IOConfig(), None):
        for fid in scene.frame_ids():
            frame = scene.load_frame(fid)
            made = make(frame, scene.load_mask(scene.gt_mask_path(fid), frame.depth_m.shape))
            if made is None:
                continue
            rgb, depth, truth, *K = made
            K = K[0] if K else frame.camera.K
            seg = segmentation_scores(segmenter(fid, rgb, depth, K).ids, truth)
            ious += list(seg["best_iou"].values())
            false.append(seg["false"])
            print(scene.frame_key(fid), f"{label}: IoU",
                  [round(v, 2) for v in seg["best_iou"].values()], "false", seg["false"],
                  file=sys.stderr)
    if not ious:
        return {}
    return {"frames": len(false), "objects": len(ious),
            "detection": float(np.mean([v >= DETECTED_IOU for v in ious])),
            "mean_iou": float(np.mean(ious)), "false_per_frame": float(np.mean(false))}


def cloth_scores(root: Path, cfg: Config) -> dict:
    """:func:`segment_modified` on every frame below ``root`` laid on a white cloth
    (:func:`under_white_cloth`)."""
    return segment_modified(root, cfg, lambda frame, truth: (
        *under_white_cloth(frame.rgb, frame.depth_m, truth), truth), "on a white cloth")


def beside_itself(rgb: np.ndarray, depth: np.ndarray, truth: np.ndarray, gap: int
                  ) -> tuple[np.ndarray, np.ndarray, np.ndarray] | None:
    """The frame with its one true object copied beside itself, ``gap`` px (at 1280 wide) to
    its right: the colour of the object and of the :data:`PAIR_BAND` around it, and the
    readings of the object and the band's missing ones (its holes and stereo shadow; the
    table's readings there stay). rgb (H, W, 3) uint8, depth (H, W) metres, truth (H, W) ids;
    returns rgb, depth and the ids (1: the object, 2: the copy), or None where the copy would
    leave the frame."""
    s = truth.shape[1] / 1280
    obj = truth > 0
    xs = np.nonzero(obj.any(axis=0))[0]
    shift = int(xs[-1] - xs[0] + 1 + round(gap * s))
    band = 2 * int(round(PAIR_BAND * s)) + 1
    zy, zx = np.nonzero(cv2.dilate(obj.astype(np.uint8), np.ones((band, band), np.uint8)))
    if zx.max() + shift >= truth.shape[1]:
        return None
    rgb, out, ids = rgb.copy(), depth.copy(), obj.astype(np.int32)
    rgb[zy, zx + shift] = rgb[zy, zx]
    own = obj[zy, zx] | (depth[zy, zx] <= 0)
    out[zy[own], zx[own] + shift] = depth[zy[own], zx[own]]
    oy, ox = np.nonzero(obj)
    ids[oy, ox + shift] = 2
    return rgb, out, ids


def shifted(rgb: np.ndarray, depth: np.ndarray, truth: np.ndarray, K: np.ndarray,
            down: int, right: int) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """The frame's content moved ``down`` and ``right`` pixels, the first rows and columns
    repeated into the gap, and K (3, 3) with its principal point moved with it. rgb (H, W, 3)
    uint8, depth (H, W) metres, truth (H, W) ids. The segmenter reduces a 1280 px frame by
    keeping one reading in each 2x2 block: moved by a pixel, the frame keeps another of the
    four, an equally likely view of the same scene."""
    K = np.array(K, dtype=np.float64)
    K[0, 2] += right
    K[1, 2] += down
    return tuple(moved_image(a, down, right) for a in (rgb, depth, truth)) + (K,)


def moved_image(a: np.ndarray, down: int, right: int) -> np.ndarray:
    """The image ``a`` (H, W, ...) moved ``down`` and ``right`` pixels, its first rows and
    columns repeated into the gap (:func:`shifted`)."""
    pad = ((down, 0), (right, 0)) + ((0, 0),) * (a.ndim - 2)
    return np.pad(a, pad, mode="edge")[:a.shape[0], :a.shape[1]]


def shift_scores(root: Path, cfg: Config) -> dict:
    """:func:`segment_modified` on every frame below ``root`` moved by each of :data:`SHIFTS`
    (:func:`shifted`): ``{"down,right": totals}``."""
    def shift(down: int, right: int):
        return lambda frame, truth: shifted(frame.rgb, frame.depth_m, truth, frame.camera.K,
                                            down, right)

    found = {f"{d},{r}": segment_modified(root, cfg, shift(d, r), f"moved {d},{r} px")
             for d, r in SHIFTS}
    return {key: totals for key, totals in found.items() if totals}


def resampled(rgb: np.ndarray, depth: np.ndarray, truth: np.ndarray, K: np.ndarray,
              size: tuple[int, int] = VGA
              ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """The frame's central crop of the aspect of ``size`` (width, height) resampled to it: the
    colour averaged over each new pixel's area, the depth and the ids taken from the nearest
    pixel (a reading is never blended across an object's edge), K (3, 3) cropped and scaled
    with them, pixel centres kept. rgb (H, W, 3) uint8, depth (H, W) metres, truth (H, W) ids.
    A 1280x720 frame's segmenter works on a 640x360 half; a 640x480 frame is worked on whole,
    at 1.33 times the scale."""
    w, h = size
    height, width = truth.shape
    crop = int(round(height * w / h))
    x0 = (width - crop) // 2
    scale = w / crop
    K = np.array(K, dtype=np.float64)
    K[0, 2] -= x0
    K[:2] *= scale
    K[:2, 2] += 0.5 * scale - 0.5
    return (cv2.resize(rgb[:, x0:x0 + crop], size, interpolation=cv2.INTER_AREA),
            cv2.resize(depth[:, x0:x0 + crop], size, interpolation=cv2.INTER_NEAREST),
            cv2.resize(truth[:, x0:x0 + crop].astype(np.uint16), size,
                       interpolation=cv2.INTER_NEAREST).astype(np.int32), K)


def narrower(rgb: np.ndarray, depth: np.ndarray, truth: np.ndarray, camera,
             width: int = NARROW_WIDTH
             ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """The whole frame resampled to ``width`` px across, its aspect kept: the view of a camera
    with the same field of view streaming fewer pixels, every object ``width / W`` times as many
    pixels across. The colour averaged over each new pixel's area, the depth and the ids taken
    from the nearest pixel (as :func:`resampled`). rgb (H, W, 3) uint8, depth (H, W) metres,
    truth (H, W) ids, ``camera``: the frame's :class:`~sr3d_cli.geometry.camera.Camera`;
    returns them resampled, with K (3, 3) for the new size."""
    height, full = truth.shape
    size = (width, int(round(height * width / full)))
    return (cv2.resize(rgb, size, interpolation=cv2.INTER_AREA),
            cv2.resize(depth, size, interpolation=cv2.INTER_NEAREST),
            cv2.resize(truth.astype(np.uint16), size,
                       interpolation=cv2.INTER_NEAREST).astype(np.int32),
            camera.scaled(*size).K)


def toned(rgb: np.ndarray, tone: str) -> np.ndarray:
    """``rgb (H, W, 3) uint8`` as :data:`TONES` names ``tone`` changes it (the noise drawn
    with a fixed seed), uint8."""
    x = rgb.astype(np.float32) / 255.0
    if tone == "darker":
        x = x * 0.55
    elif tone == "paler":
        x = 1.0 - (1.0 - x) * 0.6
    elif tone == "noisier":
        x = x + np.random.default_rng(0).normal(0.0, 0.02, x.shape)
    else:
        raise ValueError(f"tone {tone!r}: one of {', '.join(TONES)}")
    return np.clip(x * 255.0 + 0.5, 0, 255).astype(np.uint8)


def tone_scores(root: Path, cfg: Config) -> dict:
    """:func:`segment_modified` on every frame below ``root`` with its colour changed by each
    of :data:`TONES` (:func:`toned`), the depth as it is: ``{tone: totals}``."""
    return {tone: segment_modified(root, cfg, lambda frame, truth, tone=tone: (
        toned(frame.rgb, tone), frame.depth_m, truth), tone) for tone in TONES}


def in_steps(depth: np.ndarray, step: float = STORED_STEP) -> np.ndarray:
    """Depth ``(H, W)`` metres rounded to ``step`` metres, as a camera writing 16-bit depth
    stores it (0 stays 0): ClearGrasp's frames are kept as float EXR, finer than that."""
    return (np.round(depth / step) * step).astype(np.float32)


def stored_scores(root: Path, cfg: Config) -> dict:
    """:func:`segment_modified` on every frame below ``root`` with its depth rounded to
    :data:`STORED_STEP` (:func:`in_steps`), the colour as it is."""
    return segment_modified(root, cfg, lambda frame, truth: (
        frame.rgb, in_steps(frame.depth_m), truth), "depth in millimetres")


def resampled_scores(root: Path, cfg: Config) -> dict:
    """:func:`segment_modified` on every frame below ``root`` resampled to :data:`VGA`
    (:func:`resampled`)."""
    return segment_modified(root, cfg, lambda frame, truth: resampled(
        frame.rgb, frame.depth_m, truth, frame.camera.K), f"resampled to {VGA[0]}x{VGA[1]}")


def pair_scores(root: Path, cfg: Config) -> dict:
    """:func:`segment_modified` on every one-object frame below ``root`` with its object
    copied beside itself (:func:`beside_itself`), at each of :data:`PAIR_GAPS`:
    ``{gap: totals}``."""
    def pair(gap: int):
        def make(frame, truth):
            if len(np.unique(truth[truth > 0])) != 1:
                return None
            return beside_itself(frame.rgb, frame.depth_m, truth, gap)
        return make

    found = {str(gap): segment_modified(root, cfg, pair(gap), f"beside itself {gap} px")
             for gap in PAIR_GAPS}
    return {gap: totals for gap, totals in found.items() if totals}


def run_set(root: Path, work: Path, cfg: Config, grasps: bool = False) -> dict:
    """The whole default pipeline on every frame below ``root`` (its ground truth never read
    by the pipeline); numbers as described in the module docstring. ``work`` is emptied first:
    every stage runs, and is timed, on the current code."""
    shutil.rmtree(work, ignore_errors=True)
    rows = {m: [] for m in ("raw", "plane-fill", "inpaint", "sr3d")}
    ious, false, invented, timings, frames, poses = [], [], [], [], [], []
    drawn = grasp_planners(cfg.grasp, GRASP_DRAWS) if grasps else []
    judged = [[] for _ in drawn]  # per draw, per frame
    Pipeline(cfg).renderer  # its libraries load once per process, as in a batch: not a frame's
    for source in discover_scenes(root, IOConfig(), None):
        scene = staged(source, work / source.name)
        for fid in scene.frame_ids():
            frame = scene.load_frame(fid)
            truth = scene.load_mask(scene.gt_mask_path(fid), frame.depth_m.shape)
            gt = scene.load_gt_depth(fid, frame.depth_m.shape)
            pipe, t = Pipeline(cfg), {}
            with one_core():
                start = time.perf_counter()
                try:
                    depth, ids = timed_repair(pipe, frame, t)
                except Exception as exc:  # a frame the pipeline fails on counts as raw depth
                    print(f"{scene.frame_key(fid)}: failed: {exc}", file=sys.stderr)
                    depth, ids = frame.depth_m, np.zeros(frame.depth_m.shape, np.int32)
                t["total"] = time.perf_counter() - start
            timings.append(t)
            pred, _ = stages.load_instances(scene, fid, frame.depth_m.shape) \
                if scene.stage_file("masks", fid, (".png",)) else (ids, {})
            seg = segmentation_scores(pred, truth)
            ious += list(seg["best_iou"].values())
            false.append(seg["false"])
            invented.append(invented_share(depth, frame.depth_m, truth))
            mask = truth > 0
            plane, _ = stages.frame_plane(frame, truth, cfg.plane)
            preds = {"raw": frame.depth_m, "sr3d": depth,
                     "plane-fill": plane_fill(frame.depth_m, mask, plane, frame.camera.K)
                     if plane is not None else frame.depth_m,
                     "inpaint": inpaint_fill(frame.depth_m, mask)}
            for m, p in preds.items():
                rows[m].append(depth_metrics(p, gt, mask))
            if drawn:
                write_depth(scene.output_path("repaired", fid), depth, frame.camera.depth_scale)
                for draw, planner in enumerate(drawn):
                    with one_core():
                        t0 = time.perf_counter()
                        stages.grasp_frame(frame, planner, cfg.plane, "repaired")
                        if draw == 0:
                            t["grasp"] = time.perf_counter() - t0
                    judged[draw].append(stages.evaluate_grasp_frame(scene, fid, cfg))
            poses += frame_poses(scene, fid)
            frames.append(scene.frame_key(fid))
            print(scene.frame_key(fid), "IoU", [round(v, 2) for v in seg["best_iou"].values()],
                  "false", seg["false"], f"inv {invented[-1]*100:.2f}%", f"sr3d {rows['sr3d'][-1]['mae'] * 1000:.1f} mm",
                  f"raw {rows['raw'][-1]['mae'] * 1000:.1f} mm", f"{t['total']:.1f} s",
                  file=sys.stderr)
    out = {"frames": len(frames), "objects": len(ious),
           "detection": float(np.mean([v >= DETECTED_IOU for v in ious])) if ious else 0.0,
           "mean_iou": float(np.mean(ious)) if ious else 0.0,
           "false_per_frame": float(np.mean(false)), "invented_share": float(np.mean(invented)),
           "depth": {m: mean_metrics(r) for m, r in rows.items()},
           "median_mae": {m: float(np.median([x["mae"] for x in r])) for m, r in rows.items()},
           "seconds": {k: float(np.median([t[k] for t in timings if k in t]))
                       for k in (*STAGES, "grasp") if any(k in t for t in timings)},
           "max_seconds": float(max(t["total"] for t in timings))}
    if poses:
        out["pose"] = summarise(poses)
    if drawn:
        from sr3d_cli.grasp.quality import overall

        draws = [overall(frames_judged) for frames_judged in judged]
        out["grasp"] = {k: float(np.mean([g[k] for g in draws]))
                        for k in ("objects", "objects_with_grasps", "top1_success",
                                  "top10_success")}
        out["grasp"]["top1_by_draw"] = [g["top1_success"] for g in draws]
    return out


def border_cut(truth: np.ndarray, side: str) -> tuple[slice, slice] | None:
    """The window (rows, columns) of a frame with true ids ``truth (H, W)`` whose border cuts
    :data:`BORDER_SHARE` off one object: its lowest object's foot (``side`` "foot": the rows
    above) or its leftmost object's left side ("side": the columns right of it). None for a
    frame with no object."""
    ids = [k for k in np.unique(truth) if k > 0]
    if not ids:
        return None
    axis = 1 if side == "foot" else 0
    spans = {k: np.nonzero((truth == k).any(axis=axis))[0] for k in ids}
    if side == "foot":
        span = spans[max(ids, key=lambda k: spans[k][-1])]
        return slice(0, int(span[-1] - BORDER_SHARE * (span[-1] - span[0]))), slice(None)
    span = spans[min(ids, key=lambda k: spans[k][0])]
    return slice(None), slice(int(span[0] + BORDER_SHARE * (span[-1] - span[0])), None)


def write_frames(root: Path, out: Path, make) -> Path:
    """Every frame below ``root`` as ``make(frame, truth, true depth)`` changes it, written to
    ``out`` (emptied first) as a scene of sr3d's native layout each: colour, depth, camera,
    true ids and depth. ``make`` returns (rgb (H, W, 3) uint8, depth (H, W) metres, true ids
    (H, W), true depth (H, W) metres, K (3, 3)), or None to leave the frame out. Depths are
    written as float metres (``.npy``): the change is all that differs, not even the depth's
    step (see :func:`stored_scores`). Returns ``out``."""
    import json

    shutil.rmtree(out, ignore_errors=True)
    for source in discover_scenes(root, IOConfig(), None):
        for fid in source.frame_ids():
            frame = source.load_frame(fid)
            truth = source.load_mask(source.gt_mask_path(fid), frame.depth_m.shape)
            made = make(frame, truth, source.load_gt_depth(fid, truth.shape))
            if made is None:
                continue
            rgb, depth, ids, gt, K = made
            folder = out / source.frame_key(fid).replace("/", "_")
            for sub in ("rgb", "depth", "gt/masks", "gt/depth"):
                (folder / sub).mkdir(parents=True, exist_ok=True)
            h, w = ids.shape
            scale = frame.camera.depth_scale
            (folder / "camera.json").write_text(json.dumps(
                {"K": np.asarray(K, dtype=np.float64).tolist(), "depth_scale": scale,
                 "height": h, "width": w}))
            cv2.imwrite(str(folder / "rgb" / "000000.png"),
                        cv2.cvtColor(np.ascontiguousarray(rgb), cv2.COLOR_RGB2BGR))
            write_depth(folder / "depth" / "000000.npy", depth, scale)
            cv2.imwrite(str(folder / "gt" / "masks" / "000000.png"),
                        np.ascontiguousarray(ids).astype(np.uint16))
            write_depth(folder / "gt" / "depth" / "000000.npy", gt, scale)
    return out


def write_border_cuts(root: Path, out: Path, side: str) -> Path:
    """:func:`write_frames` with every frame cropped to its :func:`border_cut` window (K moved
    with the crop)."""
    def crop(frame, truth, gt):
        window = border_cut(truth, side)
        if window is None:
            return None
        rows, cols = window
        K = np.array(frame.camera.K, dtype=np.float64)
        K[0, 2] -= cols.start or 0
        K[1, 2] -= rows.start or 0
        return frame.rgb[window], frame.depth_m[window], truth[window], gt[window], K

    return write_frames(root, out, crop)


def border_cut_scores(root: Path, work: Path, cfg: Config) -> dict:
    """:func:`run_set` on the frames below ``root`` cropped by :func:`write_border_cuts`, for
    each of :data:`BORDER_SIDES`."""
    return {side: run_set(write_border_cuts(root, work / f"border_{side}_frames", side),
                          work / f"border_{side}", cfg) for side in BORDER_SIDES}


def moved_scores(root: Path, work: Path, cfg: Config) -> dict:
    """:func:`run_set` on the frames below ``root`` moved by each of :data:`MOVES`
    (:func:`shifted`, the true depth moved with them): ``{"down,right": totals}``. The whole
    pipeline's spread over equally likely views of the same scenes: a change to the method
    smaller than it is not measured."""
    out = {}
    for down, right in MOVES:
        def move(frame, truth, gt, down=down, right=right):
            rgb, depth, ids, K = shifted(frame.rgb, frame.depth_m, truth, frame.camera.K,
                                         down, right)
            return rgb, depth, ids, moved_image(gt, down, right), K

        frames = write_frames(root, work / f"moved_{down}{right}_frames", move)
        out[f"{down},{right}"] = run_set(frames, work / f"moved_{down}{right}", cfg)
    return out


def narrower_scores(root: Path, work: Path, cfg: Config) -> dict:
    """:func:`run_set` on the frames below ``root`` resampled by :func:`narrower` (the true
    depth with them, each pixel from the nearest), with ``scale``: the new width over the
    frames' own (the widest, where they differ)."""
    widths = []

    def narrow(frame, truth, gt):
        widths.append(truth.shape[1])
        rgb, depth, ids, K = narrower(frame.rgb, frame.depth_m, truth, frame.camera)
        return rgb, depth, ids, cv2.resize(gt, ids.shape[::-1],
                                           interpolation=cv2.INTER_NEAREST), K

    frames = write_frames(root, work / "narrower_frames", narrow)
    out = run_set(frames, work / "narrower", cfg)
    return {**out, "scale": NARROW_WIDTH / max(widths)} if widths else out


def realdata_section(work: Path, cfg: Config) -> dict:
    root = SHARED / "realdata"
    if not root.is_dir():
        return {"skipped": f"{root} not present"}
    out = run_set(root, work / "realdata_nomask", cfg)
    out["peak_mib"] = peak_memory_mib(root, work / "realdata_memory")
    out["cloth"] = cloth_scores(root, cfg)
    out["pair"] = pair_scores(root, cfg)
    out["shifted"] = shift_scores(root, cfg)
    out["vga"] = resampled_scores(root, cfg)
    out["toned"] = tone_scores(root, cfg)
    out["stored"] = stored_scores(root, cfg)
    out["border_cut"] = border_cut_scores(root, work, cfg)
    out["moved"] = moved_scores(root, work / "realdata_moved", cfg)
    return out


def extsim_section(work: Path, cfg: Config) -> dict:
    root = SHARED / "extsim"
    if not root.is_dir():
        return {"skipped": f"{root} not present"}
    out = run_set(root, work / "extsim", cfg, grasps=True)
    out["shifted"] = shift_scores(root, cfg)
    out["toned"] = tone_scores(root, cfg)
    out["moved"] = moved_scores(root, work / "extsim_moved", cfg)
    out["narrower"] = narrower_scores(root, work / "extsim_narrower", cfg)
    return out


def report(results: dict) -> list[str]:
    """The headline sections of RESULTS.md."""
    lines = []
    for key, title, note in (
            ("realdata", "real frames, no masks given (../shared/realdata)",
             "3 ClearGrasp frames (D435, D415, 1280x720) and 8 Tracebot views (D435, 1280x720): "
             "the whole default `repair-depth` from the raw frame."),
            ("extsim", "independent renderer (../shared/extsim)",
             "16 frames (848x480) of scanned household meshes, 1-3 objects each: the whole "
             f"default pipeline from the raw frame; grasps judged on the true meshes at "
             f"friction 0.5, the mean of {GRASP_DRAWS} random draws of seed points "
             "(`grasp.seed` 0, 1, ...).")):
        r = results.get(key, {})
        if not r:
            continue
        lines += [f"## {title}", ""]
        if "skipped" in r:
            lines += [f"skipped: {r['skipped']}", ""]
            continue
        lines += [note, "",
                  f"- segmentation: {r['objects']} true objects, detected (best IoU >= "
                  f"{DETECTED_IOU}) {r['detection']:.2f}, mean best IoU {r['mean_iou']:.3f}, "
                  f"false instances per frame {r['false_per_frame']:.2f} (>= {FALSE_AREA} px, "
                  f"IoU < {FALSE_IOU} with every object)",
                  f"- invented depth: {100 * r['invented_share']:.2f}% of the frame (pixels over "
                  f"{INVENTED_REACH} px from every object changed by over "
                  f"{100 * INVENTED_CHANGE:.0f} cm)",
                  "- median seconds per frame on one core: " + ", ".join(
                      f"{k} {v:.2f}" for k, v in r["seconds"].items())
                  + f"; slowest frame {r['max_seconds']:.1f} s"]
        if "peak_mib" in r:
            lines.append(f"- peak memory of one `sr3d repair-depth` worker over the frames: "
                         f"{r['peak_mib']:.0f} MiB")
        if "cloth" in r:
            c = r["cloth"]
            lines.append(f"- on a white cloth that returns no readings, laid under the objects "
                         f"(simulated: every reading but the objects' own dropped, the pixels "
                         f"moved towards white; segment alone): detected {c['detection']:.2f}, "
                         f"mean best IoU {c['mean_iou']:.3f}, false instances per frame "
                         f"{c['false_per_frame']:.2f}")
        if r.get("pair"):
            lines.append("- two alike side by side (simulated: each one-object frame's object "
                         "with the band around it copied beside itself; segment alone): " +
                         "; ".join(f"{gap} px apart at 1280 px ({p['frames']} frames): detected "
                                   f"{p['detection']:.2f}, mean best IoU {p['mean_iou']:.3f}, "
                                   f"false instances per frame {p['false_per_frame']:.2f}"
                                   for gap, p in r["pair"].items()))
        if r.get("shifted"):
            why = "the segmenter's 2x2 reduction then keeps another reading of each block" \
                if key == "realdata" else "every outline then falls on the pixel grid " \
                "another way"
            lines.append(f"- the same frames moved by one pixel ({why}; segment alone): " +
                         "; ".join(f"down {key.split(',')[0]}, right {key.split(',')[1]}: "
                                   f"detected {p['detection']:.2f}, mean best IoU "
                                   f"{p['mean_iou']:.3f}, false instances per frame "
                                   f"{p['false_per_frame']:.2f}"
                                   for key, p in r["shifted"].items()))
        if r.get("vga"):
            v = r["vga"]
            lines.append(f"- resampled to {VGA[0]}x{VGA[1]} (each frame's central crop of that "
                         f"aspect: a VGA frame is segmented whole, not halved; segment alone): "
                         f"detected {v['detection']:.2f}, mean best IoU {v['mean_iou']:.3f}, "
                         f"false instances per frame {v['false_per_frame']:.2f}")
        if r.get("toned"):
            lines.append("- the colour as another exposure or sensor gives it (segment alone): " +
                         "; ".join(f"{tone}, {TONES[tone]}: detected {p['detection']:.2f}, "
                                   f"mean best IoU {p['mean_iou']:.3f}, false instances per "
                                   f"frame {p['false_per_frame']:.2f}"
                                   for tone, p in r["toned"].items()))
        if r.get("stored"):
            p = r["stored"]
            lines.append(f"- the depth rounded to {1000 * STORED_STEP:g} mm, as a camera writing "
                         f"16-bit depth stores it (ClearGrasp's EXR holds finer values; Tracebot's "
                         f"are already so; segment alone): detected {p['detection']:.2f}, mean "
                         f"best IoU {p['mean_iou']:.3f}, false instances per frame "
                         f"{p['false_per_frame']:.2f}")
        if r.get("moved"):
            lines.append(
                "- the whole pipeline on the same frames moved by one pixel (as above; the "
                "spread of every number here over equally likely views): " + "; ".join(
                    f"down {key.split(',')[0]}, right {key.split(',')[1]}: detected "
                    f"{m['detection']:.2f}, mean best IoU {m['mean_iou']:.3f}, object MAE "
                    f"{1000 * m['depth']['sr3d']['mae']:.1f} / "
                    f"{1000 * m['median_mae']['sr3d']:.1f} mm (mean / median)"
                    for key, m in r["moved"].items()))
        if r.get("narrower"):
            n = r["narrower"]
            lines.append(
                f"- the whole pipeline on the same frames resampled to {NARROW_WIDTH} px across "
                f"(a camera of the same field of view streaming fewer pixels: each object "
                f"{n['scale']:.2f} times as many pixels across): detected "
                f"{n['detection']:.2f}, mean best IoU {n['mean_iou']:.3f}, false instances per "
                f"frame {n['false_per_frame']:.2f}, object MAE "
                f"{1000 * n['depth']['sr3d']['mae']:.1f} / {1000 * n['median_mae']['sr3d']:.1f} "
                f"mm (mean / median)")
        if r.get("border_cut"):
            lines.append(
                f"- cut by the image border (simulated: each frame cropped so that the border "
                f"cuts {BORDER_SHARE:.0%} off its lowest object's foot, or off its leftmost "
                f"object's side; whole pipeline, object MAE over the true masks, mean / "
                f"median): " + "; ".join(
                    f"{side}: sr3d {1000 * b['depth']['sr3d']['mae']:.0f} / "
                    f"{1000 * b['median_mae']['sr3d']:.0f} mm, raw "
                    f"{1000 * b['depth']['raw']['mae']:.0f} / "
                    f"{1000 * b['median_mae']['raw']:.0f} mm, detected {b['detection']:.2f}, "
                    f"invented depth {100 * b['invented_share']:.2f}%"
                    for side, b in r["border_cut"].items()))
        if "pose" in r:
            p = r["pose"]
            lines.append(
                f"- pose of the objects with a true pose: {p['matched']} of {p['objects']} "
                f"placed (mask IoU >= {MATCH_IOU}); median axis angle "
                f"{p['median_axis_deg']:.1f} deg, base translation "
                f"{p['median_translation_mm']:.1f} mm, height {p['median_scale_pct']:.1f}%, "
                f"ADD-S {p['median_add_s_mm']:.1f} mm (mean {p['mean_add_s_mm']:.1f} mm); "
                "`sr3d_cli/pose_error.py`: the angle between the z axes (a surface of "
                "revolution's turn about its axis is no error; an object placed upside down "
                "is 180 deg off), the distance between the base centres, the placed height "
                "against the true one, and the mean distance from the true surface to the "
                "placed one")
        if "grasp" in r:
            g = r["grasp"]
            by_draw = ", ".join(f"{v:.3f}" for v in g.get("top1_by_draw", []))
            lines.append(f"- grasps: {g['objects']:.0f} objects, {g['objects_with_grasps']:.0f}"
                         f" with grasps, top-1 {g['top1_success']:.3f}, top-10 "
                         f"{g['top10_success']:.3f}" + (f" (top-1 by draw: {by_draw})"
                                                        if by_draw else ""))
        lines += ["", "Object depth over the true masks (holes count full error); plane-fill and "
                      "inpaint are given the true masks:", "",
                  "| method | RMSE m | REL | MAE m | median MAE mm |", "|---|---|---|---|---|"]
        for m, x in r["depth"].items():
            lines.append(f"| {m} | {x['rmse']:.4f} | {x['rel']:.4f} | {x['mae']:.4f} | "
                         f"{1000 * r['median_mae'][m]:.1f} |")
        lines.append("")
    return lines
