"""Per-frame stage runs on scene folders: read a stage's inputs, call the core, write outputs.

The commands in :mod:`sr3d_cli.cli` loop over frames and report; this module knows which file
each stage reads and writes (DESIGN.md, "Scene folder"). A frame's stage data is held by one
:class:`FrameState`: each stage takes its inputs from it (what an earlier stage made in the same
run, or else its files, each read once) and puts its outputs there as it writes them, so a run
of several stages fits the table once and reads back nothing it wrote, and each stage still
runs alone from the files. Object-level problems do not fail the frame: they are returned as
:class:`~sr3d_cli.errors.Problem` values and recorded in the stage's JSON.
"""

from __future__ import annotations

import json
import logging
from pathlib import Path

import numpy as np
import trimesh

from sr3d_cli.errors import InputError, NoTable, Problem
from sr3d_cli.geometry.occlusion import occluders, opaque_objects, without_spill
from sr3d_cli.geometry.plane import Plane, support_plane
from sr3d_cli.geometry.transforms import place_points
from sr3d_cli.io import images, provenance
from sr3d_cli.io.atomic import write_bytes, write_json, write_npy, write_png
from sr3d_cli.io.scene import Frame, SceneSource

log = logging.getLogger("sr3d")


# the JSON of each stage output that holds its ``made_from`` record (DESIGN.md, "Scene folder")
RECORD_FILES = {"segment": ("masks", ".json"), "reconstruct": ("meshes", ".json"),
                "align": ("poses", ".json"), "repair": ("repaired", ".json"),
                "grasp": ("grasps", ".json")}
MISSING = "missing"  # why a stage must run whose output is not there (:func:`stale`)


def write_instances(source: SceneSource, frame_id: str, instances, backend: str,
                    record: dict | None = None) -> None:
    """masks/<frame>.png (the ids, 8 or 16 bits) and masks/<frame>.json (the records of
    :class:`~sr3d_cli.segment.Instances`, the backend, ``record``)."""
    ids = instances.ids
    dtype = np.uint8 if ids.max(initial=0) <= 255 else np.uint16
    document = instances.to_json(backend)
    if record is not None:
        document[provenance.RECORD_KEY] = record
    write_png(source.output_path("masks", frame_id), ids.astype(dtype))
    write_json(source.output_path("masks", frame_id, ".json"), document)


def folder_mask_path(folder, frame_id: str):
    """The mask of a frame in a folder of masks made elsewhere: ``<frame>.png``, or ClearGrasp's
    ``<frame>-mask.png``, or TransCG's ``<frame>/depth1-gt-mask.png`` (None: none there)."""
    folder = Path(folder)
    for name in (f"{frame_id}.png", f"{frame_id}-mask.png", f"{frame_id}/depth1-gt-mask.png"):
        if (folder / name).is_file():
            return folder / name
    return None


def masks_path(source: SceneSource, frame_id: str, which: str = "segment"):
    """The instance mask file a stage reads: ``masks/`` (segment), the ground truth (gt) or a
    folder of masks made elsewhere (None where there is none yet)."""
    if which == "segment":
        return source.stage_file("masks", frame_id, (".png",))
    if which == "gt":
        return source.gt_mask_path(frame_id)
    return folder_mask_path(which, frame_id)


