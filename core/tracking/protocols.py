"""The roles a tracker is assembled from, after Stone Soup's design.

One small :class:`typing.Protocol` per role; each family of implementations lives in its
own module and a tracker (:mod:`.tracker`) is assembled from one of each:

=====================  ===============================================================
role                   families
=====================  ===============================================================
motion model           :mod:`.motion` (constant velocity), :mod:`.roads` (on roads)
measurement model      :mod:`.measurement` (first / last / all hits, road rule)
filter                 :mod:`.kalman`, :mod:`.particle`, :mod:`.passthrough`
hypothesiser           :mod:`.hypothesiser` (chi-square gate, best hit)
data associator        :mod:`.association` (global nearest neighbour)
initiator              :mod:`.initiation` (M-of-N and settled, one seed per hit or a
                       mixture)
deleter                :mod:`.deletion` (coast time)
reacquirer             :mod:`.reacquire` (own prediction, or along the roads)
=====================  ===============================================================

A missed detection is an explicit hypothesis (:class:`MissedDetection`), chosen by the
associator like any other.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any, Protocol

import numpy as np

from .types import Fix

__all__ = [
    "Candidates",
    "DataAssociator",
    "Deleter",
    "Filter",
    "Hypothesis",
    "Hypothesiser",
    "Initiator",
    "Measurement",
    "MeasurementModel",
    "MissedDetection",
    "MotionModel",
    "ParticleMotionModel",
    "Reacquirer",
    "SingleHypothesis",
]


@dataclass(frozen=True, eq=False)
class Candidates:
    """The position measurements a measurement model reads out of one fix.

    Parameters
    ----------
    z_enu : ndarray, shape (m, 3)
        Candidate positions, local frame (m), ``m >= 1``.
    sigma_m : ndarray, shape (m,)
        1-sigma horizontal uncertainty of each (m).
    weight : ndarray, shape (m,)
        Prior probability that each is the object (sums to 1).
    mixture : bool
        True: the update uses every candidate as a mixture (hypotheses carried or
        weighed); False: it uses only the one the hypothesiser chose.
    cov_m2 : ndarray, shape (m, 2, 2), or None
        Full horizontal covariance of each (m^2); None: isotropic ``sigma_m**2 I``.
    """

    z_enu: np.ndarray
    sigma_m: np.ndarray
    weight: np.ndarray
    mixture: bool
    cov_m2: np.ndarray | None = None

    @classmethod
    def _trusted(
        cls,
        z_enu: np.ndarray,
        sigma_m: np.ndarray,
        weight: np.ndarray,
        mixture: bool,
        cov_m2: np.ndarray | None,
    ) -> Candidates:
        """Internal: the constructor's value without its per-field frozen-dataclass cost."""
        out = object.__new__(cls)
        out.__dict__.update(
            z_enu=z_enu, sigma_m=sigma_m, weight=weight, mixture=mixture, cov_m2=cov_m2
        )
        return out

    def cov(self, j: int) -> np.ndarray:
        """Horizontal covariance (2, 2) of candidate ``j`` (m^2)."""
        if self.cov_m2 is not None:
            return self.cov_m2[j]
        return float(self.sigma_m[j]) ** 2 * np.eye(2)

    def covariances(self) -> np.ndarray:
        """Horizontal covariances of all candidates, shape (m, 2, 2) (m^2)."""
        if self.cov_m2 is not None:
            return self.cov_m2
        return self.sigma_m[:, None, None] ** 2 * np.eye(2)[None]

    def take(self, index: np.ndarray | slice) -> Candidates:
        """The candidates at ``index``, weights renormalised."""
        w = self.weight[index]
        return Candidates(
            self.z_enu[index],
            self.sigma_m[index],
            w / w.sum(),
            self.mixture,
            None if self.cov_m2 is None else self.cov_m2[index],
        )

    @property
    def size(self) -> int:
        """Number of candidates ``m``."""
        return int(self.z_enu.shape[0])


@dataclass(frozen=True, eq=False)
class Measurement:
    """A fix as the tracker consumes it: possibly fused from several sensors' fixes.

    Parameters
    ----------
    fix : Fix
        The (possibly triangulated) fix.
    indices : tuple of int
        Indices of the source fixes, in the order the tracker received them.
    sensors : tuple of str
        Sensors of the source fixes.
    """

    fix: Fix
    indices: tuple[int, ...]
    sensors: tuple[str, ...]

    @property
    def t_s(self) -> float:
        """Time (s)."""
        return self.fix.t_s

    @property
    def cls(self) -> str:
        """Object class."""
        return self.fix.cls


@dataclass(frozen=True)
class SingleHypothesis:
    """Track <- measurement: the measurement is this track's object.

    Parameters
    ----------
    measurement_index : int
        Index of the measurement in its scan.
    candidate_index : int
        The candidate (hit) nearest the prediction.
    distance2 : float
        Its squared Mahalanobis distance to the predicted position.
    """

    measurement_index: int
    candidate_index: int
    distance2: float


@dataclass(frozen=True)
class MissedDetection:
    """Track <- nothing: no measurement of the scan is this track's object."""


Hypothesis = SingleHypothesis | MissedDetection


