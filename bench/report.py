"""bench/RESULTS.md and bench/mae.png from the results of :mod:`run`'s sections."""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np

import generalise
from common import OTHER_CONTACTS


def _breakdown_report(breakdown: dict, title: str, frames: str) -> list[str]:
    """The section of a breakdown (``bench/run.py breakdown`` or ``extbreakdown``) titled
    ``title``, its ``frames`` said in words."""
    if not breakdown:
        return []
    draws = len(next(iter(breakdown["conditions"].values()))["grasp"]["top1_by_draw"])
    lines = [f"## {title}", "",
             f"{breakdown['frames']} {frames}; the same planner on the true meshes at "
             "their true poses with the true depth, on sr3d's reconstruction and placement "
             "from the true masks, and on the whole pipeline; judged as above, mean of "
             f"{draws} draws. Depth over the true object masks.", "",
             "| grasps planned on | objects | REL | MAE mm | top-1 | top-10 |" + _OTHER_HEAD,
             "|---|---|---|---|---|---|" + _OTHER_RULE]
    for name, c in breakdown["conditions"].items():
        d, g = c["depth"], c["grasp"]
        lines.append(f"| {name} | {g['objects']} | {d['rel']:.4f} | {1000 * d['mae']:.1f} | "
                     f"{g['top1_success']:.3f} | {g['top10_success']:.3f} |{_others(g)}")
    conditions = breakdown["conditions"]
    lines += ["", "Top-1 by object class, contacts by the grid:", ""]
    lines += _class_table({name: c["grasp"] for name, c in conditions.items()})
    if all("merged" in c for c in conditions.values()):
        m = next(iter(conditions.values()))["merged"]
        lines += ["", "Top-1 of the objects sr3d's segmenter merged with another (its instance "
                  "covers 30% of another object too) and of the rest, contacts by the grid:", "",
                  "| objects | " + " | ".join(conditions) + " |", "|---|" + "---|" * len(conditions),
                  f"| merged ({m['objects']}) | " + " | ".join(
                      f"{c['merged']['top1_success']:.3f}" for c in conditions.values()) + " |",
                  f"| the rest ({m['rest_objects']}) | " + " | ".join(
                      f"{c['merged']['rest_top1_success']:.3f}" for c in conditions.values())
                  + " |"]
    apart = next(iter(conditions.values())).get("apart", {})
    if all("apart" in c for c in conditions.values()) and apart["grid"]["rim only"]["objects"]:
        first = apart["grid"]
        lines += ["", "Top-1 of the objects only a pinch across the rim can hold (`rim_only`) and "
                  "of the others, by each contact model:", "",
                  "| objects | contacts | " + " | ".join(conditions) + " |",
                  "|---|---|" + "---|" * len(conditions)]
        for group in ("rim only", "others"):
            for model in apart:
                lines.append(f"| {group} ({first[group]['objects']}) | {model} | " + " | ".join(
                    f"{c['apart'][model][group]['top1_success']:.3f}"
                    for c in conditions.values()) + " |")
    return lines + [""]


def _class_table(columns: dict[str, dict]) -> list[str]:
    """A table of top-1 by object class, one column per grasp summary in ``columns``."""
    first = next(iter(columns.values())).get("top1_by_class", {})
    if not first:
        return ["(no classes: results.json predates them)"]
    lines = ["| class | objects | " + " | ".join(columns) + " |",
             "|---|---|" + "---|" * len(columns)]
    for name, t in first.items():
        cells = " | ".join(f"{g['top1_by_class'][name]['top1_success']:.3f}"
                           if name in g.get("top1_by_class", {}) else "-"
                           for g in columns.values())
        lines.append(f"| {name} | {t['objects']} | {cells} |")
    return lines


_OTHER_HEAD = "".join(f" {m}: top-1 | top-10 |" for m in OTHER_CONTACTS)
_OTHER_RULE = "---|---|" * len(OTHER_CONTACTS)


def _others(g: dict) -> str:
    """Top-1 and top-10 by each of :data:`OTHER_CONTACTS` as more table cells."""
    return "".join(f" {g[m]['top1_success']:.3f} | {g[m]['top10_success']:.3f} |"
                   if m in g else " - | - |" for m in OTHER_CONTACTS)


