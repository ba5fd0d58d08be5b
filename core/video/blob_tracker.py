"""A per-camera 2-D blob tracker: local ids, and a class vote over each blob's history.

Each track holds its last box and an image velocity (px/s, smoothed). Every frame the
tracks are predicted to the frame's time and matched to the blobs by the Hungarian method
on a cost of ``1 - IoU`` of predicted and measured boxes, or, where the boxes do not
overlap, the centre distance over the box diagonal (so a blob that reappears beside its
predicted place after an occlusion is still taken); pairs beyond the gate are not matched.
A blob nobody takes starts a track (birth); a track unmatched for ``max_missed_s`` ends
(death). The class of a track is the **majority of its per-frame classes so far**,
committed only after ``min_history`` frames (Lipton et al.'s temporal consistency), with
clutter votes counted: a track that is mostly clutter is reported as clutter. A track
is a moving object (``moved``) once it has travelled half a box diagonal from where it
appeared: motion that goes nowhere (a tree crown in the wind) is not an object.
A track is seen only in part (``partial``) while its object slides behind, or out from
behind, an occluder: one side edge of its box stands still while the other moves
steadily (:func:`partial_view`).
"""

from __future__ import annotations

import itertools
from collections import Counter
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np
from scipy.optimize import linear_sum_assignment

from ..errors import VideoError
from .blobs import Blob
from .detector import iou

__all__ = ["BlobTrack", "BlobTracker", "TrackedBlob"]


@dataclass
class BlobTrack:
    """A track's state (mutable inside the tracker only)."""

    local_id: str
    bbox: tuple[float, float, float, float]
    t_s: float
    velocity_px_s: np.ndarray = field(default_factory=lambda: np.zeros(2))
    votes: Counter = field(default_factory=Counter)
    n_seen: int = 0
    scores: list[float] = field(default_factory=list)
    origin_px: np.ndarray | None = None  # box centre when first seen
    moved: bool = False  # has travelled ``travel`` box diagonals from its origin
    recent: list = field(default_factory=list)  # the last 4 boxes

    @property
    def partial(self) -> bool:
        """Seen in part at an occluder's edge (see :func:`partial_view`)."""
        return partial_view(self.recent)

    def predict(self, t_s: float) -> tuple[float, float, float, float]:
        """The box moved on by the velocity to ``t_s``."""
        du, dv = self.velocity_px_s * (t_s - self.t_s)
        u0, v0, u1, v1 = self.bbox
        return (u0 + du, v0 + dv, u1 + du, v1 + dv)

    def voted_class(self, min_history: int) -> str | None:
        """The majority class, or None before ``min_history`` frames."""
        if self.n_seen < min_history or not self.votes:
            return None
        return self.votes.most_common(1)[0][0]


@dataclass(frozen=True)
class TrackedBlob:
    """A blob with its track.

    ``local_id``, the voted class (None: not yet committed), the blob's own class this
    frame and its track's mean score.
    """

    blob: Blob
    local_id: str
    cls: str | None
    frame_cls: str
    score: float
    partial: bool = False


def partial_view(boxes: Sequence[tuple[float, float, float, float]]) -> bool:
    """Whether a track's last four boxes show an object passing an occluder's edge.

    Over the last three frames one side edge stood still (within half a pixel in all)
    while the other moved steadily one way, 3 px or more in all: the object slides
    behind (or out from behind) something, the box is its visible part and the box's
    bottom-centre not the object's foot.
    """
    if len(boxes) < 4:
        return False
    b = np.asarray(boxes[-4:], dtype=np.float64)
    for still, moving in ((0, 2), (2, 0)):
        d_still, d_moving = np.diff(b[:, still]), np.diff(b[:, moving])
        steady = (d_moving > 0).all() or (d_moving < 0).all()
        if (np.abs(d_still) <= 0.5).all() and steady and abs(d_moving.sum()) >= 3.0:
            return True
    return False


def _centre(b: tuple[float, float, float, float]) -> np.ndarray:
    return np.array([(b[0] + b[2]) / 2.0, (b[1] + b[3]) / 2.0])


