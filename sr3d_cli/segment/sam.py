"""Segment Anything through onnxruntime, prompted with boxes or points.

Tensors of the standard export (the SAM repository's ``export_onnx_model`` decoder and an encoder
exported beside it):

- encoder: image ``(1, 3, 1024, 1024)`` float32, RGB normalised with ImageNet mean/std, longest
  side resized to 1024 and zero-padded bottom/right -> ``image_embeddings (1, 256, 64, 64)``;
- decoder: ``image_embeddings``, ``point_coords (1, N, 2)`` in the resized frame,
  ``point_labels (1, N)`` (foreground point 1, box corners 2 and 3, padding point -1),
  ``mask_input (1, 1, 256, 256)``, ``has_mask_input (1,)``, ``orig_im_size (2,)`` ->
  ``masks (1, M, H, W)`` logits at the original size, ``iou_predictions (1, M)``,
  ``low_res_masks``.
"""

from __future__ import annotations

import cv2
import numpy as np

from sr3d_cli.onnx_model import OnnxModel

SIZE = 1024
MEAN = np.array([123.675, 116.28, 103.53], np.float32)
STD = np.array([58.395, 57.12, 57.375], np.float32)

ENCODER_IO = ({"*": (1, 3, SIZE, SIZE)}, {"image_embeddings": (1, 256, 64, 64)})
DECODER_IO = (
    {"image_embeddings": (1, 256, 64, 64), "point_coords": (1, None, 2),
     "point_labels": (1, None), "mask_input": (1, 1, 256, 256), "has_mask_input": (1,),
     "orig_im_size": (2,)},
    {"masks": (1, None, None, None), "iou_predictions": (1, None), "low_res_masks": None},
)


class SamOnnx:
    def __init__(self, encoder_path: str, decoder_path: str):
        self.encoder = OnnxModel(encoder_path, "SAM encoder", *ENCODER_IO)
        self.decoder = OnnxModel(decoder_path, "SAM decoder", *DECODER_IO)

    @staticmethod
    def preprocess(rgb: np.ndarray) -> tuple[np.ndarray, float]:
        """RGB ``(H, W, 3) uint8`` -> encoder input ``(1, 3, 1024, 1024)`` and the resize factor."""
        h, w = rgb.shape[:2]
        scale = SIZE / max(h, w)
        nh, nw = int(round(h * scale)), int(round(w * scale))
        resized = cv2.resize(rgb, (nw, nh), interpolation=cv2.INTER_LINEAR).astype(np.float32)
        padded = np.zeros((SIZE, SIZE, 3), np.float32)
        padded[:nh, :nw] = (resized - MEAN) / STD
        return padded.transpose(2, 0, 1)[None], scale

    def embed(self, rgb: np.ndarray) -> tuple[np.ndarray, float]:
        image, scale = self.preprocess(rgb)
        return self.encoder.run({"*": image})["image_embeddings"], scale

    def segment_box(self, embedding: np.ndarray, scale: float, box: np.ndarray,
                    shape: tuple[int, int]) -> tuple[np.ndarray, float]:
        """Mask ``(H, W) bool`` and predicted IoU for a box ``[x0, y0, x1, y1]`` (pixels)."""
        x0, y0, x1, y1 = (float(v) for v in box)
        coords = np.array([[[x0, y0], [x1, y1], [0.0, 0.0]]], np.float32) * scale
        return self.decode(embedding, coords, np.array([[2, 3, -1]], np.float32), shape)

    def segment_point(self, embedding: np.ndarray, scale: float, point: np.ndarray,
                      shape: tuple[int, int]) -> tuple[np.ndarray, float]:
        """Mask ``(H, W) bool`` and predicted IoU for one foreground point ``[x, y]`` (pixels)."""
        x, y = (float(v) for v in point)
        coords = np.array([[[x, y], [0.0, 0.0]]], np.float32) * scale
        return self.decode(embedding, coords, np.array([[1, -1]], np.float32), shape)

    def decode(self, embedding: np.ndarray, coords: np.ndarray, labels: np.ndarray,
               shape: tuple[int, int]) -> tuple[np.ndarray, float]:
        """The decoder's best mask ``(H, W) bool`` and its predicted IoU for prompts ``coords``
        ``(1, N, 2)`` (resized frame) with ``labels`` ``(1, N)``."""
        out = self.decoder.run({
            "image_embeddings": embedding.astype(np.float32), "point_coords": coords,
            "point_labels": labels, "mask_input": np.zeros((1, 1, 256, 256), np.float32),
            "has_mask_input": np.zeros(1, np.float32),
            "orig_im_size": np.array(shape, np.float32),
        })
        masks, ious = np.asarray(out["masks"]), np.asarray(out["iou_predictions"]).reshape(-1)
        if masks.ndim != 4 or masks.shape[2:] != tuple(shape):
            raise ValueError(f"SAM decoder returned masks of shape {masks.shape}; expected "
                             f"(1, M, {shape[0]}, {shape[1]})")
        best = int(np.argmax(ious)) if ious.size else 0
        return masks[0, best] > 0, float(ious[best]) if ious.size else 0.0