def load_instances(source: SceneSource, frame_id: str, shape: tuple[int, int],
                   which: str = "segment") -> tuple[np.ndarray, dict[int, dict]]:
    """Instance ids ``(H, W) int32`` and per-id records, from ``masks/`` (``which`` segment),
    the ground truth (gt) or a folder of masks (``which`` is its path; a binary mask is split
    into connected components)."""
    if which not in ("gt", "segment"):
        path = folder_mask_path(which, frame_id)
        if path is None:
            raise InputError(which, f"no mask for frame {frame_id} ({frame_id}.png or "
                                    f"{frame_id}-mask.png)")
        from sr3d_cli.io.images import read_mask

        ids = read_mask(path, split_binary=True)
        if ids.shape != tuple(shape):
            raise InputError(path, f"mask is {ids.shape[1]}x{ids.shape[0]} but the images are "
                                   f"{shape[1]}x{shape[0]}")
        return ids, {int(k): {"id": int(k), "label": ""} for k in np.unique(ids) if k > 0}
    if which == "gt":
        path = source.gt_mask_path(frame_id)
        if path is None:
            raise InputError(source.root / "gt" / "masks", f"no ground-truth mask for {frame_id}")
        ids = source.load_mask(path, shape)
        gt = source.load_gt_objects(frame_id) or {}
        labels = {o["id"]: o.get("label", "") for o in gt.get("objects", [])}
        return ids, {int(k): {"id": int(k), "label": labels.get(int(k), "")}
                     for k in np.unique(ids) if k > 0}
    path = source.stage_file("masks", frame_id, (".png",))
    if path is None:
        raise InputError(source.out / "masks" / f"{frame_id}.png",
                         "no masks for this frame: run `sr3d segment` first")
    ids = images.read_mask(path)  # sr3d's own ids, whatever the layout: never split
    if ids.shape != tuple(shape):
        raise InputError(path, f"mask is {ids.shape[1]}x{ids.shape[0]} but the images are "
                               f"{shape[1]}x{shape[0]}")
    meta = path.with_suffix(".json")
    if not meta.is_file():
        return ids, instance_records(ids, [])
    try:
        objects = json.loads(meta.read_text(encoding="utf-8")).get("objects", [])
        return ids, instance_records(ids, objects)
    except (ValueError, OSError, TypeError, AttributeError) as exc:
        raise InputError(meta, f"cannot read instance records ({exc})") from None


def instance_records(ids: np.ndarray, objects: list[dict]) -> dict[int, dict]:
    """{id: record} of every id in ``ids (H, W) int32`` (0 = background): its entry in
    ``objects`` (masks/<frame>.json), else ``{"id", "label": ""}``."""
    records = {int(k): {"id": int(k), "label": ""} for k in np.unique(ids) if k > 0}
    for obj in objects:
        if int(obj.get("id", -1)) in records:
            records[int(obj["id"])] = obj
    return records


def segment_frame(state: "FrameState", segmenter, backend: str, record: dict | None = None):
    """Segment a frame: writes masks/<frame>.png and .json (:func:`write_instances`), keeps the
    instances in ``state`` and returns them (:class:`~sr3d_cli.segment.Instances`)."""
    frame = state.frame
    try:
        instances = segmenter(frame.frame_id, frame.rgb, frame.depth_m, frame.camera.K)
    except NoTable as exc:
        raise InputError(frame.scene.depth_path(frame.frame_id), str(exc)) from None
    write_instances(frame.scene, frame.frame_id, instances, backend, record)
    state.segmented(instances.ids, instances.objects)
    return instances


def frame_plane(frame: Frame, ids: np.ndarray, plane_cfg) -> tuple[Plane | None, str | None]:
    """The support plane with the objects left out, or (None, reason)."""
    try:
        return support_plane(frame.depth_m, frame.camera.K, plane_cfg, exclude=ids > 0), None
    except ValueError as exc:
        return None, str(exc)


MESH_SUFFIXES = (".ply", ".obj", ".stl")  # the mesh files a stage output may hold
OPEN_SUFFIX = "_open.ply"  # meshes/<frame>/<k>_open.ply: the object opened at a likely mouth


def mesh_path(source: SceneSource, frame_id: str, obj_id: int, suffix: str = ".ply"):
    return source.out / "meshes" / frame_id / f"{obj_id}{suffix}"


def find_mesh(source: SceneSource, frame_id: str, obj_id: int):
    """The mesh of an object: under the output root, else under the input root (else the
    output path, which does not exist)."""
    hit = source.stage_file(f"meshes/{frame_id}", str(obj_id), MESH_SUFFIXES)
    return hit if hit is not None else mesh_path(source, frame_id, obj_id)


def write_mesh(path, mesh: trimesh.Trimesh) -> tuple[trimesh.Trimesh, str]:
    """Write ``mesh`` as binary PLY; returns the mesh as the file holds it (vertices rounded to
    float32, as :func:`load_mesh` reads them back) and the file's fingerprint."""
    data = mesh.export(file_type="ply", encoding="binary")
    write_bytes(path, data)
    stored = trimesh.Trimesh(np.asarray(mesh.vertices, np.float32).astype(np.float64),
                             np.asarray(mesh.faces, np.int64), process=False)
    return stored, provenance.digest(data)


