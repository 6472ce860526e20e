"""ROS recordings to native scene folders (extra ``bag``: rosbags, pure Python).

Read: ROS 1 ``.bag`` files, ROS 2 bag folders (``metadata.yaml``) and the ``.db3`` (SQLite) or
``.mcap`` file inside one, with no ROS install. Topics are found by the names the RealSense
drivers and the RealSense Viewer give them (:data:`COLOUR_TOPICS` and the lists beside it) or
given by the user.

Depth must be aligned to colour: the driver's ``aligned_depth_to_color`` stream, or a depth
stream whose camera info has the colour stream's size and K (a camera that registers depth
itself). Anything else is refused with how to record it aligned. Depth and colour messages are
paired by header stamp: each depth image with the nearest colour image within half the colour
frame interval.

Depth units: ``16UC1``/``mono16`` images are in the recording's depth units (the Viewer's
``Depth Units`` option when recorded, else millimetres as ROS REP 118 says, unless the user gives
a scale); ``32FC1`` images are metres and are written as millimetres.
"""

from __future__ import annotations

import bisect
import logging
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from sr3d_cli.errors import InputError, MissingExtraError
from sr3d_cli.io.atomic import write_json, write_png

log = logging.getLogger("sr3d")

IMAGE_TYPES = ("sensor_msgs/msg/Image", "sensor_msgs/msg/CompressedImage")
INFO_TYPE = "sensor_msgs/msg/CameraInfo"
# topic name endings, best first: realsense2_camera (ROS 1 /camera/..., ROS 2 /camera/camera/...)
# and the RealSense Viewer / librealsense recorder (/device_0/sensor_N/<Stream>_0/...)
COLOUR_TOPICS = ("/color/image_raw", "/color/image_rect_raw", "/color/image_rect_color",
                 "/Color_0/image/data", "/color/image_raw/compressed")
DEPTH_TOPICS = ("/aligned_depth_to_color/image_raw", "/depth_registered/image_raw",
                "/depth_registered/image_rect", "/depth/image_rect_raw", "/depth/image_raw",
                "/Depth_0/image/data")
ALIGNED_MARKS = ("aligned_depth_to_color", "depth_registered")
DEPTH_UNITS_TOPIC = "/option/Depth Units/value"  # Viewer: std_msgs/Float32, metres per unit
RECORD_ALIGNED = (
    "record depth aligned to colour: ROS 2 `ros2 launch realsense2_camera rs_launch.py "
    "align_depth.enable:=true` and record /camera/camera/aligned_depth_to_color/image_raw, "
    "/camera/camera/color/image_raw and /camera/camera/color/camera_info; ROS 1 `roslaunch "
    "realsense2_camera rs_camera.launch align_depth:=true` (the RealSense Viewer records depth "
    "unaligned)")


def import_rosbags():
    """The rosbags reader, or :class:`MissingExtraError` with the install command."""
    try:
        from rosbags.highlevel import AnyReader
        from rosbags.typesys import Stores, get_typestore
    except ImportError:
        raise MissingExtraError("reading recordings", "rosbags", "bag") from None
    return AnyReader, get_typestore(Stores.LATEST)


@dataclass
class Topics:
    """Topic names of one recording: colour and depth images, their camera infos (may be None)."""

    colour: str
    depth: str
    colour_info: str | None
    depth_info: str | None
    depth_units: str | None = None


@dataclass
class Selection:
    """Which frames to keep: every ``every``-th pair whose stamp lies in [start, end] seconds
    after the recording's first pair, at most ``limit`` of them."""

    every: int = 1
    start: float | None = None
    end: float | None = None
    limit: int | None = None


@dataclass
class _Stream:
    stamps: list[int] = field(default_factory=list)  # header stamp, ns, per message in order


def recording_paths(path: Path) -> list[Path]:
    """What to open: a ``.bag`` file, or a ROS 2 bag folder (given, or the folder holding the
    given ``.db3``/``.mcap`` when it has ``metadata.yaml``; else the file alone)."""
    path = Path(path)
    if not path.exists():
        raise InputError(path, "no such recording")
    if path.is_dir():
        if not (path / "metadata.yaml").is_file():
            raise InputError(path, "not a ROS 2 bag folder (no metadata.yaml)")
        return [path]
    suffix = path.suffix.lower()
    if suffix in (".db3", ".mcap"):
        return [path.parent] if (path.parent / "metadata.yaml").is_file() else [path]
    if suffix == ".bag":
        return [path]
    raise InputError(path, "not a recording: expected a ROS 1 .bag, a ROS 2 bag folder, "
                           "a .db3 or an .mcap file")


