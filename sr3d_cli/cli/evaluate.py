"""``sr3d evaluate SCENE``: depth metrics against ground truth, several predictions side by side."""

from __future__ import annotations

import math
from pathlib import Path

import click
from tqdm import tqdm

from sr3d_cli.cli.batch import check_writable, iter_frames, open_scenes
from sr3d_cli.cli.options import UsageExit, common_options, load_config, scene_options
from sr3d_cli.cli.report import Report

COLUMNS = ("frames", "pixels", "coverage", "rmse", "rel", "mae",
           "delta_1.05", "delta_1.10", "delta_1.25")
HEADERS = ("frames", "pixels", "valid%", "RMSE", "REL", "MAE", "d<1.05", "d<1.10", "d<1.25")


def _fmt(key: str, value) -> str:
    if value is None or (isinstance(value, float) and math.isnan(value)):
        return "-"
    if key in ("frames", "pixels"):
        return str(int(value))
    if key == "coverage":
        return f"{100 * value:.1f}"
    if key.startswith("delta"):
        return f"{value:.2f}"
    return f"{value:.4f}"


def format_table(means: dict[str, dict], median: bool = False) -> str:
    """The mean table; ``median`` adds the median relative error column."""
    columns, headers = list(COLUMNS), list(HEADERS)
    if median:
        columns.insert(5, "rel_median")
        headers.insert(5, "REL med")
    width = max([4] + [len(p) for p in means])
    lines = [f"{'pred':<{width}}  " + "  ".join(f"{h:>8}" for h in headers)]
    for pred, row in means.items():
        lines.append(f"{pred:<{width}}  " + "  ".join(f"{_fmt(k, row.get(k)):>8}"
                                                    for k in columns))
    return "\n".join(lines)


def _nan_to_none(obj):
    if isinstance(obj, float) and math.isnan(obj):
        return None
    if isinstance(obj, dict):
        return {k: _nan_to_none(v) for k, v in obj.items()}
    if isinstance(obj, list):
        return [_nan_to_none(v) for v in obj]
    return obj


def _csv(frames: dict[str, dict], means: dict[str, dict]) -> str:
    keys = ("pixels", "coverage", "rmse", "rel", "rel_median", "mae", "delta_1.05", "delta_1.10",
            "delta_1.25")

    def row(name: str, pred: str, m: dict) -> str:
        cells = ("" if math.isnan(float(m[k])) else f"{m[k]:.6g}" for k in keys)
        return f"{name},{pred}," + ",".join(cells)

    rows = ["frame,pred," + ",".join(keys)]
    rows += [row(key, pred, m) for key, per_pred in frames.items() for pred, m in per_pred.items()]
    rows += [row("mean", pred, m) for pred, m in means.items()]
    return "\n".join(rows) + "\n"


def _pose_csv(frames: dict[str, dict], summary: dict) -> str:
    """pose_metrics.csv: one row per true object, then the median and mean rows."""
    from sr3d_cli.pose_error import METRICS

    def cells(values) -> str:
        return ",".join("" if v is None or (isinstance(v, float) and math.isnan(v))
                        else f"{v:.6g}" if isinstance(v, float) else str(v) for v in values)

    rows = ["frame,id,label,pred_id,iou,symmetric," + ",".join(METRICS)]
    for key, frame in frames.items():
        for r in frame["objects"]:
            rows.append(f"{key}," + cells([r["id"], r["label"].replace(",", " "), r["pred_id"],
                                           r.get("iou"), r.get("symmetric")]
                                          + [r.get(m) for m in METRICS]))
    for stat in ("median", "mean"):
        rows.append(f"{stat},,,,,," + cells([summary[f"{stat}_{m}"] for m in METRICS]))
    return "\n".join(rows) + "\n"



@click.command()
@click.argument("scene", type=click.Path(exists=True, file_okay=False))
@click.option("--pred", "preds", multiple=True,
              help="Prediction to score: repaired (default), depth (raw sensor), or a folder; "
                   "repeat for a side-by-side table.")
@click.option("--only-valid", is_flag=True, default=None,
              help="Count only pixels where the prediction has a value (default: holes count "
                   "with full error, as ClearGrasp).")
@click.option("--mask", "mask_source", type=click.Choice(["auto", "gt", "pred"]), default=None,
              help="Pixels to score: gt masks, masks/ from segment, or auto (gt, else masks/).")
@click.option("--protocol", type=click.Choice(["native", "transcg", "cleargrasp"]),
              default=None,
              help="How pixels are counted: native (default), transcg (per-image means over "
                   "object and over all pixels, depth 0.3-1.5 m) or cleargrasp (256x144, "
                   "median REL too). See the README.")
@click.option("--resolution", metavar="WxH|native", default=None,
              help="Resize every image (nearest) to WxH before counting, e.g. 320x240 for "
                   "TransCG's tables (default: the protocol's).")
