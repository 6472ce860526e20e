"""Grasp studies on generated seeds: which objects a change wins or loses, by class.

Not a test and not part of ``make bench``: a developer's tool for trying a change on whole
frames before it goes near the held-out set. Sets and outputs live under bench/work/study/.

    bench/study.py run SEED... --tag TAG [--grasp-only BASE] [--set grasp.seeds=128]
        the whole default pipeline (or, with --grasp-only, only the grasp stage on a copy of
        run BASE's stage outputs) on the first --frames frames of each seed, --draws planner
        draws each; every true object's outcome per draw goes to res{SEED}_{TAG}.json
    bench/study.py compare TAG [TAG2] --seeds SEED...
        top-1 by class (object-draws held / judged) of one run, or of two side by side with
        the objects whose count changed

Seeds looked at often get easier than new ones (see ``BREAKDOWN_SEED`` in run.py): a change
tuned there loses on new seeds what it seemed to win. Try changes on fresh seeds (seeds
already used are listed in bench/HISTORY.md), and read the held-out set only as totals.
"""

from __future__ import annotations

import argparse
import json
import shutil
import sys
from collections import defaultdict

from run import GRASP_DRAWS, ROOT, _planners, _repair, generated_set

from sr3d_cli import stages
from sr3d_cli.config import Config, IOConfig, SynthConfig, build_config
from sr3d_cli.io.formats import discover_scenes
from sr3d_cli.pipeline import Pipeline
from sr3d_cli.render import make_renderer

WORK = ROOT / "work" / "study"
FID = "000000"


def run(seed: int, tag: str, frames: int, draws: int, grasp_only: str | None,
        cfg: Config) -> tuple[int, int]:
    """One seed's frames through the pipeline (or its grasp stage), judged per draw; returns
    (object-draws held, judged)."""
    folder = WORK / f"set{seed}"
    generated_set(folder, frames, SynthConfig(seed=seed, views=1), make_renderer("auto"))
    out = WORK / f"out{seed}_{tag}"
    shutil.rmtree(out, ignore_errors=True)  # a rerun of a tag starts afresh: no stale stages
    if grasp_only:
        shutil.copytree(WORK / f"out{seed}_{grasp_only}", out)
    pipeline = Pipeline(cfg)
    planners = _planners(cfg)[:draws]
    results: dict[str, dict[str, list[bool]]] = {}
    for source in discover_scenes(folder, IOConfig(), out):
        index = int(source.name.rsplit("_", 1)[-1])
        if index >= frames:
            continue
        if not grasp_only:
            _repair(pipeline, source.load_frame(FID))
        held = {str(o["id"]): [] for o in source.load_gt_objects(FID)["objects"]}
        for planner in planners:
            stages.grasp_frame(source.load_frame(FID), planner, cfg.plane, "repaired")
            top1 = stages.evaluate_grasp_frame(source, FID, cfg)["top1"]
            for k in held:
                held[k].append(bool(top1.get(k)))  # None (no grasp on it): not held
        results[str(index)] = held
        print(seed, source.name, sum(map(sum, held.values())), "of",
              sum(map(len, held.values())), file=sys.stderr)
    (WORK / f"res{seed}_{tag}.json").write_text(json.dumps(results))
    return (sum(sum(map(sum, h.values())) for h in results.values()),
            sum(sum(map(len, h.values())) for h in results.values()))


def outcomes(tag: str, seeds: list[int]) -> dict[tuple[int, int, int], tuple[str, list[bool]]]:
    """(seed, frame, object id) -> (class, held per draw) of a run."""
    found = {}
    for seed in seeds:
        path = WORK / f"res{seed}_{tag}.json"
        if not path.is_file():
            continue
        for frame, held in json.loads(path.read_text()).items():
            truth = WORK / f"set{seed}" / f"scene_{int(frame):04d}" / "gt" / "objects" / \
                f"{FID}.json"
            classes = {str(o["id"]): stages.object_class(o)
                       for o in json.loads(truth.read_text())["objects"]}
            for k, draws in held.items():
                found[(seed, int(frame), int(k))] = (classes[k], draws)
    return found


def compare(tags: list[str], seeds: list[int]) -> list[str]:
    """Lines of a by-class table over the objects every run has, then the changed objects."""
    runs = [outcomes(tag, seeds) for tag in tags]
    common = sorted(set(runs[0]).intersection(*runs[1:]))
    table: dict[str, list[list[int]]] = defaultdict(lambda: [[0, 0] for _ in runs])
    for key in common:
        for i, found in enumerate(runs):
            cls, draws = found[key]
            for row in (cls, "all"):
                table[row][i][0] += sum(draws)
                table[row][i][1] += len(draws)
    lines = [f"{'class':14s} " + "  ".join(f"{tag:>17s}" for tag in tags)]
    for cls in sorted(table, key=lambda c: (c == "all", c)):
        lines.append(f"{cls:14s} " + "  ".join(f"{h:5d}/{n:<5d} {h / n:.3f}"
                                                for h, n in table[cls]))
    if len(runs) == 2:
        for key in common:
            (cls, a), (_, b) = runs[0][key], runs[1][key]
            if sum(a) != sum(b):
                lines.append(f"seed {key[0]} frame {key[1]} object {key[2]} ({cls}): "
                             f"{sum(a)} -> {sum(b)}")
    return lines


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    sub = parser.add_subparsers(dest="command", required=True)
    p_run = sub.add_parser("run")
    p_run.add_argument("seeds", type=int, nargs="+")
    p_run.add_argument("--tag", required=True)
    p_run.add_argument("--frames", type=int, default=24)
    p_run.add_argument("--draws", type=int, default=4, choices=range(1, GRASP_DRAWS + 1))
    p_run.add_argument("--grasp-only", metavar="BASE")
    p_run.add_argument("--set", action="append", default=[], metavar="SECTION.KEY=VALUE")
    p_cmp = sub.add_parser("compare")
    p_cmp.add_argument("tags", nargs="+")
    p_cmp.add_argument("--seeds", type=int, nargs="+", required=True)
    args = parser.parse_args(argv)
    if args.command == "run":
        cfg = build_config(sets=args.set)
        for seed in args.seeds:
            held, judged = run(seed, args.tag, args.frames, args.draws, args.grasp_only, cfg)
            print(f"seed {seed} {args.tag}: {held} of {judged} object-draws held")
    else:
        print("\n".join(compare(args.tags, args.seeds)))


if __name__ == "__main__":
    main()
