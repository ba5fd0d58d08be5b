"""A user-supplied ONNX detector (onnxruntime, CPU) as the detector component.

The model contract:

- **input**: one tensor, ``float32`` of shape ``(1, 3, H, W)`` (NCHW), RGB, values
  ``0..1``. ``H`` and ``W`` may be fixed in the model (the frame is resized to them and
  the boxes scaled back) or free (the frame goes in at its own size).
- **outputs**, in this order: ``boxes`` ``(N, 4)`` float, ``(x_min, y_min, x_max, y_max)``
  in input pixels (demtrack's convention, ``(0, 0)`` the centre of the top-left pixel);
  ``scores`` ``(N,)`` float in ``0..1``; ``classes`` ``(N,)`` integer class indices. A
  leading batch axis of 1 on any of them is accepted.
- **class names**: ``class_names`` maps an index to ``human`` or ``vehicle`` (default
  ``{0: "human", 1: "vehicle"}``); indices not in it are dropped, as are scores below
  ``min_score``.

The model's own class becomes the blob's label; the blob tracker still votes over it.
"""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path

import cv2
import numpy as np

from ..errors import VideoError
from .blobs import Blob, prepare_mask
from .reader import Frame

__all__ = ["DEFAULT_CLASS_NAMES", "OnnxDetector"]

DEFAULT_CLASS_NAMES: Mapping[int, str] = {0: "human", 1: "vehicle"}


class OnnxDetector:
    """Boxes from an ONNX model (see the module docstring).

    Parameters
    ----------
    path : str or Path
        The ``.onnx`` file.
    size : tuple of int
        Frame size ``(width, height)``.
    class_names : mapping, optional
        Class index -> ``human`` / ``vehicle``.
    min_score : float
        Boxes below this score are dropped.
    mask : ndarray of bool, optional
        Ignore mask: boxes whose foot pixel lies under it are dropped.
    """

    def __init__(
        self,
        path: str | Path,
        size: tuple[int, int],
        *,
        class_names: Mapping[int, str] | None = None,
        min_score: float = 0.5,
        mask: np.ndarray | None = None,
    ) -> None:
        import onnxruntime as ort

        path = Path(path)
        if not path.is_file():
            raise VideoError(f"ONNX model not found: {path}")
        opts = ort.SessionOptions()
        opts.intra_op_num_threads = 1
        opts.log_severity_level = 3
        try:
            self.session = ort.InferenceSession(str(path), opts, providers=["CPUExecutionProvider"])
        except Exception as exc:  # onnxruntime raises its own untyped errors
            first = str(exc).strip().splitlines()[0] if str(exc).strip() else type(exc).__name__
            raise VideoError(f"cannot load ONNX model {path}: {first}") from None
        inputs = self.session.get_inputs()
        if len(inputs) != 1 or len(inputs[0].shape) != 4:
            raise VideoError(f"ONNX model {path} must take one (1, 3, H, W) input")
        if len(self.session.get_outputs()) < 3:
            raise VideoError(f"ONNX model {path} must give boxes, scores and classes")
        self.input_name = inputs[0].name
        shape = inputs[0].shape
        self.size = (int(size[0]), int(size[1]))
        fixed = isinstance(shape[2], int) and isinstance(shape[3], int)
        self.input_size = (int(shape[3]), int(shape[2])) if fixed else self.size
        self.class_names = dict(class_names or DEFAULT_CLASS_NAMES)
        self.min_score = float(min_score)
        self.mask = prepare_mask(mask, self.size)

    def detect(self, frame: Frame) -> list[Blob]:
        """The model's boxes on ``frame`` (RGB), as labelled blobs."""
        img = frame.image
        if img.ndim != 3:
            raise VideoError("the ONNX detector needs RGB frames (open the reader without gray)")
        if img.shape[1::-1] != self.size:
            raise VideoError(
                f"frame is {img.shape[1]}x{img.shape[0]}, detector expects {self.size}"
            )
        if self.input_size != self.size:
            img = cv2.resize(img, self.input_size, interpolation=cv2.INTER_AREA)
        x = np.ascontiguousarray(img.transpose(2, 0, 1)[None], dtype=np.float32) / 255.0
        boxes, scores, classes = self.session.run(None, {self.input_name: x})[:3]
        boxes = np.asarray(boxes, dtype=np.float64).reshape(-1, 4)
        scores = np.asarray(scores, dtype=np.float64).reshape(-1)
        classes = np.asarray(classes).reshape(-1).astype(np.int64)
        sx = self.size[0] / self.input_size[0]
        sy = self.size[1] / self.input_size[1]
        out = []
        for box, score, k in zip(boxes, scores, classes, strict=True):
            name = self.class_names.get(int(k))
            if name is None or not np.isfinite(box).all() or score < self.min_score:
                continue
            # scale about the pixel-centre convention: an edge at -0.5 stays at -0.5
            u0, u1 = (box[0] + 0.5) * sx - 0.5, (box[2] + 0.5) * sx - 0.5
            v0, v1 = (box[1] + 0.5) * sy - 0.5, (box[3] + 0.5) * sy - 0.5
            if u1 <= u0 or v1 <= v0:
                continue
            blob = Blob.from_box((u0, v0, u1, v1), score=float(score), label=name)
            if self.mask is not None:
                fu = int(np.clip(round(blob.foot_px[0]), 0, self.size[0] - 1))
                fv = int(np.clip(round(blob.foot_px[1]), 0, self.size[1] - 1))
                if self.mask[fv, fu]:
                    continue
            out.append(blob)
        return out
