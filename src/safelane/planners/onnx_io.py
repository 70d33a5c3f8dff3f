"""ONNX export of :class:`~safelane.planners.nn.MLPPlanner` and an ONNX Runtime planner.

The graph takes raw features ``features`` ``(N, F)`` float32 (columns as in
:data:`~safelane.planners.features.FEATURE_NAMES`) and returns ``actions`` ``(N, 2)`` float32 [m/s²]
(``a_x``, ``a_y``): normalisation, both networks and the tanh output scaling are inside the graph, so any ONNX
runtime reproduces :meth:`MLPPlanner.predict` (to float32 rounding). The planner's metadata JSON is stored in
the model's ``metadata_props`` under the key ``"safelane"``.

``onnx`` (export) and ``onnxruntime`` (inference) are optional: ``pip install 'safelane[train]'``.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from ..params import Params
from .base import Observation, clip_actions
from .features import FEATURE_NAMES, features

OPSET = 17
IR_VERSION = 8  # readable by ONNX Runtime >= 1.10
METADATA_KEY = "safelane"


def _require(module: str):
    import importlib

    try:
        return importlib.import_module(module)
    except ImportError as exc:
        raise ImportError(f"{module} is needed for the ONNX path: pip install 'safelane[train]'") from exc


def export_onnx(planner, path: Path | str) -> Path:
    """Write ``planner`` (an :class:`MLPPlanner`) as an ONNX model to ``path``; returns the path."""
    onnx = _require("onnx")
    from onnx import TensorProto, helper, numpy_helper

    from .nn import HEADS

    inits, nodes = [], []

    def const(name: str, value) -> str:
        inits.append(numpy_helper.from_array(np.asarray(value, dtype=np.float32), name))
        return name

    def node(op: str, inputs: list[str], out: str) -> str:
        nodes.append(helper.make_node(op, inputs, [out]))
        return out

    x = node("Sub", ["features", const("mean", planner.mean)], "centred")
    x = node("Div", [x, const("std", planner.std)], "normalised")
    act = {"tanh": "Tanh", "relu": "Relu"}[planner.activation]
    head_outputs = []
    for head in HEADS:
        h = x
        layers = planner.layers[head]
        for k, (w, b) in enumerate(layers):
            h = node("MatMul", [h, const(f"{head}_W{k}", w)], f"{head}_mm{k}")
            h = node("Add", [h, const(f"{head}_b{k}", b)], f"{head}_z{k}")
            h = node(act if k < len(layers) - 1 else "Tanh", [h], f"{head}_h{k}")
        lo, hi = planner.bounds[head]
        h = node("Mul", [h, const(f"{head}_half", 0.5 * (hi - lo))], f"{head}_scaled")
        head_outputs.append(node("Add", [h, const(f"{head}_mid", 0.5 * (lo + hi))], f"{head}_action"))
    nodes.append(helper.make_node("Concat", head_outputs, ["actions"], axis=1))

    graph = helper.make_graph(
        nodes,
        "safelane_mlp_planner",
        [helper.make_tensor_value_info("features", TensorProto.FLOAT, ["N", len(FEATURE_NAMES)])],
        [helper.make_tensor_value_info("actions", TensorProto.FLOAT, ["N", len(HEADS)])],
        initializer=inits,
    )
    model = helper.make_model(
        graph, producer_name="safelane", opset_imports=[helper.make_opsetid("", OPSET)], ir_version=IR_VERSION
    )
    helper.set_model_props(model, {METADATA_KEY: json.dumps(planner.full_metadata(), sort_keys=True)})
    onnx.checker.check_model(model)
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    onnx.save(model, str(path))
    return path


class OnnxPlanner:
    """A :class:`~safelane.planners.base.NominalPlanner` running an exported planner in ONNX Runtime.

    Same call signature and clipping as :class:`MLPPlanner`; ``threads`` sets ONNX Runtime's intra-op threads.
    """

    def __init__(self, path: Path | str, threads: int = 1) -> None:
        ort = _require("onnxruntime")
        path = Path(path)
        if not path.exists():
            raise FileNotFoundError(f"ONNX model not found: {path}")
        opts = ort.SessionOptions()
        opts.intra_op_num_threads = threads
        opts.inter_op_num_threads = 1
        self.session = ort.InferenceSession(str(path), sess_options=opts, providers=["CPUExecutionProvider"])
        props = self.session.get_modelmeta().custom_metadata_map
        if METADATA_KEY not in props:
            raise ValueError(f"{path}: no {METADATA_KEY!r} metadata; not exported by safelane")
        self.metadata = json.loads(props[METADATA_KEY])
        from .nn import _check_compat

        try:
            _check_compat(self.metadata)
        except ValueError as err:
            raise ValueError(f"{path}: {err}") from None

    def predict(self, x: np.ndarray) -> np.ndarray:
        """Bounded actions ``(B, 2)`` [m/s²] for raw features ``x`` ``(B, F)`` (computed in float32)."""
        x = np.ascontiguousarray(x, dtype=np.float32)
        return self.session.run(["actions"], {"features": x})[0].astype(np.float64)

    def __call__(self, obs: Observation, params: Params) -> tuple[np.ndarray, np.ndarray]:
        """``(a_x, a_y)`` [m/s²], each ``(B,)``, clipped to the mechanical limits of ``params``."""
        out = self.predict(features(obs, params))
        return clip_actions(out[:, 0], out[:, 1], params)