class MotionModel(Protocol):
    """Linear-Gaussian motion of a state ``[x, y, vx, vy]`` (m, m/s)."""

    def transition(self, dt_s: float) -> np.ndarray:
        """State transition matrix F, shape (4, 4)."""
        ...

    def covariance(self, dt_s: float) -> np.ndarray:
        """Process noise covariance Q, shape (4, 4)."""
        ...


class ParticleMotionModel(Protocol):
    """Sampled motion of a particle set (its layout is the model's business)."""

    def initial(self, cands: Candidates, n: int, rng: np.random.Generator) -> Any:
        """Draw ``n`` particles spread over the candidates by their weights."""
        ...

    def propagate(self, particles: Any, dt_s: float, rng: np.random.Generator) -> Any:
        """Move every particle ``dt_s`` seconds ahead with process noise."""
        ...

    def positions(self, particles: Any) -> np.ndarray:
        """Horizontal positions, shape (n, 2) (m)."""
        ...

    def take(self, particles: Any, index: np.ndarray) -> Any:
        """Return the particles at ``index`` (resampling)."""
        ...


class MeasurementModel(Protocol):
    """Reads position candidates out of a fix."""

    def candidates(self, fix: Fix) -> Candidates | None:
        """Candidates of ``fix``, or None when it has nothing to measure (no hit)."""
        ...


class Filter(Protocol):
    """Predictor and updater of one state family (Gaussian, particles, raw)."""

    def initiate(
        self, cands: Candidates, which: int | None, t_s: float, rng: np.random.Generator
    ) -> Any:
        """Start a state from candidate ``which`` (None: all of them, as a mixture)."""
        ...

    def predict(self, state: Any, t_s: float, rng: np.random.Generator) -> Any:
        """Move the state to time ``t_s``."""
        ...

    def gaussian(self, state: Any) -> tuple[np.ndarray, np.ndarray]:
        """Horizontal position mean (2,) and covariance (2, 2), for gating."""
        ...

    def update(self, state: Any, cands: Candidates, chosen: int, rng: np.random.Generator) -> Any:
        """Update with a measurement (``chosen`` from the hypothesiser)."""
        ...

    def estimate(self, state: Any) -> tuple[np.ndarray, np.ndarray | None]:
        """Position estimate (3,) and its horizontal covariance (2, 2) or None."""
        ...

    def density(self, state: Any, xy: np.ndarray, cov_xy: np.ndarray) -> float:
        """Predictive density (1/m^2) of a position ``xy`` (2,) with covariance ``cov_xy``."""
        ...

    def revise(self, state: Any, n: int) -> list[np.ndarray]:
        """Re-estimate the last ``n`` measurement times.

        Returns smoothed horizontal positions (2,), oldest first, or fewer (an empty
        list: the filter does not revise its past).
        """
        ...


class Hypothesiser(Protocol):
    """Scores one track against one measurement."""

    def hypothesise(
        self, mean_xy: np.ndarray, cov_xy: np.ndarray, cands: Candidates, measurement_index: int
    ) -> SingleHypothesis | None:
        """Hypothesise that the measurement is the track's object; None outside the gate."""
        ...


class DataAssociator(Protocol):
    """Chooses one hypothesis per track, each measurement used at most once."""

    def associate(
        self, hypotheses: Sequence[Sequence[SingleHypothesis | None]], n_measurements: int
    ) -> list[Hypothesis]:
        """``hypotheses[i][j]``: track i vs measurement j (None = gated out)."""
        ...


class Initiator(Protocol):
    """Starts tentative tracks and decides when they become (or fail to be) tracks."""

    def seeds(self, cands: Candidates) -> list[int | None]:
        """Which candidate(s) each seed starts from (None: all, as a mixture)."""
        ...

    def confirmed(self, n_updates: int, age_s: float, spread: float = 0.0) -> bool:
        """Whether a tentative track with this history is confirmed.

        ``spread`` is the worst-direction 1-sigma (m) of its state's position after its
        last update.
        """
        ...

    def expired(self, n_updates: int, age_s: float) -> bool:
        """Whether a tentative track with this history is dropped."""
        ...

    def reportable(self, spreads: list[float]) -> int:
        """How many leading points of a newly confirmed track to leave out.

        ``spreads``: the state's position spread (m) after each tentative update.
        """
        ...


class Deleter(Protocol):
    """Ends confirmed tracks."""

    def delete(self, cls: str, coast_s: float) -> bool:
        """Whether a track of class ``cls`` unseen for ``coast_s`` seconds ends."""
        ...


class Reacquirer(Protocol):
    """Scores a lost track's prediction at a new track's position (identity over gaps)."""

    def density(
        self,
        flt: Filter,
        state: Any,
        last_t_s: float,
        last_xy: np.ndarray,
        t_s: float,
        xy: np.ndarray,
        cov_xy: np.ndarray,
        rng: np.random.Generator,
        v_xy: np.ndarray | None = None,
        cov_v: np.ndarray | None = None,
    ) -> float:
        """Density (1/m^2) at ``xy`` (2,), known to ``cov_xy``, of the lost track at ``t_s``.

        ``state`` is its (possibly coasted) state; ``last_t_s``, ``last_xy`` (2,) the
        time and position of its last estimate. Given the new track's velocity ``v_xy``
        (2,) known to ``cov_v`` (2, 2), and where the prediction has a velocity, the
        density is joint over position and velocity (1/m^2 times 1/(m/s)^2).
        """
        ...