class FrameState:
    """One frame's stage data, each piece read or computed once: the instances, the table, the
    objects' meshes, the poses. A stage that runs puts what it writes here (as its files hold
    it); what no stage made in this run is read from the stage outputs on first use.

    frame : the frame; plane_cfg : the ``plane`` config; which_masks : where the instances
    come from (``segment``, ``gt`` or a folder, :func:`load_instances`).
    """

    def __init__(self, frame: Frame, plane_cfg, which_masks: str = "segment"):
        self.frame, self.plane_cfg, self.which_masks = frame, plane_cfg, which_masks
        self._instances: tuple[np.ndarray, dict[int, dict]] | None = None
        self._plane: tuple[Plane | None, str | None] | None = None
        self._seen: np.ndarray | None = None
        self._occluders: dict[int, np.ndarray | None] = {}
        self._made: dict[int, tuple[trimesh.Trimesh, dict, trimesh.Trimesh | None]] | None = None
        self._read: dict[int, trimesh.Trimesh] = {}
        self._poses: dict | None = None

    @property
    def source(self) -> SceneSource:
        return self.frame.scene

    @property
    def frame_id(self) -> str:
        return self.frame.frame_id

    def instances(self) -> tuple[np.ndarray, dict[int, dict]]:
        """Instance ids ``(H, W) int32`` and {id: record}: segmented in this run, else read."""
        if self._instances is None:
            self._instances = load_instances(self.source, self.frame_id,
                                             self.frame.depth_m.shape, self.which_masks)
        return self._instances

    def segmented(self, ids: np.ndarray, objects: list[dict]) -> None:
        """The instances segment made: ids ``(H, W) int32``, one record per id."""
        self._instances = (ids, instance_records(ids, objects))
        self._plane = self._seen = None  # fitted with the objects left out; made from them
        self._occluders = {}

    def plane(self) -> tuple[Plane | None, str | None]:
        """The table with the instances left out (:func:`frame_plane`), or (None, why): fitted
        once, for every stage after segment. Segment finds the objects on a table it fits
        before there are any (all the readings, at its working size); the placed objects
        come out better on this one, which needs the masks (the bench's depth MAE)."""
        if self._plane is None:
            self._plane = frame_plane(self.frame, self.instances()[0], self.plane_cfg)
        return self._plane

    def seen(self) -> np.ndarray:
        """The instance ids ``(H, W) int32`` with the opaque objects the raw depth sees added
        (:func:`opaque_objects`; the ids alone without a table): what may stand in front of an
        instance and hide its foot. Made once, for reconstruct and align."""
        if self._seen is None:
            ids, plane = self.instances()[0], self.plane()[0]
            self._seen = ids if plane is None else opaque_objects(
                ids, self.frame.depth_m, self.frame.camera.K, plane)
        return self._seen

    def occluders(self, k: int) -> np.ndarray | None:
        """Pixels ``(H, W) bool`` of what stands in front of instance ``k`` near it
        (:func:`occluders` on :meth:`seen`), None where nothing does or there is no table.
        Made once per instance, for reconstruct and align."""
        if k not in self._occluders:
            plane = self.plane()[0]
            self._occluders[k] = None if plane is None else \
                occluders(self.seen(), k, self.frame.camera.K, plane)
        return self._occluders[k]

    def reconstructed(self, made: dict[int, tuple[trimesh.Trimesh, dict,
                                                  trimesh.Trimesh | None]]) -> None:
        """The meshes reconstruct wrote in this run: {id: (mesh, meta, open alternative or
        None)}, as their files hold them; an id without one is looked up in the files."""
        self._made, self._read = made, {}

    def has_mesh(self, k: int) -> bool:
        return (self._made is not None and k in self._made) or \
            find_mesh(self.source, self.frame_id, k).is_file()

    def mesh(self, k: int) -> trimesh.Trimesh:
        """Object ``k``'s mesh (object frame); :class:`InputError` naming the file where there
        is none or it cannot be read."""
        if self._made is not None and k in self._made:
            return self._made[k][0]
        if k not in self._read:
            path = find_mesh(self.source, self.frame_id, k)
            if not path.is_file():
                raise InputError(path, "no mesh: run `sr3d reconstruct` first")
            self._read[k] = load_mesh(path)
        return self._read[k]

    def mesh_meta(self, k: int) -> dict:
        """meshes/<frame>/<k>.json of object ``k`` ({} where there is none or it is unreadable)."""
        if self._made is not None and k in self._made:
            return self._made[k][1]
        try:
            meta = json.loads(find_mesh(self.source, self.frame_id, k).with_suffix(".json")
                              .read_text(encoding="utf-8"))
        except (OSError, ValueError):
            return {}
        return meta if isinstance(meta, dict) else {}

    def pose_hint(self, k: int) -> tuple[np.ndarray, float] | None:
        """The pose ``(T_cam_obj (4, 4), scale)`` reconstruct fitted on its way, if any."""
        try:
            hint = self.mesh_meta(k)["pose_hint"]
            return np.asarray(hint["T_cam_obj"], dtype=np.float64), float(hint["scale"])
        except (KeyError, TypeError, ValueError):
            return None

    def open_alternative(self, k: int) -> trimesh.Trimesh | None:
        """Object ``k`` opened where its mouth likely is (``open_alternative`` in its meta, in
        the mesh's own object frame), if reconstruct made one."""
        if self._made is not None and k in self._made:
            return self._made[k][2]
        try:
            name = self.mesh_meta(k)["open_alternative"]
            return load_mesh(find_mesh(self.source, self.frame_id, k).with_name(name))
        except (OSError, ValueError, KeyError, TypeError):
            return None

    def placed(self, document: dict) -> None:
        """The pose document align wrote in this run (:func:`align_frame`)."""
        self._poses = document

    def pose_document(self) -> dict:
        """poses/<frame>.json: placed in this run, else read (:func:`load_pose_document`)."""
        if self._poses is None:
            self._poses = load_pose_document(self.source, self.frame_id)
        return self._poses