@click.option("--plot", is_flag=True, default=None, help="Write per-frame error maps (PNG).")
@click.option("--grasps", "grasps", is_flag=True,
              help="Score grasps/ instead of depth: jaws closed on the true meshes, force "
                   "closure at grasp.friction; writes grasp_metrics.json.")
@click.option("--contacts", type=click.Choice(["grid", "pads", "line"]), default=None,
              help="With --grasps: how a closing finger's contact is found: rays from a 6 x 3 "
                   "grid on each pad (default; steps over a lip narrower than its 9.4 mm rows), "
                   "each flat pad's exact first touch, or one ray along the closing line "
                   "(GraspNet-1Billion's). See the README.")
@scene_options
@common_options
def evaluate(scene, preds, only_valid, mask_source, protocol, resolution, plot, grasps, contacts,
             out, frames, fmt):
    """Score depth predictions against ground truth over the transparent objects.

    Writes metrics.json and metrics.csv (to --out, else SCENE) and prints the mean table.
    Where the scene has true poses (gt/objects) and placed objects (poses/ from align), also
    scores each placed object's pose: rotation (the axis only for a surface of revolution),
    translation, scale and ADD-S, into metrics.json and pose_metrics.csv.
    With --grasps, scores grasps instead (needs gt/objects: true meshes and poses).

    \b
    Example:
      sr3d evaluate sample_data --pred depth --pred repaired --plot
    """
    if grasps:
        return _evaluate_grasps(scene, out, frames, fmt, contacts or "grid")
    if contacts:
        raise UsageExit("--contacts goes with --grasps")
    from sr3d_cli import evaluate as core
    from sr3d_cli import pose_error
    from sr3d_cli.io.atomic import write_json, write_png, write_text
    from sr3d_cli.io.preview import error_map_figure

    cfg = load_config({
        "evaluate.pred": list(preds) or None, "evaluate.mask": mask_source,
        "evaluate.plot": plot, "evaluate.holes": "ignore" if only_valid else None,
        "evaluate.protocol": protocol, "evaluate.resolution": resolution, "io.format": fmt,
    })
    ev = cfg.evaluate
    proto = core.PROTOCOLS[ev.protocol]
    try:
        size = core.parse_resolution(ev.resolution) if ev.resolution else proto.resolution
    except ValueError as exc:
        raise UsageExit(f"evaluate.resolution: {exc}") from None
    if only_valid and proto.holes is not None:
        raise UsageExit(f"--only-valid does not go with --protocol {proto.name} (it counts "
                        "holes with full error)")
    proto = core.Protocol(proto.name, size, proto.depth_range, proto.pixel_sets, proto.holes,
                          proto.note)
    ctx = click.get_current_context()
    report = Report(verbose=ctx.meta["sr3d.verbose"])
    out_root = Path(out) if out else Path(scene)
    scenes = open_scenes(scene, cfg, out)
    check_writable(out_root)
    pairs = list(iter_frames(scenes, frames, report))
    per_frame: dict[str, dict] = {}
    pose_frames: dict[str, dict] = {}
    for source, frame_id in tqdm(pairs, desc="evaluate", unit="frame",
                                 disable=ctx.meta["sr3d.quiet"]):
        key = source.frame_key(frame_id)
        try:
            result = core.evaluate_frame(source, frame_id, ev.pred, holes=ev.holes,
                                         mask_source=ev.mask, protocol=proto)
            if ev.plot:
                arrays = result["arrays"]
                for pred in ev.pred:
                    image = error_map_figure(
                        core.error_map_image(arrays[pred], arrays["gt"], arrays["mask"],
                                             max_error=ev.plot_max_error), ev.plot_max_error)
                    write_png(source.out / "eval_plots" / Path(pred).name / f"{frame_id}.png",
                              image)
            poses = pose_error.evaluate_frame_poses(source, frame_id)
        except Exception as exc:
            report.fail(key, exc)
            continue
        per_frame[key] = result["preds"]
        if poses is not None:
            pose_frames[key] = poses
        report.ok()
    names = core.result_names(list(ev.pred), proto)
    means = {name: core.mean_metrics([f[name] for f in per_frame.values()]) for name in names}
    document = {
        "protocol": proto.describe(ev.holes),
        "holes": core.HOLES_NOTE[proto.holes or ev.holes],
        "pixels": "inside the object mask (gt/masks, else masks/; ClearGrasp: the -mask.png "
                  "components) where the ground truth is finite and > 0"
                  + ("; rows '<pred>:all': every pixel with valid ground truth"
                     if "all" in proto.pixel_sets else ""),
        "mean": "per-frame metrics averaged over frames with counted pixels",
        "units": {"rmse": "m", "mae": "m", "rel": "mean of |pred - gt| / gt",
                  "rel_median": "median of |pred - gt| / gt", "delta": "percent",
                  "coverage": "share of counted pixels where the prediction is valid"},
        "predictions": list(ev.pred),
        "means": means,
        "frames": per_frame,
        "failed": report.failures,
    }
    pose_summary = None
    if pose_frames:
        pose_summary = pose_error.summarise([r for f in pose_frames.values()
                                             for r in f["objects"]])
        document["poses"] = {"method": pose_error.METHOD, "units": pose_error.UNITS,
                             "summary": pose_summary, "frames": pose_frames}
    try:
        write_json(out_root / "metrics.json", _nan_to_none(document))
        write_text(out_root / "metrics.csv", _csv(per_frame, means))
        if pose_summary is not None:
            write_text(out_root / "pose_metrics.csv", _pose_csv(pose_frames, pose_summary))
    except OSError as exc:
        raise UsageExit(f"{out_root}: cannot write metrics ({exc.strerror or exc}); "
                        "use --out DIR") from None
    described = proto.describe(ev.holes)
    range_note = (f", depth {proto.depth_range[0]:g}-{proto.depth_range[1]:g} m"
                  if proto.depth_range else "")
    click.echo(f"# protocol {proto.name}: {described['resolution']}{range_note}; "
               + "; ".join(f"{'rows <pred>:' + k if k != proto.pixel_sets[0] else 'pixels'}: {v}"
                           for k, v in described["pixel_sets"].items()))
    click.echo(f"# {core.HOLES_NOTE[proto.holes or ev.holes]}")
    click.echo(format_table(means, median=proto.name == "cleargrasp"))
    if pose_summary is not None:
        click.echo(format_poses(pose_summary))
    report.finish("frames")