def _pick(topics: dict[str, str], endings, types, what: str, path: Path,
          given: str | None) -> str:
    if given:
        if given not in topics:
            raise InputError(path, f"no topic {given!r} ({what}); topics: "
                                   f"{', '.join(sorted(topics)) or 'none'}")
        return given
    for ending in endings:
        for name in sorted(topics):
            if name.endswith(ending) and topics[name] in types:
                return name
    images = sorted(n for n, t in topics.items() if t in IMAGE_TYPES)
    raise InputError(path, f"no {what} image topic found (image topics: "
                           f"{', '.join(images) or 'none'}); name it with --"
                           f"{'colour' if what == 'colour' else 'depth'}-topic")


def info_topic_for(image_topic: str, topics: dict[str, str]) -> str | None:
    """The camera info published beside an image topic, if recorded."""
    base = image_topic.removesuffix("/compressed")
    candidates = [base.rsplit("/", 1)[0] + "/camera_info"]
    if base.endswith("/image/data"):  # Viewer: /device_0/sensor_1/Color_0/info/camera_info
        candidates.insert(0, base.removesuffix("/image/data") + "/info/camera_info")
    return next((c for c in candidates if topics.get(c) == INFO_TYPE), None)


def find_topics(topics: dict[str, str], path: Path, *, colour: str | None = None,
                depth: str | None = None, info: str | None = None) -> Topics:
    """Choose the topics to read from ``{name: message type}``; given names win."""
    c = _pick(topics, COLOUR_TOPICS, IMAGE_TYPES, "colour", path, colour)
    d = _pick(topics, DEPTH_TOPICS, ("sensor_msgs/msg/Image",), "depth", path, depth)
    if info and topics.get(info) != INFO_TYPE:
        raise InputError(path, f"no CameraInfo topic {info!r}")
    units = next((n for n, t in sorted(topics.items())
                  if n.endswith(DEPTH_UNITS_TOPIC) and t.startswith("std_msgs/msg/Float")), None)
    return Topics(c, d, info or info_topic_for(c, topics), info_topic_for(d, topics), units)


def _stamp(msg, fallback: int) -> int:
    header = getattr(msg, "header", None)
    if header is None:
        return fallback
    ns = int(header.stamp.sec) * 1_000_000_000 + int(header.stamp.nanosec)
    return ns if ns > 0 else fallback


def _info_K(msg) -> tuple[np.ndarray, int, int, np.ndarray]:
    K = np.asarray(getattr(msg, "k", None) if hasattr(msg, "k") else msg.K,
                   dtype=np.float64).reshape(3, 3)
    D = np.asarray(getattr(msg, "d", None) if hasattr(msg, "d") else msg.D, dtype=np.float64)
    return K, int(msg.width), int(msg.height), D


def decode_colour(msg, path: Path) -> np.ndarray:
    """A colour Image or CompressedImage message as ``(H, W, 3) uint8`` RGB."""
    import cv2

    if msg.__msgtype__.endswith("CompressedImage"):
        image = cv2.imdecode(np.asarray(msg.data, dtype=np.uint8), cv2.IMREAD_COLOR)
        if image is None:
            raise InputError(path, f"cannot decode a compressed colour image ({msg.format})")
        return np.ascontiguousarray(image[..., ::-1])
    enc = msg.encoding.lower()
    channels = {"rgb8": 3, "bgr8": 3, "rgba8": 4, "bgra8": 4, "mono8": 1, "8uc3": 3}
    buf = np.asarray(msg.data, dtype=np.uint8)
    if enc in ("yuyv", "yuv422_yuy2", "yuv422"):
        pixels = buf.reshape(msg.height, msg.step)[:, :msg.width * 2].reshape(msg.height,
                                                                            msg.width, 2)
        code = cv2.COLOR_YUV2RGB_UYVY if enc == "yuv422" else cv2.COLOR_YUV2RGB_YUYV
        return cv2.cvtColor(np.ascontiguousarray(pixels), code)
    if enc not in channels:
        raise InputError(path, f"colour encoding {msg.encoding!r} is not read (rgb8, bgr8, "
                               "rgba8, bgra8, mono8, yuyv)")
    n = channels[enc]
    image = buf.reshape(msg.height, msg.step)[:, :msg.width * n].reshape(msg.height,
                                                                        msg.width, n)
    if n == 1:
        image = np.repeat(image, 3, axis=2)
    elif enc.startswith("bgr") or enc == "8uc3":
        image = image[..., 2::-1]
    return np.ascontiguousarray(image[..., :3])