def stage_inputs(source: SceneSource, frame_id: str, stage: str, which_masks: str = "segment",
                 grasp_source: str = "repaired") -> dict:
    """The upstream files a stage reads for a frame (see :mod:`sr3d_cli.io.provenance`)."""
    inputs = {"depth": source.depth_path(frame_id), "camera": source.camera_path(),
              "masks": masks_path(source, frame_id, which_masks)}
    if stage in ("segment", "reconstruct"):
        inputs["rgb"] = source.rgb_path(frame_id)
    if stage == "segment":
        del inputs["masks"]
    if stage in ("align", "repair") or (stage == "grasp" and grasp_source == "repaired"):
        inputs["meshes"] = source.stage_file("meshes", frame_id, (".json",))
    if stage == "repair" or (stage == "grasp" and grasp_source == "repaired"):
        inputs["poses"] = source.stage_file("poses", frame_id, (".json",))
    if stage == "grasp" and grasp_source == "repaired":
        inputs["repaired"] = source.prediction_path("repaired", frame_id)
    return inputs


def stage_record(cfg, source: SceneSource, frame_id: str, stage: str) -> dict:
    """The ``made_from`` record a stage output of this frame made now would carry."""
    inputs = stage_inputs(source, frame_id, stage, cfg.reconstruct.masks, cfg.grasp.source)
    if stage == "segment" and cfg.segment.backend == "import" and cfg.segment.import_dir:
        folder = Path(cfg.segment.import_dir)  # the imported mask, whatever its image suffix
        inputs["imported"] = next((folder / f"{frame_id}{suffix}" for suffix in
                                   (".png", ".tif", ".tiff", ".bmp")
                                   if (folder / f"{frame_id}{suffix}").is_file()), None)
    record = provenance.made_from(cfg, stage, inputs)
    record["config"]["io.depth_scale"] = float(cfg.io.depth_scale)
    return record


def record_path(source: SceneSource, frame_id: str, stage: str):
    folder, suffix = RECORD_FILES[stage]
    return source.stage_file(folder, frame_id, (suffix,))