def write_report(results: dict, methods, out: Path) -> None:
    lines = ["# sr3d benchmark", "",
             "Written by `make bench` (bench/run.py). The first two sections are the headline: "
             "data sr3d was not built on (bench/generalise.py). The sections after them are "
             "regression checks on sr3d's own generator, and the real frames with their true "
             "masks given.", "",
             *generalise.report(results),
             "## own generator and real frames with true masks", "",
             "Depth metrics over the ground-truth object "
             "masks, holes counted with full error, mean over frames (median MAE separately). "
             "Synthetic: 24 frames, seed 700, full default pipeline (training-free segment -> "
             "revolution reconstruct -> align -> repair). Real: the two ClearGrasp frames of "
             "../shared/realdata/cleargrasp-real, true masks imported. `paper` = same pipeline with `align.mode: "
             "paper` (162 viewpoints x 4 rolls, to keep the run short).", ""]
    for label in ("synthetic", "real"):
        r = results[label]
        if not r:  # the depth section has not run into this folder
            continue
        lines.append(f"## {label}")
        if "skipped" in r:
            lines += [f"skipped: {r['skipped']}", ""]
            continue
        lines += ["", "| method | RMSE m | REL | MAE m | median MAE mm | d<1.05 % | d<1.10 % | "
                      "d<1.25 % |", "|---|---|---|---|---|---|---|---|"]
        for m in methods:
            x = r[m]
            lines.append(f"| {m} | {x['rmse']:.4f} | {x['rel']:.4f} | {x['mae']:.4f} | "
                         f"{1000 * r['median_mae'][m]:.1f} | {x['delta_1.05']:.1f} | "
                         f"{x['delta_1.10']:.1f} | {x['delta_1.25']:.1f} |")
        lines.append("")
        for name, t in results["timings"].get(label, {}).items():
            lines.append(f"- median seconds per frame, {name}: " + ", ".join(
                f"{k} {v:.3f}" for k, v in t.items()))
        lines.append("")
    lines += ["## align alone (synthetic, ground-truth masks and meshes)", "",
              "| mode | objects | failed | rotation deg | translation mm | scale % | ADD-S mm "
              "| s/object |", "|---|---|---|---|---|---|---|---|"]
    for mode, p in results["poses"].items():
        add_s = f"{p['median_add_s_mm']:.1f}" if "median_add_s_mm" in p else "-"
        lines.append(f"| {mode} | {p['objects']} | {p['failed']} | {p['median_rotation_deg']:.2f} "
                     f"| {p['median_translation_mm']:.1f} | {p['median_scale_pct']:.2f} | "
                     f"{add_s} | {p['median_seconds']:.2f} |")
    lines += ["", "Rotation error of axially symmetric objects is the axis angle; ADD-S: mean "
              "distance from the true surface to the placed one (`sr3d_cli/pose_error.py`, as "
              "`sr3d evaluate` reports it). Medians; seconds: the aligner's.", ""]
    grasp = results.get("grasp", {})
    if grasp:
        lines += ["## grasps (synthetic, sr3d's masks; judged on the true meshes)", "",
                  f"Friction {grasp['friction']}: jaws closed on the true meshes, force closure, "
                  "collisions with the true scene and table. Top-1: the best grasp of each true "
                  "object (no grasp counts as a failure). Top-10: mean over frames of the 10 best "
                  "grasps' success. Contacts by a grid of 6 x 3 rays on each pad; the same "
                  "grasps also judged by `pads` (each whole flat pad's exact first touch, a corner "
                  "it presses on taking its normal) and "
                  "`line` (one ray per jaw on the closing line through the grasp centre, as "
                  "GraspNet-1Billion's metric); see `sr3d_cli/grasp/quality.py`.", "",
                  "| planned on | objects | with grasps | top-1 success | top-10 success |"
                  + _OTHER_HEAD, "|---|---|---|---|---|" + _OTHER_RULE]
        for name in ("repaired", "raw"):
            g = grasp[name]
            lines.append(f"| {name} | {g['objects']} | {g['objects_with_grasps']:g} | "
                         f"{g['top1_success']:.3f} | {g['top10_success']:.3f} |{_others(g)}")
        by_draw = ", ".join(f"{v:.3f}" for v in grasp["repaired"].get("top1_by_draw", []))
        lines += ["", f"- repaired: the mean of {len(grasp['repaired'].get('top1_by_draw', []))} "
                  f"random draws of seed points (`grasp.seed` 0, 1, ...); top-1 by draw: "
                  f"{by_draw}; raw: draw 0",
                  f"- grasp stage, median seconds per frame on one core: "
                  f"{grasp['median_seconds']:.3f}", "",
                  "Top-1 on the repaired scene by object class, by each contact model:", ""]
        g = grasp["repaired"]
        lines += _class_table({"grid": g, **{m: g[m] for m in OTHER_CONTACTS if m in g}}) + [""]
    held = results.get("heldout", {})
    if held:
        d, g = held["depth"], held["grasp"]
        lines += [f"## held-out set (seed {held['seed']}: read only as these totals)", "",
                  f"{held['frames']} generated frames, the whole default pipeline from the raw "
                  "frame (sr3d's own masks) to grasps, judged as above. The seed-700 set above "
                  "is the one sr3d's parameters were tuned on and seed 900 the one failures are "
                  "studied on; expect these numbers on new frames.", "",
                  "| objects | REL | MAE mm | median MAE mm | grasp top-1 | top-10 |"
                  + _OTHER_HEAD, "|---|---|---|---|---|---|" + _OTHER_RULE,
                  f"| {g['objects']} | {d['rel']:.4f} | {1000 * d['mae']:.1f} | "
                  f"{1000 * held['median_mae']:.1f} | {g['top1_success']:.3f} | "
                  f"{g['top10_success']:.3f} |{_others(g)}", "",
                  "- grasp top-1 by draw: " + ", ".join(f"{v:.3f}" for v in g["top1_by_draw"])]
        apart = held.get("grasp_apart")
        if apart:
            rim, rest = apart["rim only"], apart["others"]
            lines += [f"- top-1 of the {rim['objects']} objects only a pinch across the rim can "
                      f"hold (beakers and glasses wider than the opening less its margins, lying "
                      f"ones also longer; `rim_only`): {rim['top1_success']:.3f}; of the other "
                      f"{rest['objects']}: {rest['top1_success']:.3f}"]
        lines += [""]
    breakdown = results.get("breakdown", {})
    lines += _breakdown_report(breakdown, f"where grasps are lost (study seed "
                               f"{breakdown.get('seed')}, `bench/run.py breakdown`)",
                               "generated frames")
    lines += _breakdown_report(results.get("extbreakdown", {}), "where grasps are lost on the "
                               "independent renderer (`bench/run.py extbreakdown`)",
                               "frames of ../shared/extsim (scanned meshes, some open surfaces)")
    mesh = results.get("mesh", {})
    if mesh:
        lines += ["## segmentation and reconstruction (default backends)", "",
                  "Segmentation: best IoU of each ground-truth instance; detected = IoU > 0.5; "
                  "precision = share of predicted instances with IoU > 0.5 against some "
                  "ground-truth instance (the rest are false detections or fragments). "
                  "Reconstruction: ground-truth masks and support plane, symmetric Chamfer "
                  "distance / height against the true mesh (both at unit height), median.", "",
                  "| set | instances | mean IoU | detection % | predicted | precision % |",
                  "|---|---|---|---|---|---|"]
        for label in ("synthetic", "real"):
            m = mesh.get(label, {})
            if "skipped" in m or not m:
                lines.append(f"| {label} | skipped: {m.get('skipped', 'not run')} | | | | |")
                continue
            lines.append(f"| {label} | {m['instances']} | {m['mean_iou']:.3f} | "
                         f"{100 * m['detection']:.1f} | {m.get('predicted', '-')} | "
                         + (f"{100 * m['precision']:.1f} |" if "precision" in m else "- |"))
        lines += ["", "| resting | objects | median Chamfer / height % |", "|---|---|---|"]
        for k, v in mesh.get("shape", {}).items():
            lines.append(f"| {k} | {v['objects']} | {100 * v['median_chamfer_per_height']:.2f} |")
        lines.append("")
    scale = results.get("scale", {})
    if scale:
        lines += ["## batch throughput (`sr3d repair-depth --workers N`)", "",
                  f"{scale['frames']} synthetic frames (one scene folder each), a fresh `sr3d` "
                  f"process per run (start-up included), median of {scale['repeats']} runs.", "",
                  "| workers | seconds | frames/s |", "|---|---|---|"]
        for w in (1, 2):
            x = scale[f"workers_{w}"]
            lines.append(f"| {w} | {x['seconds']:.1f} | {x['fps']:.2f} |")
        lines += ["", f"- speed-up with 2 workers: {scale['speedup']:.2f}x", ""]
    speed = results.get("speed", {})
    if speed:
        lines += ["## one object, one core (`sr3d repair-depth` stages)", "",
                  f"{speed['frames']} synthetic 640x480 frames with one glass object (seed 701), "
                  "default backends, the process pinned to one CPU core, models loaded; median "
                  "seconds per frame.", "",
                  "| segment | reconstruct | align | render + write | total | MAE mm |",
                  "|---|---|---|---|---|---|",
                  f"| {speed['segment']:.3f} | {speed['reconstruct']:.3f} | {speed['align']:.3f} "
                  f"| {speed['render']:.3f} | {speed['total']:.3f} | {1000 * speed['mae']:.1f} |",
                  ""]
    (out / "RESULTS.md").write_text("\n".join(lines))