def decode_depth(msg, path: Path) -> tuple[np.ndarray, bool]:
    """A depth Image message as ``(H, W)`` uint16 units, or float32 metres; the flag says which
    (True: metres)."""
    enc = msg.encoding.lower()
    if enc in ("16uc1", "mono16", "z16"):
        dtype, metres = np.dtype(">u2" if msg.is_bigendian else "<u2"), False
    elif enc == "32fc1":
        dtype, metres = np.dtype(">f4" if msg.is_bigendian else "<f4"), True
    else:
        raise InputError(path, f"depth encoding {msg.encoding!r} is not read (16UC1, mono16, "
                               "32FC1)")
    rows = np.asarray(msg.data, dtype=np.uint8).reshape(msg.height, msg.step)
    image = rows[:, :msg.width * dtype.itemsize].copy().view(dtype).reshape(msg.height,
                                                                           msg.width)
    return image.astype(np.float32 if metres else np.uint16), metres


def _pairs(colour: list[int], depth: list[int]) -> list[tuple[int, int]]:
    """(colour index, depth index) pairs: each depth stamp with the nearest colour stamp within
    half the median colour interval; each colour image used once; in time order."""
    if not colour or not depth:
        return []
    order = sorted(range(len(colour)), key=colour.__getitem__)
    sorted_c = [colour[i] for i in order]
    gaps = np.diff(sorted_c)
    tolerance = 0.5 * float(np.median(gaps[gaps > 0])) if (gaps > 0).any() else 20e6
    used: set[int] = set()
    pairs = []
    for j, t in sorted(enumerate(depth), key=lambda x: x[1]):
        k = bisect.bisect_left(sorted_c, t)
        near = [i for i in (k - 1, k) if 0 <= i < len(sorted_c)]
        best = min(near, key=lambda i: abs(sorted_c[i] - t))
        if abs(sorted_c[best] - t) <= tolerance and order[best] not in used:
            used.add(order[best])
            pairs.append((order[best], j))
    return pairs


def _select(pairs, colour_stamps, selection: Selection) -> list[tuple[int, int]]:
    if not pairs:
        return []
    t0 = colour_stamps[pairs[0][0]]
    kept = []
    for p in pairs:
        t = (colour_stamps[p[0]] - t0) * 1e-9
        if selection.start is not None and t < selection.start:
            continue
        if selection.end is not None and t > selection.end:
            continue
        kept.append(p)
    kept = kept[::selection.every]
    return kept[:selection.limit] if selection.limit is not None else kept


def import_recording(path: Path, out: Path, selection: Selection | None = None, *,
                     colour_topic: str | None = None, depth_topic: str | None = None,
                     info_topic: str | None = None, depth_scale: float | None = None) -> int:
    """Write ``out/{rgb,depth}/<NNNNNN>.png``, ``out/camera.json`` (colour K, size, depth scale)
    and ``out/recording.json`` (topics, stamp of each frame); returns the frames written.

    Raises :class:`InputError` (naming ``path``) when the recording cannot be read, lacks a
    stream or camera info, or holds depth not aligned to colour.
    """
    AnyReader, default_types = import_rosbags()
    from rosbags.highlevel import AnyReaderError

    selection = selection or Selection()
    path = Path(path)
    paths = recording_paths(path)
    try:
        reader = AnyReader(paths, default_typestore=default_types)
        reader.open()
    except Exception as exc:  # rosbags raises several types for a damaged file
        raise InputError(path, f"cannot read the recording ({type(exc).__name__}: "
                               f"{exc})") from None
    try:
        return _import(reader, path, out, selection, colour_topic, depth_topic, info_topic,
                       depth_scale)
    except AnyReaderError as exc:
        raise InputError(path, f"cannot read the recording ({exc})") from None
    finally:
        reader.close()