def stale(cfg, source: SceneSource, frame_id: str, stage: str) -> str | None:
    """Why a stage's output of this frame must be made again: :data:`MISSING`, damaged
    (:func:`broken`), the first difference from its record, or None (current, or made
    elsewhere without a record)."""
    path = record_path(source, frame_id, stage)
    if path is None:
        return MISSING
    try:
        document = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return f"{path.name} cannot be read"
    why = broken(path, document, stage)
    if why is not None:
        return why
    return provenance.stale_reason(provenance.record_of(document),
                                   stage_record(cfg, source, frame_id, stage))


def broken(path: Path, document, stage: str) -> str | None:
    """Why the output of ``stage`` whose JSON ``path`` holds ``document`` cannot be used (None:
    it can): no mapping, or a file it stands for empty or gone (the masks' PNG beside it; the
    meshes it lists). A run stopped hard or a disk that filled up leaves such files; they are
    made again rather than failing the frame."""
    if not isinstance(document, dict):
        return f"{path.name} holds no mapping"
    data = []  # each file that must be there, as the ways it may be written
    if stage == "segment":
        data = [[path.with_suffix(".png")]]
    elif stage == "reconstruct" and isinstance(document.get("objects"), dict):
        data = [[path.parent / path.stem / f"{k}{suffix}" for suffix in MESH_SUFFIXES]
                for k in document["objects"]]
    for ways in data:
        if not any(file.is_file() and file.stat().st_size > 0 for file in ways):
            return f"{ways[0].parent.name}/{ways[0].name} is missing or empty"
    return None


def reconstruct_frame(state: FrameState, reconstructor, record: dict | None = None
                      ) -> tuple[int, list[Problem]]:
    """Reconstruct every instance of a frame from its mask less the spill along the others
    that do not stand in front of it (:func:`without_spill`); returns (meshes written, object
    problems). Writes ``meshes/<frame>.json`` (the meshes written, with their fingerprints,
    the object problems, ``frame_failed`` where there are instances and no mesh, and
    ``record``), removes meshes of an earlier run no instance has now, and keeps the meshes
    in ``state``."""
    frame, source, fid = state.frame, state.source, state.frame_id
    ids, records = state.instances()
    plane, why = state.plane()
    problems, made, kept = [], {}, {}
    for k in sorted(records):
        try:
            if plane is None and reconstructor.needs_plane:
                raise ValueError(why)
            front = state.occluders(k)
            result = reconstructor(frame.rgb, without_spill(ids, k, front), frame.camera.K, plane,
                                   records[k].get("label", ""), frame.depth_m, front)
        except ValueError as exc:  # ObjectError, and model/fit failures of this object
            problems.append(Problem(str(exc), k))
            continue
        mesh, made[str(k)] = write_mesh(mesh_path(source, fid, k), result.mesh)
        meta, opened = result.meta, None
        if result.open_alternative is not None:
            path = mesh_path(source, fid, k, OPEN_SUFFIX)
            opened, _ = write_mesh(path, result.open_alternative)
            meta = {**meta, "open_alternative": path.name}
        write_json(mesh_path(source, fid, k, ".json"), meta)
        kept[k] = (mesh, meta, opened)
    folder = source.out / "meshes" / fid
    if folder.is_dir():  # meshes of an earlier run that no instance of this one has
        for path in folder.iterdir():
            if path.stem.split("_")[0] not in made and path.stem.split("_")[0].isdigit():
                path.unlink()
    document = {"objects": made, "failed": [str(p) for p in problems]}
    if records and not made:
        document["frame_failed"] = "no mesh made (" + "; ".join(map(str, problems)) + ")"
    if record is not None:
        document[provenance.RECORD_KEY] = record
    write_json(source.output_path("meshes", fid, ".json"), document)
    state.reconstructed(kept)
    return len(made), problems


def load_mesh(path) -> trimesh.Trimesh:
    """A triangle mesh file (PLY, OBJ, STL...); :class:`InputError` naming it where it cannot be
    read, has no triangles or holds non-finite vertices."""
    try:
        mesh = trimesh.load(path, force="mesh", process=False)
    except Exception as exc:
        raise InputError(path, f"cannot read mesh ({type(exc).__name__}: {exc})") from None
    if not isinstance(mesh, trimesh.Trimesh) or len(mesh.faces) == 0:
        raise InputError(path, "mesh has no triangles (truncated or not a mesh)")
    if not np.isfinite(mesh.vertices).all():
        raise InputError(path, "mesh has non-finite vertices (NaN or inf)")
    return mesh