def plot(results: dict, methods, out: Path) -> None:
    """Bar chart of MAE per method (mm), synthetic and real side by side."""
    h, w = 320, 640
    img = np.full((h, w, 3), 255, np.uint8)
    sets = [k for k in ("synthetic", "real") if results[k] and "skipped" not in results[k]]
    values = [[results[s][m]["mae"] * 1000 for m in methods] for s in sets]
    top = max(max(v) for v in values) if values else 1
    colours = [(80, 80, 200), (200, 120, 60)]
    for si, vals in enumerate(values):
        for mi, v in enumerate(vals):
            x = 40 + mi * 120 + si * 45
            y = int(h - 50 - (h - 90) * v / top)
            cv2.rectangle(img, (x, y), (x + 40, h - 50), colours[si], -1)
            cv2.putText(img, f"{v:.0f}", (x, y - 5), cv2.FONT_HERSHEY_SIMPLEX, 0.4, (0, 0, 0), 1)
    for mi, m in enumerate(methods):
        cv2.putText(img, m, (40 + mi * 120, h - 25), cv2.FONT_HERSHEY_SIMPLEX, 0.45, (0, 0, 0), 1)
    cv2.putText(img, "MAE mm: " + " / ".join(sets), (10, 20), cv2.FONT_HERSHEY_SIMPLEX, 0.5,
                (0, 0, 0), 1)
    cv2.imwrite(str(out / "mae.png"), img)