def _import(reader, path, out, selection, colour_topic, depth_topic, info_topic, depth_scale):
    topics = {c.topic: c.msgtype for c in reader.connections}
    chosen = find_topics(topics, path, colour=colour_topic, depth=depth_topic, info=info_topic)
    if chosen.colour_info is None:
        raise InputError(path, f"no camera_info recorded for {chosen.colour} (record it, or "
                               "name it with --info-topic)")
    wanted = {chosen.colour, chosen.depth, chosen.colour_info, chosen.depth_info,
              chosen.depth_units} - {None}
    conns = [c for c in reader.connections if c.topic in wanted]
    streams = {name: _Stream() for name in (chosen.colour, chosen.depth)}
    first: dict[str, object] = {}
    for conn, t, raw in reader.messages(connections=conns):
        if conn.topic in streams:
            msg = reader.deserialize(raw, conn.msgtype)
            streams[conn.topic].stamps.append(_stamp(msg, t))
        elif conn.topic not in first:
            first[conn.topic] = reader.deserialize(raw, conn.msgtype)
    if chosen.colour_info not in first:
        raise InputError(path, f"no message on {chosen.colour_info}")
    K, width, height, D = _info_K(first[chosen.colour_info])
    if np.any(np.abs(D) > 1e-6):
        log.warning("notice: %s: colour distortion %s is ignored (sr3d uses a pinhole camera)",
                    path, np.round(D, 5).tolist())
    _check_aligned(path, chosen, first, K, width, height)
    scale = depth_scale
    if scale is None and chosen.depth_units in first:
        scale = float(first[chosen.depth_units].data)
    scale = scale or 0.001
    cs, ds = streams[chosen.colour].stamps, streams[chosen.depth].stamps
    keep = _select(_pairs(cs, ds), cs, selection)
    if not keep:
        raise InputError(path, f"no depth image on {chosen.depth} within half a frame of a "
                               f"colour image on {chosen.colour} in the range asked")
    return _write(reader, path, out, chosen, conns, keep, cs, K, width, height, scale)


def _check_aligned(path, chosen: Topics, first, K, width, height) -> None:
    if any(mark in chosen.depth for mark in ALIGNED_MARKS):
        return
    info = first.get(chosen.depth_info)
    if info is not None:
        Kd, wd, hd, _ = _info_K(info)
        if (wd, hd) == (width, height) and np.allclose(Kd, K, atol=1e-3):
            return
        why = (f"depth {chosen.depth} is {wd}x{hd} with fx {Kd[0, 0]:.2f}, colour "
               f"{width}x{height} with fx {K[0, 0]:.2f}")
    else:
        why = f"{chosen.depth} is not an aligned stream and has no camera_info to check"
    raise InputError(path, f"depth is not aligned to colour ({why}): {RECORD_ALIGNED}")


def _write(reader, path, out, chosen: Topics, conns, keep, colour_stamps, K, width, height,
           scale) -> int:
    want_c = {c: n for n, (c, _) in enumerate(keep)}
    want_d = {d: n for n, (_, d) in enumerate(keep)}
    pending: dict[int, dict[str, np.ndarray]] = {}
    index = {chosen.colour: -1, chosen.depth: -1}
    written = 0
    frames = {}
    image_conns = [c for c in conns if c.topic in index]
    for conn, _, raw in reader.messages(connections=image_conns):
        index[conn.topic] += 1
        i = index[conn.topic]
        is_colour = conn.topic == chosen.colour
        n = (want_c if is_colour else want_d).get(i)
        if n is None:
            continue
        msg = reader.deserialize(raw, conn.msgtype)
        slot = pending.setdefault(n, {})
        if is_colour:
            slot["rgb"] = decode_colour(msg, path)
        else:
            depth, metres = decode_depth(msg, path)
            if metres:
                depth = np.round(np.nan_to_num(depth, nan=0.0, posinf=0.0, neginf=0.0)
                                 / 0.001).clip(0, 65535).astype(np.uint16)
            slot["depth"] = depth
            slot["metres"] = metres
        if len(slot) == 3:
            rgb, depth = slot["rgb"], slot["depth"]
            for name, image in (("colour", rgb), ("depth", depth)):
                if image.shape[:2] != (height, width):
                    raise InputError(path, f"{name} image is {image.shape[1]}x{image.shape[0]} "
                                           f"but the camera info says {width}x{height}")
            fid = f"{n:06d}"
            write_png(out / "rgb" / f"{fid}.png", rgb)
            write_png(out / "depth" / f"{fid}.png", depth)
            frames[fid] = {"stamp_ns": colour_stamps[keep[n][0]]}
            if slot["metres"]:
                scale = 0.001
            del pending[n]
            written += 1
    write_json(out / "camera.json", {"K": K.tolist(), "width": width, "height": height,
                                     "depth_scale": float(f"{scale:.7g}")})
    write_json(out / "recording.json", {
        "source": str(path), "frames": frames,
        "topics": {"colour": chosen.colour, "depth": chosen.depth,
                   "camera_info": chosen.colour_info}})
    return written