def align_frame(state: FrameState, aligner, record: dict | None = None
                ) -> tuple[list[dict], list[Problem]]:
    """Place every reconstructed object; writes ``poses/<id>.json`` (``frame_failed`` where
    there are instances and none was placed) and keeps it in ``state``. Returns (objects,
    problems); an object without a mesh is an ``upstream`` problem (reconstruct's)."""
    frame, source, fid = state.frame, state.source, state.frame_id
    ids, records = state.instances()
    plane, why = state.plane()
    objects, problems = [], []
    for k in sorted(records):
        if not state.has_mesh(k):
            problems.append(Problem("no mesh: run `sr3d reconstruct` first", k, upstream=True))
            continue
        try:
            if plane is None:
                raise ValueError(why)
            placement = aligner(state.mesh(k), ids == k, frame.camera.K, plane, frame.depth_m,
                                hint=state.pose_hint(k),
                                occluders=state.occluders(k))
        except ValueError as exc:
            problems.append(Problem(str(exc), k))
            continue
        objects.append({"id": k, "label": records[k].get("label", ""),
                        "mesh": f"meshes/{fid}/{k}.ply", "T_cam_obj": placement.T_cam_obj.tolist(),
                        "scale": float(placement.scale), "scores": placement.scores,
                        "diagnostics": placement.diagnostics})
    document = {"objects": objects, "failed": [str(p) for p in problems],
                "plane": plane.to_json() if plane is not None else None}
    if records and not objects:
        document["frame_failed"] = "no object placed (" + "; ".join(map(str, problems)) + ")"
    if record is not None:
        document[provenance.RECORD_KEY] = record
    write_json(source.output_path("poses", fid, ".json"), document)
    state.placed(document)
    return objects, problems


def load_pose_document(source: SceneSource, frame_id: str) -> dict:
    """poses/<id>.json as written by :func:`align_frame` (objects, failed, plane)."""
    path = source.stage_file("poses", frame_id, (".json",))
    if path is None:
        raise InputError(source.out / "poses" / f"{frame_id}.json",
                         "no poses: run `sr3d align` first")
    try:
        document = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, ValueError) as exc:
        raise InputError(path, f"cannot read poses ({exc})") from None
    if not isinstance(document, dict) or not isinstance(document.get("objects", []), list):
        raise InputError(path, "poses file must hold a mapping with an 'objects' list")
    for obj in document.get("objects", []):
        check_placement(obj, path)
    return document


def check_placement(obj, path) -> None:
    """Raise :class:`InputError` naming ``path`` where a placed object (``id``, ``T_cam_obj``
    4x4, ``scale`` > 0) has a missing, malformed or non-finite value."""
    try:
        k = int(obj["id"])
        T = np.asarray(obj["T_cam_obj"], dtype=np.float64)
        scale = float(obj["scale"])
    except (KeyError, TypeError, ValueError) as exc:
        raise InputError(path, f"object without a valid id, T_cam_obj and scale ({exc})") \
            from None
    if T.shape != (4, 4) or not np.isfinite(T).all():
        raise InputError(path, f"object {k}: T_cam_obj must be a finite 4x4")
    if not (np.isfinite(scale) and scale > 0):
        raise InputError(path, f"object {k}: scale must be a finite number > 0, got {scale}")


def load_poses(source: SceneSource, frame_id: str) -> list[dict]:
    return load_pose_document(source, frame_id).get("objects", [])


def depth_suffix(source: SceneSource, frame_id: str) -> str:
    """Repaired depth keeps the input's encoding (PNG with depth_scale, EXR or npy metres)."""
    suffix = source.depth_path(frame_id).suffix.lower()
    return suffix if suffix in (".png", ".exr", ".npy") else ".png"


def _read_prediction(source: SceneSource, stage: str, frame_id: str, shape) -> np.ndarray:
    path = source.prediction_path(stage, frame_id)
    if path is None:
        raise ValueError(f"no {stage} depth: run `sr3d repair-depth` first")
    return source.read_depth_checked(path, shape)