def format_poses(summary: dict) -> str:
    """The pose summary line: objects placed and the median of each pose error."""
    def cell(key: str, unit: str) -> str:
        value = summary[f"median_{key}"]
        return "-" if math.isnan(value) else f"{value:.1f} {unit}"

    return (f"# poses: {summary['matched']} of {summary['objects']} true objects placed; "
            f"median rotation {cell('rotation_deg', 'deg')} (axis only for surfaces of "
            f"revolution; axis of every object {cell('axis_deg', 'deg')}), translation "
            f"{cell('translation_mm', 'mm')}, scale {cell('scale_pct', '%')}, ADD-S "
            f"{cell('add_s_mm', 'mm')}")


def _evaluate_grasps(scene, out, frames, fmt, contacts: str = "grid"):
    from sr3d_cli.grasp.quality import CONTACTS, overall
    from sr3d_cli.io.atomic import write_json
    from sr3d_cli.stages import evaluate_grasp_frame

    cfg = load_config({"io.format": fmt})
    ctx = click.get_current_context()
    report = Report(verbose=ctx.meta["sr3d.verbose"])
    out_root = Path(out) if out else Path(scene)
    per_frame: dict[str, dict] = {}
    scenes = open_scenes(scene, cfg, out)
    check_writable(out_root)
    pairs = list(iter_frames(scenes, frames, report))
    for source, frame_id in tqdm(pairs, desc="evaluate grasps", unit="frame",
                                 disable=ctx.meta["sr3d.quiet"]):
        try:
            per_frame[source.frame_key(frame_id)] = evaluate_grasp_frame(source, frame_id, cfg,
                                                                         contacts)
        except Exception as exc:
            report.fail(source.frame_key(frame_id), exc)
            continue
        report.ok()
    summary = overall(list(per_frame.values()))
    document = {"friction": cfg.grasp.friction, "contacts": contacts, "overall": summary,
                "frames": per_frame, "failed": report.failures,
                "method": f"jaws closed on the true meshes ({CONTACTS[contacts]}), "
                          "collisions with the true meshes, true depth and table, two-contact "
                          "force closure; top-1 per true object (objects without a grasp "
                          "count as failures), mean success of the 10 best grasps per frame"}
    try:
        write_json(out_root / "grasp_metrics.json", _nan_to_none(document))
    except OSError as exc:
        raise UsageExit(f"{out_root}: cannot write grasp_metrics.json "
                        f"({exc.strerror or exc}); use --out DIR") from None
    click.echo(f"frames {summary['frames']}  objects {summary['objects']}  "
               f"top-1 success {summary['top1_success']:.3f}  "
               f"top-10 mean {summary['top10_success']:.3f}  (friction {cfg.grasp.friction:g})")
    click.echo("success by friction: " + "  ".join(
        f"{k}: {v:.3f}" for k, v in summary["success_by_friction"].items()))
    if summary["top1_by_class"]:
        click.echo("top-1 by class: " + "  ".join(
            f"{name} {t['top1_success']:.3f} ({t['objects']})"
            for name, t in summary["top1_by_class"].items()))
    report.finish("frames")
