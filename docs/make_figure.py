"""Make docs/repair.png, the README's picture: RGB with the found objects outlined | raw depth |
repaired depth, for one bundled sample frame.

    python docs/make_figure.py [SCENE] [--out docs/repair.png]

It runs ``sr3d repair-depth SCENE --preview`` into build/figure/ (the sample folder is left as it
is), scales the preview to 1200 px wide and labels the three panels.
"""

from __future__ import annotations

import argparse
import subprocess
import sys
from pathlib import Path

import cv2
import numpy as np
from PIL import Image

ROOT = Path(__file__).resolve().parents[1]
LABELS = ("RGB (objects found)", "raw depth", "repaired depth")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("scene", nargs="?", default=str(ROOT / "sample_data" / "scene_0003"))
    parser.add_argument("--out", default=str(ROOT / "docs" / "repair.png"))
    parser.add_argument("--width", type=int, default=1200)
    args = parser.parse_args()

    work = ROOT / "build" / "figure"
    subprocess.run([sys.executable, "-m", "sr3d_cli", "repair-depth", args.scene, "--out",
                    str(work), "--preview", "-q"], check=True)
    preview = sorted((work / "repaired").glob("*_preview.png"))[0]
    image = cv2.imread(str(preview), cv2.IMREAD_COLOR)  # BGR, three panels side by side
    h, w = image.shape[:2]
    height = round(h * args.width / w)
    image = cv2.resize(image, (args.width, height), interpolation=cv2.INTER_AREA)
    panel = args.width / len(LABELS)
    for i, label in enumerate(LABELS):
        x = int(i * panel)
        (tw, th), _ = cv2.getTextSize(label, cv2.FONT_HERSHEY_SIMPLEX, 0.5, 1)
        cv2.rectangle(image, (x, 0), (x + tw + 12, th + 12), (0, 0, 0), -1)
        cv2.putText(image, label, (x + 6, th + 6), cv2.FONT_HERSHEY_SIMPLEX, 0.5,
                    (255, 255, 255), 1, cv2.LINE_AA)
    # 128 colours keep the file small; the depth colour maps are smooth ramps
    rgb = Image.fromarray(np.ascontiguousarray(image[..., ::-1]))
    Path(args.out).parent.mkdir(parents=True, exist_ok=True)
    rgb.quantize(128, dither=Image.Dither.NONE).save(args.out, optimize=True)
    print(f"{args.out}: {args.width}x{height}, {Path(args.out).stat().st_size // 1024} KiB")


if __name__ == "__main__":
    main()
