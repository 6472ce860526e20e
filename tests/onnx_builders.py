"""Tiny ONNX models built in the tests, so the real loading and inference code runs in CI."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import onnx
from onnx import TensorProto, helper, numpy_helper

OPSET = [helper.make_opsetid("", 17)]


def _save(graph, path: Path) -> Path:
    model = helper.make_model(graph, opset_imports=OPSET)
    model.ir_version = 8
    onnx.checker.check_model(model)
    onnx.save(model, str(path))
    return path


def _const(name, array):
    return numpy_helper.from_array(np.asarray(array), name)


def sam_encoder(path: Path, input_name: str = "input_image") -> Path:
    """image (1, 3, 1024, 1024) -> image_embeddings (1, 256, 64, 64) by a strided convolution."""
    w = np.zeros((256, 3, 16, 16), np.float32)
    w[:, :, 0, 0] = 0.01
    node = helper.make_node("Conv", [input_name, "w"], ["image_embeddings"], strides=[16, 16])
    graph = helper.make_graph(
        [node], "sam_encoder",
        [helper.make_tensor_value_info(input_name, TensorProto.FLOAT, [1, 3, 1024, 1024])],
        [helper.make_tensor_value_info("image_embeddings", TensorProto.FLOAT, [1, 256, 64, 64])],
        [_const("w", w)])
    return _save(graph, path)


def sam_box_decoder(path: Path, masks_name: str = "masks") -> Path:
    """A SAM-shaped decoder whose mask is exactly the prompt box (corners inclusive)."""
    f = TensorProto.FLOAT
    inputs = [
        helper.make_tensor_value_info("image_embeddings", f, [1, 256, 64, 64]),
        helper.make_tensor_value_info("point_coords", f, [1, "n", 2]),
        helper.make_tensor_value_info("point_labels", f, [1, "n"]),
        helper.make_tensor_value_info("mask_input", f, [1, 1, 256, 256]),
        helper.make_tensor_value_info("has_mask_input", f, [1]),
        helper.make_tensor_value_info("orig_im_size", f, [2]),
    ]
    outputs = [
        helper.make_tensor_value_info(masks_name, f, [1, 1, "h", "w"]),
        helper.make_tensor_value_info("iou_predictions", f, [1, 1]),
        helper.make_tensor_value_info("low_res_masks", f, [1, 1, 256, 256]),
    ]
    init = [_const("i0", np.array(0, np.int64)), _const("i1", np.array(1, np.int64)),
            _const("i2", np.array(2, np.int64)), _const("i3", np.array(3, np.int64)),
            _const("flat", np.array([-1], np.int64)), _const("zero", np.array(0.0, np.float32)),
            _const("one", np.array(1.0, np.float32)), _const("k1024", np.array(1024.0, np.float32)),
            _const("twenty", np.array(20.0, np.float32)), _const("ten", np.array(10.0, np.float32)),
            _const("ax0", np.array([0], np.int64)), _const("ax1", np.array([1], np.int64)),
            _const("ax01", np.array([0, 1], np.int64)),
            _const("iou", np.array([[0.9]], np.float32)),
            _const("low", np.zeros((1, 1, 256, 256), np.float32))]
    n = helper.make_node
    nodes = [
        n("Gather", ["orig_im_size", "i0"], ["H"]), n("Gather", ["orig_im_size", "i1"], ["W"]),
        n("Max", ["H", "W"], ["mx"]), n("Div", ["mx", "k1024"], ["f"]),
        n("Reshape", ["point_coords", "flat"], ["pc"]), n("Mul", ["pc", "f"], ["pco"]),
        n("Gather", ["pco", "i0"], ["x0"]), n("Gather", ["pco", "i1"], ["y0"]),
        n("Gather", ["pco", "i2"], ["x1"]), n("Gather", ["pco", "i3"], ["y1"]),
        n("Range", ["zero", "W", "one"], ["xs"]), n("Range", ["zero", "H", "one"], ["ys"]),
        n("GreaterOrEqual", ["xs", "x0"], ["gx"]), n("LessOrEqual", ["xs", "x1"], ["lx"]),
        n("And", ["gx", "lx"], ["inx"]),
        n("GreaterOrEqual", ["ys", "y0"], ["gy"]), n("LessOrEqual", ["ys", "y1"], ["ly"]),
        n("And", ["gy", "ly"], ["iny"]),
        n("Unsqueeze", ["iny", "ax1"], ["col"]), n("Unsqueeze", ["inx", "ax0"], ["row"]),
        n("And", ["col", "row"], ["m"]), n("Cast", ["m"], ["mf"], to=TensorProto.FLOAT),
        n("Mul", ["mf", "twenty"], ["m20"]), n("Sub", ["m20", "ten"], ["logit"]),
        n("Unsqueeze", ["logit", "ax01"], [masks_name]),
        n("Identity", ["iou"], ["iou_predictions"]), n("Identity", ["low"], ["low_res_masks"]),
    ]
    return _save(helper.make_graph(nodes, "sam_decoder", inputs, outputs, init), path)


def density_sphere(path: Path, res: int = 48, radius_grid: float = 0.87, sphere: float = 0.5,
                   size: int = 64) -> Path:
    """image (1, 3, size, size) -> density (1, R, R, R): 100 * (sphere^2 - |p|^2) * 100, so the
    iso-level 25 is the sphere of radius sqrt(sphere^2 - 0.0025)."""
    axis = np.linspace(-radius_grid, radius_grid, res)
    x, y, z = np.meshgrid(axis, axis, axis, indexing="ij")
    density = (1e4 * (sphere ** 2 - (x * x + y * y + z * z)))[None].astype(np.float32)
    n = helper.make_node
    nodes = [n("ReduceMean", ["image"], ["mean"], keepdims=0),
             n("Mul", ["mean", "zero"], ["nothing"]),
             n("Add", ["grid", "nothing"], ["density"])]
    graph = helper.make_graph(
        nodes, "density",
        [helper.make_tensor_value_info("image", TensorProto.FLOAT, [1, 3, size, size])],
        [helper.make_tensor_value_info("density", TensorProto.FLOAT, [1, res, res, res])],
        [_const("grid", density), _const("zero", np.array(0.0, np.float32))])
    return _save(graph, path)


def triplane_pair(encoder: Path, decoder: Path, P: int = 32, radius: float = 0.87,
                  sphere: float = 0.5) -> tuple[Path, Path]:
    """TripoSR-shaped pair: planes hold their own coordinates (C = 2, plus 10), the decoder
    turns the sampled (x, y, z) into 1e4 * (sphere^2 - |p|^2)."""
    c = ((np.arange(P) + 0.5) * 2 / P - 1) * radius  # pixel-centre coordinates
    width = np.broadcast_to(c[None, :], (P, P))
    height = np.broadcast_to(c[:, None], (P, P))
    # stored with +10 so that grid_sample's zero padding outside the planes reads as far away
    planes = (np.stack([np.stack([width, height])] * 3)[None] + 10).astype(np.float32)
    n = helper.make_node
    enc = helper.make_graph(
        [n("ReduceMean", ["image"], ["mean"], keepdims=0), n("Mul", ["mean", "zero"], ["z0"]),
         n("Add", ["planes", "z0"], ["triplane"])], "encoder",
        [helper.make_tensor_value_info("image", TensorProto.FLOAT, [1, 3, 512, 512])],
        [helper.make_tensor_value_info("triplane", TensorProto.FLOAT, [1, 3, 2, P, P])],
        [_const("planes", planes), _const("zero", np.array(0.0, np.float32))])
    select = np.zeros((6, 3), np.float32)
    select[0, 0] = select[1, 1] = select[3, 2] = 1.0  # xy plane -> x, y; xz plane -> z
    dec = helper.make_graph(
        [n("MatMul", ["feats", "sel"], ["xyz10"]), n("Sub", ["xyz10", "ten"], ["xyz"]),
         n("Mul", ["xyz", "xyz"], ["sq"]),
         n("ReduceSum", ["sq", "ax"], ["r2"], keepdims=1), n("Sub", ["s2", "r2"], ["d"]),
         n("Mul", ["d", "k"], ["density"])], "decoder",
        [helper.make_tensor_value_info("feats", TensorProto.FLOAT, ["n", 6])],
        [helper.make_tensor_value_info("density", TensorProto.FLOAT, ["n", 1])],
        [_const("sel", select), _const("ax", np.array([1], np.int64)),
         _const("ten", np.array(10.0, np.float32)),
         _const("s2", np.array(sphere ** 2, np.float32)), _const("k", np.array(1e4, np.float32))])
    return _save(enc, encoder), _save(dec, decoder)