class BlobTracker:
    """Per-camera tracker of blobs (see the module docstring).

    Parameters
    ----------
    max_missed_s : float
        A track unmatched for longer ends (s).
    min_history : int
        Frames of history before a class is committed.
    gate : float
        Largest centre distance, in box diagonals, of a match without overlap.
    velocity_gain : float
        Weight of a new velocity measurement in the smoothed velocity (0..1).
    travel : float
        A track counts as a moving object (``moved``) once its box centre has been this
        many box diagonals (at least 3 px) from where it was first seen; a swaying tree
        crown or a flickering shadow never gets there.
    """

    def __init__(
        self,
        *,
        max_missed_s: float = 1.5,
        min_history: int = 5,
        gate: float = 1.0,
        velocity_gain: float = 0.3,
        travel: float = 0.5,
    ) -> None:
        if not max_missed_s > 0:
            raise VideoError(f"max_missed_s must be positive, got {max_missed_s}")
        if int(min_history) < 1:
            raise VideoError(f"min_history must be 1 or more, got {min_history}")
        self.max_missed_s = float(max_missed_s)
        self.min_history = int(min_history)
        self.gate = float(gate)
        self.velocity_gain = float(velocity_gain)
        self.travel = float(travel)
        self.tracks: list[BlobTrack] = []
        self._ids = itertools.count(1)

    def _cost(self, track: BlobTrack, pred: tuple, box: tuple) -> float:
        overlap = iou(pred, box)
        if overlap > 0:
            return 1.0 - overlap
        diag = max(np.hypot(box[2] - box[0], box[3] - box[1]), 1.0)
        d = float(np.linalg.norm(_centre(pred) - _centre(box))) / diag
        return 1.0 + d if d <= self.gate else np.inf

    def update(
        self,
        t_s: float,
        blobs: Sequence[Blob],
        classes: Sequence[str],
        scores: Sequence[float] | None = None,
    ) -> list[TrackedBlob]:
        """Match one frame's blobs (with their per-frame classes) to the tracks.

        Returns one :class:`TrackedBlob` per blob, in order.
        """
        if len(classes) != len(blobs):
            raise VideoError("one class per blob")
        scores = [1.0] * len(blobs) if scores is None else list(scores)
        self.tracks = [tr for tr in self.tracks if t_s - tr.t_s <= self.max_missed_s]
        preds = [tr.predict(t_s) for tr in self.tracks]
        assigned: dict[int, BlobTrack] = {}
        if self.tracks and blobs:
            cost = np.array(
                [
                    [self._cost(tr, p, b.bbox) for b in blobs]
                    for tr, p in zip(self.tracks, preds, strict=True)
                ]
            )
            finite = np.where(np.isfinite(cost), cost, 1e6)
            rows, cols = linear_sum_assignment(finite)
            for r, c in zip(rows, cols, strict=True):
                if np.isfinite(cost[r, c]):
                    assigned[int(c)] = self.tracks[int(r)]
        out = []
        for j, blob in enumerate(blobs):
            tr = assigned.get(j)
            if tr is None:
                tr = BlobTrack(f"{next(self._ids)}", blob.bbox, t_s)
                self.tracks.append(tr)
            else:
                dt = t_s - tr.t_s
                if dt > 0:
                    v = (_centre(blob.bbox) - _centre(tr.bbox)) / dt
                    g = 1.0 if tr.n_seen == 1 else self.velocity_gain
                    tr.velocity_px_s = (1 - g) * tr.velocity_px_s + g * v
                tr.bbox, tr.t_s = blob.bbox, t_s
            tr.n_seen += 1
            centre = _centre(blob.bbox)
            if tr.origin_px is None:
                tr.origin_px = centre
            elif not tr.moved:
                b = blob.bbox
                diag = float(np.hypot(b[2] - b[0], b[3] - b[1]))
                tr.moved = float(np.linalg.norm(centre - tr.origin_px)) >= max(
                    self.travel * diag, 3.0
                )
            tr.votes[classes[j]] += 1
            tr.recent = [*tr.recent[-3:], blob.bbox]
            tr.scores.append(float(scores[j]))
            tr.scores = tr.scores[-50:]
            out.append(
                TrackedBlob(
                    blob,
                    tr.local_id,
                    tr.voted_class(self.min_history),
                    classes[j],
                    float(np.mean(tr.scores)),
                    tr.partial,
                )
            )
        return out