def grasp_frame(frame: Frame, planner, plane_cfg, depth_source: str = "repaired",
                only: int | None = None, hand_poses: float | None = None,
                which_masks: str = "segment", record: dict | None = None
                ) -> tuple[int, list[Problem], str | None]:
    """Plan grasps for one frame; writes ``grasps/<id>.json`` and ``.npy`` (an empty but valid
    file, with the reason, when nothing can be planned). Returns (grasps, problems, why the
    frame failed): a frame fails when an input is missing or unreadable, or when it has
    objects and none of them got a grasp; a frame without objects does not."""
    from sr3d_cli.grasp import GraspSet

    state = FrameState(frame, plane_cfg, which_masks)
    source, fid = frame.scene, frame.frame_id
    grasps, problems, failure = GraspSet.empty(), [], None
    try:
        ids, _ = state.instances()
        if only is not None and not (ids == only).any():
            raise InputError(masks_path(source, fid, which_masks) or fid,
                             f"object {only} is not in this frame's masks")
        if not (ids > 0).any():
            problems.append(Problem("no objects in the masks: nothing to grasp"))
        else:
            grasps, said = _plan_frame(state, planner, depth_source, only)
            problems = [Problem(text) for text in said]  # the planner names each object
            if len(grasps) == 0:
                failure = "no grasp for any object (" + "; ".join(said) + ")"
    except (InputError, ValueError) as exc:
        problems.append(Problem(str(exc)))
        failure = str(exc)
    document = {"source": depth_source, "grasps": grasps.to_json(),
                "failed": [str(p) for p in problems],
                "frame": "camera (OpenCV), metres; grasp x = approach, y = closing direction, "
                         "position = grasp centre; fingertips reach `depth` past it"}
    if failure is not None:
        document["frame_failed"] = failure
    if record is not None:
        document[provenance.RECORD_KEY] = record
    write_json(source.output_path("grasps", fid, ".json"), document)
    write_npy(source.output_path("grasps", fid, ".npy"), grasps.to_array())
    if hand_poses is not None:
        write_npy(source.output_path("grasps", fid, "_hand_poses.npy"),
                  grasps.hand_poses(hand_poses))
    return len(grasps), problems, failure


def _plan_frame(state: FrameState, planner, depth_source: str, only: int | None):
    """(grasps, object messages) of a frame with objects (``state.instances()``)."""
    from sr3d_cli.grasp.planner import Cloud, depth_cloud, in_view, mesh_cloud, observed_cloud

    frame, source, fid, K = state.frame, state.source, state.frame_id, state.frame.camera.K
    ids, _ = state.instances()
    cfg = planner.cfg
    depth = frame.depth_m if depth_source == "raw" else \
        _read_prediction(source, "repaired", fid, frame.depth_m.shape)
    poses = state.pose_document() if depth_source == "repaired" else {}
    # the table align placed the objects on, else (raw depth, or none recorded) the frame's
    plane = Plane.from_json(poses["plane"]) if poses.get("plane") else None
    if plane is None:
        plane, why = state.plane()
        if plane is None:
            raise ValueError(why)
    scene = depth_cloud(depth, K, ids, cfg.stride)
    targets = {int(k): scene.select(scene.labels == k) for k in np.unique(ids) if k > 0}
    surfaces, fallbacks, axes, observed = {}, {}, {}, None
    if depth_source == "repaired":
        observed = observed_cloud(frame.depth_m, K, ids)
        placed, opened = {}, {}
        for obj in poses.get("objects", []):
            k = int(obj["id"])
            T, scale = np.asarray(obj["T_cam_obj"]), float(obj["scale"])
            axes[k] = T[:3, 2]  # the object frame's z: its height (lying: its length)
            for mesh, clouds in ((state.mesh(k), placed), (state.open_alternative(k), opened)):
                if mesh is not None:
                    clouds[k] = (mesh_cloud(mesh, T, scale, k, cfg.mesh_points, seed=k),
                                 place_points(mesh.vertices, T, scale)[mesh.faces])
            targets[k], surfaces[k] = in_view(placed[k][0], K, depth.shape), placed[k][1]
        # where the closed model gives no grasp: the same scene with the object opened,
        # its depth left out (rendered from the closed model, it holds the lid on a mouth
        # that faces the camera)
        for k, (cloud, triangles) in opened.items():
            others = [c for j, (c, _) in placed.items() if j != k]
            fallbacks[k] = (Cloud.concat([scene.select(scene.labels != k)] + others + [cloud]),
                            in_view(cloud, K, depth.shape), triangles)
        scene = Cloud.concat([scene] + [c for c, _ in placed.values()])
    if only is not None:
        targets = {only: targets[only]}
    return planner.plan(scene, targets, plane, surfaces, fallbacks, axes, observed)


