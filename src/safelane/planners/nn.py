"""Neural nominal planner: two small MLPs (longitudinal ``a_x``, lateral ``a_y``) with a pure-NumPy forward pass.

Architecture (one network per axis, as in the paper's Fig. 1): ``x = (features − mean) / std`` (the
normalisation is part of the model), then ``h ← act(h W_k + b_k)`` through the hidden layers and a linear output
``z``; the action is ``mid + half · tanh(z)``, which maps onto the open interval between the mechanical limits
the model was trained with (``[−a_x_d, a_x_a]``, ``[−a_y_m, a_y_m]``). At call time the actions are also clipped
to the limits of the ``Params`` passed in. Two separate networks rather than one with two heads: the axes have
different limits, scales and failure modes, and either network can be retrained or swapped alone.

Weights are float32 and the forward pass runs in float32 (features are computed in float64, normalised, then
cast). No PyTorch at run time; ONNX Runtime is an optional second inference path (:mod:`.onnx_io`).

File format (``.npz``, no pickles): arrays ``<head>/W<k>`` ``(n_in, n_out)`` and ``<head>/b<k>`` ``(n_out,)``
for ``head`` in :data:`HEADS`, and ``metadata``: a JSON string with the keys of :func:`_check_metadata`
(format and feature versions, feature names, layer shapes, bounds, activation, normalisation, safelane version,
training-config hash). Loading checks all of it and raises ``ValueError`` naming what does not match.
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from .. import __version__
from ..params import Params
from .base import Observation, clip_actions
from .features import FEATURE_NAMES, FEATURES_VERSION, features

FORMAT = "safelane-mlp-planner"
FORMAT_VERSION = 1
HEADS = ("a_x", "a_y")
#: Hidden activations, applied in place.
ACTIVATIONS = {"tanh": lambda h: np.tanh(h, out=h), "relu": lambda h: np.maximum(h, 0.0, out=h)}
CHUNK_ROWS = 4096
DEFAULT_MODEL = "mlp_default"

Layers = tuple[tuple[np.ndarray, np.ndarray], ...]


def head_bounds(params: Params) -> dict[str, tuple[float, float]]:
    """Mechanical action limits ``(low, high)`` [m/s²] of each head."""
    return {"a_x": (-params.a_x_d, params.a_x_a), "a_y": (-params.a_y_m, params.a_y_m)}


def _version_tuple(version: str) -> tuple[int, ...]:
    parts = []
    for piece in str(version).split(".")[:2]:
        digits = "".join(c for c in piece if c.isdigit())
        parts.append(int(digits) if digits else 0)
    return tuple(parts)


@dataclass(frozen=True, eq=False)
class MLPPlanner:
    """A :class:`~safelane.planners.base.NominalPlanner` backed by two MLPs; see the module docstring.

    Attributes:
        layers: per head, the ``(W, b)`` float32 pairs in order; ``W`` has shape ``(n_in, n_out)``.
        mean, std: feature normalisation ``(F,)``, float64.
        bounds: per head, the ``(low, high)`` [m/s²] the tanh output is scaled into.
        activation: hidden activation, a key of :data:`ACTIVATIONS`.
        metadata: free-form provenance (training config and hash, metrics) saved with the weights.
    """

    layers: dict[str, Layers]
    mean: np.ndarray
    std: np.ndarray
    bounds: dict[str, tuple[float, float]]
    activation: str = "tanh"
    metadata: dict = field(default_factory=dict)

    def __post_init__(self) -> None:
        _check_metadata(self._core_metadata(), self._arrays())

    # ------------------------------------------------------------------ inference
    def predict(self, x: np.ndarray) -> np.ndarray:
        """Bounded actions ``(B, 2)`` [m/s²] (columns ``a_x``, ``a_y``) for raw features ``x`` ``(B, F)``.

        Rows go through in chunks of :data:`CHUNK_ROWS` so the hidden activations stay in cache; bias and
        activation are applied in place."""
        x = np.asarray(x, dtype=np.float64)
        if x.ndim != 2 or x.shape[1] != self.mean.shape[0]:
            raise ValueError(f"features must have shape (B, {self.mean.shape[0]}), got {x.shape}")
        act = ACTIVATIONS[self.activation]
        out = np.empty((x.shape[0], len(HEADS)))
        for s in range(0, x.shape[0], CHUNK_ROWS):
            z0 = ((x[s : s + CHUNK_ROWS] - self.mean) / self.std).astype(np.float32)
            for j, head in enumerate(HEADS):
                h = z0
                layers = self.layers[head]
                for w, b in layers[:-1]:
                    h = h @ w
                    h += b
                    act(h)
                w, b = layers[-1]
                out[s : s + CHUNK_ROWS, j] = np.tanh(h @ w + b)[:, 0]
        for j, head in enumerate(HEADS):
            lo, hi = self.bounds[head]
            out[:, j] = 0.5 * (lo + hi) + 0.5 * (hi - lo) * out[:, j]
        return out

    def __call__(self, obs: Observation, params: Params) -> tuple[np.ndarray, np.ndarray]:
        """``(a_x, a_y)`` [m/s²], each ``(B,)``, clipped to the mechanical limits of ``params``."""
        out = self.predict(features(obs, params))
        return clip_actions(out[:, 0], out[:, 1], params)

    # ------------------------------------------------------------------ persistence
    def _core_metadata(self) -> dict:
        return {
            "format": FORMAT,
            "format_version": FORMAT_VERSION,
            "safelane_version": self.metadata.get("safelane_version", __version__),
            "features_version": FEATURES_VERSION,
            "feature_names": list(FEATURE_NAMES),
            "activation": self.activation,
            "heads": {
                h: {"layer_shapes": [list(w.shape) for w, _ in self.layers[h]], "bounds": list(self.bounds[h])}
                for h in HEADS
            },
            "normalisation": {"mean": self.mean.tolist(), "std": self.std.tolist()},
        }

    def _arrays(self) -> dict[str, np.ndarray]:
        out = {}
        for head in HEADS:
            for k, (w, b) in enumerate(self.layers[head]):
                out[f"{head}/W{k}"], out[f"{head}/b{k}"] = w, b
        return out

    def full_metadata(self) -> dict:
        """Everything saved in the ``metadata`` blob (provenance first, checked fields override it)."""
        return {**self.metadata, **self._core_metadata()}

    def save(self, path: Path | str) -> Path:
        """Write the model to ``path`` (``.npz``); returns the path written."""
        path = Path(path)
        path.parent.mkdir(parents=True, exist_ok=True)
        blob = json.dumps(self.full_metadata(), sort_keys=True)
        with path.open("wb") as fh:
            np.savez(fh, metadata=np.array(blob), **self._arrays())
        return path

    @classmethod
    def load(cls, path: Path | str) -> MLPPlanner:
        """Read a model written by :meth:`save`; ``ValueError`` if it does not match this safelane."""
        path = Path(path)
        if not path.exists():
            raise FileNotFoundError(f"model file not found: {path}")
        try:
            with np.load(path, allow_pickle=False) as npz:
                arrays = {k: npz[k] for k in npz.files}
        except (OSError, ValueError) as exc:
            raise ValueError(f"{path}: not a readable .npz model file ({exc})") from exc
        if "metadata" not in arrays:
            raise ValueError(f"{path}: no 'metadata' entry; not a {FORMAT} file")
        try:
            meta = json.loads(str(arrays.pop("metadata")))
        except json.JSONDecodeError as exc:
            raise ValueError(f"{path}: metadata is not valid JSON ({exc})") from exc
        try:
            _check_metadata(meta, arrays)
        except ValueError as exc:
            raise ValueError(f"{path}: {exc}") from exc
        layers = {
            h: tuple(
                (arrays[f"{h}/W{k}"].astype(np.float32), arrays[f"{h}/b{k}"].astype(np.float32))
                for k in range(len(meta["heads"][h]["layer_shapes"]))
            )
            for h in HEADS
        }
        norm = meta["normalisation"]
        return cls(
            layers=layers,
            mean=np.asarray(norm["mean"], dtype=np.float64),
            std=np.asarray(norm["std"], dtype=np.float64),
            bounds={h: tuple(meta["heads"][h]["bounds"]) for h in HEADS},
            activation=meta["activation"],
            metadata=meta,
        )

    def to_onnx(self, path: Path | str) -> Path:
        """Export to ONNX (normalisation and output scaling included); needs ``onnx``. See :mod:`.onnx_io`."""
        from .onnx_io import export_onnx

        return export_onnx(self, path)

    @staticmethod
    def from_onnx(path: Path | str):
        """An ONNX Runtime planner (:class:`~.onnx_io.OnnxPlanner`) for a file written by :meth:`to_onnx`."""
        from .onnx_io import OnnxPlanner

        return OnnxPlanner(path)


def _check_compat(meta: dict) -> None:
    """Raise ``ValueError`` unless ``meta`` is a safelane model of a format, version and feature map this safelane
    reads (the part of :func:`_check_metadata` that every exported form shares, ONNX included)."""
    if meta.get("format") != FORMAT:
        raise ValueError(f"format is {meta.get('format')!r}, expected {FORMAT!r}")
    if meta.get("format_version") != FORMAT_VERSION:
        raise ValueError(f"format version {meta.get('format_version')!r}; this safelane reads {FORMAT_VERSION}")
    made_by = meta.get("safelane_version", "0")
    if _version_tuple(made_by) > _version_tuple(__version__):
        raise ValueError(f"written by safelane {made_by}, newer than this safelane {__version__}; upgrade safelane")
    if meta.get("features_version") != FEATURES_VERSION or list(meta.get("feature_names", [])) != list(FEATURE_NAMES):
        raise ValueError(
            f"trained on features v{meta.get('features_version')} {meta.get('feature_names')}, but this safelane "
            f"computes v{FEATURES_VERSION} {list(FEATURE_NAMES)}; retrain the model"
        )


def _check_metadata(meta: dict, arrays: dict[str, np.ndarray]) -> None:
    """Raise ``ValueError`` unless ``meta``/``arrays`` describe a model this safelane can run."""
    _check_compat(meta)
    if meta.get("activation") not in ACTIVATIONS:
        raise ValueError(f"unknown activation {meta.get('activation')!r}; known: {sorted(ACTIVATIONS)}")
    n_feat = len(FEATURE_NAMES)
    norm = meta.get("normalisation", {})
    mean, std = np.asarray(norm.get("mean", []), float), np.asarray(norm.get("std", []), float)
    if mean.shape != (n_feat,) or std.shape != (n_feat,):
        raise ValueError(f"normalisation mean/std must have shape ({n_feat},), got {mean.shape} and {std.shape}")
    if not (np.all(np.isfinite(mean)) and np.all(np.isfinite(std)) and np.all(std > 0)):
        raise ValueError("normalisation mean/std must be finite with std > 0")
    for head in HEADS:
        spec = meta.get("heads", {}).get(head)
        if spec is None:
            raise ValueError(f"no head {head!r} in metadata")
        lo, hi = spec["bounds"]
        if not lo < hi:
            raise ValueError(f"head {head}: bounds {spec['bounds']} are not increasing")
        shapes = [tuple(s) for s in spec["layer_shapes"]]
        if not shapes or shapes[0][0] != n_feat or shapes[-1][1] != 1:
            raise ValueError(f"head {head}: layer shapes {shapes} must start at {n_feat} inputs and end at 1 output")
        for k, shape in enumerate(shapes):
            w, b = arrays.get(f"{head}/W{k}"), arrays.get(f"{head}/b{k}")
            if w is None or b is None:
                raise ValueError(f"head {head}: missing weights of layer {k}")
            if w.shape != shape or b.shape != (shape[1],):
                raise ValueError(
                    f"head {head} layer {k}: metadata says W{shape}, b({shape[1]},) but the file has "
                    f"W{w.shape}, b{b.shape}"
                )
            if k and shapes[k - 1][1] != shape[0]:
                raise ValueError(f"head {head}: layer {k - 1} outputs {shapes[k - 1][1]}, layer {k} takes {shape[0]}")
            if not (np.all(np.isfinite(w)) and np.all(np.isfinite(b))):
                raise ValueError(f"head {head} layer {k}: non-finite weights")


def load_default_planner() -> MLPPlanner:
    """The planner shipped in ``safelane/models`` (see ``safelane/models/MODEL_CARD.md``)."""
    from importlib.resources import as_file, files

    with as_file(files("safelane") / "models" / f"{DEFAULT_MODEL}.npz") as path:
        return MLPPlanner.load(path)


def with_random_weights(model: MLPPlanner, rng: np.random.Generator, gain: float = 1.5) -> MLPPlanner:
    """``model``'s architecture, normalisation, bounds and activation with random weights drawn from ``rng``.

    Weights ``N(0, gain² / fan_in)``, biases ``N(0, 0.1²)``: with the default gain the hidden units and the
    outputs spread over their whole range (a PyTorch-style ``U(±1/√fan_in)`` initialisation would leave every
    action near the middle of its limits, a gentle brake). An untrained planner that can ask for anything within
    the mechanical limits; the ablation of ``benchmarks/supervisor_ablation.py`` uses it to show the supervisor
    keeps even such a planner safe."""
    layers = {
        head: tuple(
            (
                (rng.standard_normal(w.shape) * gain / np.sqrt(w.shape[0])).astype(np.float32),
                (0.1 * rng.standard_normal(b.shape)).astype(np.float32),
            )
            for w, b in model.layers[head]
        )
        for head in HEADS
    }
    meta = {"note": f"random weights (gain {gain}) in the architecture of a trained model"}
    return MLPPlanner(layers, model.mean.copy(), model.std.copy(), dict(model.bounds), model.activation, meta)