def load_grasps(source: SceneSource, frame_id: str):
    from sr3d_cli.grasp import GraspSet

    path = source.stage_file("grasps", frame_id, (".npy",))
    if path is None:
        raise InputError(source.out / "grasps" / f"{frame_id}.npy",
                         "no grasps: run `sr3d grasp` first")
    try:
        array = np.load(path, allow_pickle=False)
        if not np.isfinite(array).all():
            raise ValueError("non-finite numbers (NaN or inf)")
        return GraspSet.from_array(array)
    except (OSError, ValueError, TypeError, EOFError) as exc:
        raise InputError(path, f"cannot read grasps ({exc})") from None


def grasp_truth(source: SceneSource, frame_id: str, plane_cfg):
    """The true scene of a frame for grasp evaluation: ground-truth meshes at their poses, the
    ground-truth depth as points, the table fitted on the ground-truth depth."""
    import trimesh

    from sr3d_cli.geometry.camera import depth_to_points
    from sr3d_cli.grasp.quality import TrueScene

    gt = source.load_gt_objects(frame_id)
    if not gt or not gt.get("objects"):
        raise InputError(source.root / "gt" / "objects" / f"{frame_id}.json",
                         "grasp evaluation needs ground-truth meshes and poses (gt/objects/)")
    frame = source.load_frame(frame_id)
    rgb_shape, camera = frame.depth_m.shape, frame.camera
    depth = source.load_gt_depth(frame_id, rgb_shape)
    if depth is None:
        raise InputError(source.root / "gt" / "depth", f"no ground-truth depth for {frame_id}")
    ids = source.load_mask(source.gt_mask_path(frame_id), rgb_shape)
    plane = support_plane(depth, camera.K, plane_cfg, exclude=None if ids is None else ids > 0)
    objects = []
    for obj in gt["objects"]:
        check_placement(obj, source.gt_objects_path(frame_id))
        mesh = load_mesh(source.root / obj["mesh"])
        verts = place_points(mesh.vertices, np.asarray(obj["T_cam_obj"]), float(obj["scale"]))
        objects.append((int(obj["id"]), trimesh.Trimesh(verts, mesh.faces, process=False)))
    pts = depth_to_points(depth, camera.K)[::2, ::2]
    truth = TrueScene.build(objects, pts[pts[..., 2] > 0], plane)
    truth.classes = {int(o["id"]): object_class(o) for o in gt["objects"]}
    return truth


def object_class(obj: dict) -> str:
    """A ground-truth object's class in reports: its ``label``, with " lying" where its
    optional ``pose`` says it lies (synthetic scenes: a goblet holds differently lying)."""
    from sr3d_cli.grasp.quality import UNLABELLED

    label = str(obj.get("label") or UNLABELLED)
    return f"{label} lying" if str(obj.get("pose", "")).startswith("lying") else label


def evaluate_grasp_frame(source: SceneSource, frame_id: str, cfg, contacts: str = "grid",
                         also: tuple[str, ...] = ()) -> dict:
    """Grasps of a frame judged against its ground truth (see :mod:`sr3d_cli.grasp.quality`;
    ``contacts``: its contact model). ``also``: other contact models, each judged on the same
    true scene into the result under its name."""
    from sr3d_cli.grasp.gripper import Gripper
    from sr3d_cli.grasp.quality import judge, summarise

    grasps = load_grasps(source, frame_id)
    truth = grasp_truth(source, frame_id, cfg.plane)
    gripper = Gripper.from_config(cfg.grasp)

    def judged(model: str) -> dict:
        records = judge(grasps, truth, gripper, contacts=model)
        return summarise(grasps, records, truth.ids, cfg.grasp.friction,
                         classes=truth.classes)

    result = judged(contacts)
    result.update({model: judged(model) for model in also})
    return result
